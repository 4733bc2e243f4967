"""The served model's identity in the cache key: a model swapped behind one URL is never
served from the cache, the former model's answers come back when it does, and a filled
cache still replays when the server cannot be asked."""

from __future__ import annotations

import json

import pytest

from llm_server import Reply, make_requests, serve
from popnavshift.errors import ConfigError, TransportError
from popnavshift.responses.llm import OpenAIRespondent
from popnavshift.responses.llm.identity import listing_identity


def llama_listing(size: int, created: int = 0) -> Reply:
    """``GET /v1/models`` of llama.cpp's server: one model under an alias, its file's meta."""
    return Reply(raw=json.dumps({"object": "list", "data": [
        {"id": "local", "object": "model", "created": created, "owned_by": "llamacpp",
         "meta": {"n_params": 134515008, "size": size}}]}).encode())


@pytest.fixture
def server():
    with serve() as s:
        yield s


def make(server, tmp_path) -> OpenAIRespondent:
    return OpenAIRespondent(base_url=server.openai_url, model="local", api_key_env=None,
                            cache_path=tmp_path / "cache.sqlite", timeout=5.0, max_retries=0)


def run(server, tmp_path, listing: Reply) -> int:
    """Chat requests one run of 3 records made, the server listing ``listing``."""
    before = server.calls
    server.enqueue_models(listing)
    answers = make(server, tmp_path).answer_all(make_requests(3))
    assert all(a.answer is not None for a in answers)
    return server.calls - before


def test_a_model_swapped_behind_one_url_is_never_served_from_cache(server, tmp_path):
    a, b = llama_listing(94_000_000), llama_listing(270_000_000)
    assert run(server, tmp_path, a) == 3
    assert run(server, tmp_path, llama_listing(94_000_000, created=99)) == 0  # same model
    assert run(server, tmp_path, b) == 3  # another file behind the same alias: asked again
    assert run(server, tmp_path, a) == 0  # the first model's answers are still there


def test_a_filled_cache_replays_when_the_server_cannot_be_asked(server, tmp_path):
    b = llama_listing(270_000_000)
    assert run(server, tmp_path, llama_listing(94_000_000)) == 3
    assert run(server, tmp_path, b) == 3
    # loading (503): the identity last seen (b) keys the replay, nothing is asked
    assert run(server, tmp_path, Reply(status=503)) == 0


def test_a_rejected_key_at_the_identity_check_stops_the_run(server, tmp_path):
    server.enqueue_models(Reply(status=401))
    with pytest.raises(TransportError, match="HTTP 401"):
        make(server, tmp_path).answer_all(make_requests(2))
    assert server.calls == 0


def test_listing_identity_picks_the_requested_model_or_the_only_one():
    one = {"data": [{"id": "/models/x.gguf", "created": 1, "meta": {"size": 1}}]}
    many = {"data": [{"id": "gpt-a", "owned_by": "o"}, {"id": "gpt-b", "owned_by": "o"}]}
    assert listing_identity(one, "anything") == listing_identity(
        {"data": [{"id": "/models/x.gguf", "created": 2, "meta": {"size": 1}}]}, "x")
    assert listing_identity(many, "gpt-a") != listing_identity(many, "gpt-b")
    assert listing_identity(many, "gpt-c") is None
    assert listing_identity({"object": "list"}, "m") is None and listing_identity([], "m") is None


