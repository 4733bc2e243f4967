"""The served model's identity in the cache key: a model swapped behind one URL is never
served from the cache, the former model's answers come back when it does, and a filled
cache still replays when the server cannot be asked."""

from __future__ import annotations

import json

import pytest

from llm_server import Reply, make_requests, serve
from popnavshift.errors import TransportError
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