def llama_props(path: str = "/home/alice/models/SmolLM2-135M-Instruct.Q4_1.gguf",
                slots: int = 1, build: str = "b7000-abc") -> Reply:
    """llama.cpp's ``GET /props``: the model's path, its build, and slot settings."""
    return Reply(raw=json.dumps({"model_path": path, "build_info": build, "total_slots": slots,
                                 "model_ftype": "Q4_1",
                                 "default_generation_settings": {"n_ctx": 4096 // slots}}
                                ).encode())


def llama_server_listing(n_ctx: int, path: str = "/home/alice/models/x.gguf") -> Reply:
    """llama.cpp's listing as a server without ``--alias`` gives it: the model named by its
    path, the slot context ``n_ctx`` (``-c`` / ``-np``) beside the model's own meta."""
    return Reply(raw=json.dumps({"object": "list", "data": [
        {"id": path, "object": "model", "created": 5, "owned_by": "llamacpp",
         "meta": {"vocab_type": 2, "n_vocab": 49152, "n_ctx": n_ctx, "n_ctx_train": 8192,
                  "n_embd": 576, "n_params": 134515008, "size": 94000000,
                  "ftype": "Q4_1"}}]}).encode())


def llama_run(server, tmp_path, n_ctx: int = 4096, slots: int = 1, **kw) -> list:
    """One run of 3 records against a llama.cpp-like server; its answers."""
    server.enqueue_models(llama_server_listing(n_ctx), llama_props(slots=slots))
    respondent = make(server, tmp_path)
    for k, v in kw.items():
        setattr(respondent, k, v)
    answers = respondent.answer_all(make_requests(3))
    assert all(a.answer is not None for a in answers)
    return answers


def test_a_model_changed_in_its_weights_only_is_asked_again_and_comes_back(
        server, tmp_path, caplog):
    llama_run(server, tmp_path)
    assert server.calls == 3
    server.weights = "model-b"  # same name, file, size, parameters, build: other weights
    with caplog.at_level("WARNING", logger="popnavshift"):
        llama_run(server, tmp_path)
    assert server.calls == 6
    said = [r.getMessage() for r in caplog.records if "canary" in r.getMessage()]
    assert len(said) == 1 and "asked every record again" in said[0] and "weights changed" in said[0]
    server.weights = "model-a"  # the former model back: its answers are still there
    caplog.clear()
    with caplog.at_level("WARNING", logger="popnavshift"):
        llama_run(server, tmp_path)
    assert server.calls == 6
    said = [r.getMessage() for r in caplog.records if "canary" in r.getMessage()]
    # one line says it changed back, and claims no record is asked again: none is
    assert len(said) == 1 and "its records are asked again" not in said[0], said
    assert "only answers this model gave are taken from the cache" in said[0]


def test_a_restart_with_other_slots_or_context_asks_nothing_again(server, tmp_path):
    llama_run(server, tmp_path, n_ctx=4096, slots=1)
    llama_run(server, tmp_path, n_ctx=2048, slots=2)
    llama_run(server, tmp_path, n_ctx=8192, slots=4)
    assert server.calls == 3


def test_a_server_that_answers_the_canaries_differently_each_time_keeps_its_cache(
        server, tmp_path, caplog):
    server.unstable_canaries = True
    llama_run(server, tmp_path)
    with caplog.at_level("WARNING", logger="popnavshift"):
        llama_run(server, tmp_path)
    assert server.calls == 3  # nothing asked again: a swap cannot be seen, and it says so
    assert any("differently twice in a row" in r.getMessage() for r in caplog.records)


def test_a_model_sha256_keys_the_cache_and_is_recorded(server, tmp_path):
    digest_a, digest_b = "a" * 64, "B" * 64
    [first, *_] = llama_run(server, tmp_path, model_sha256=digest_a)
    llama_run(server, tmp_path, model_sha256=digest_a)
    assert server.calls == 3
    llama_run(server, tmp_path, model_sha256=digest_b)
    assert server.calls == 6
    respondent = make(server, tmp_path)
    respondent.model_sha256 = "not-a-digest"
    with pytest.raises(ConfigError, match="model_sha256 must be None or the 64 hex digits"):
        respondent.answer_all(make_requests(1))


def test_records_hold_the_identity_without_a_machine_path(server, tmp_path):
    respondent = make(server, tmp_path)
    server.enqueue_models(llama_server_listing(4096), llama_props())
    server.responder = lambda rec: Reply(model="/home/alice/models/x.gguf")
    answers = respondent.answer_all(make_requests(2))
    details = respondent.served_details
    assert {a.served_model for a in answers} == {"x.gguf"}
    assert details["model_file"] == "SmolLM2-135M-Instruct.Q4_1.gguf"
    assert (details["model_quant"], details["server_build"]) == ("Q4_1", "b7000-abc")
    assert (details["model_size"], details["model_params"]) == (94e6, 134515008.0)
    assert len(details["model_canaries"]) == 64
    assert "/home/alice" not in json.dumps(details)
    # the cached answers come back without the path too
    server.enqueue_models(llama_server_listing(4096), llama_props())
    again = make(server, tmp_path).answer_all(make_requests(2))
    assert {a.served_model for a in again} == {"x.gguf"} and all(a.cached for a in again)


def test_no_fingerprint_when_switched_off(server, tmp_path):
    llama_run(server, tmp_path, fingerprint=False)
    assert server.canary_calls == 0
