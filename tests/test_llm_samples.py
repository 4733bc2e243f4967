"""Independent samples, server-specific fields and the served model's identity, against
the loopback server: each sample sends its own seed and has its own cache entry; the
responses table has a ``sample`` column and the identity columns (a file name, never a
path); ``extra_body`` reaches the request and the key; the manifest names the endpoint
and the samples; wording of authentication and JSON errors; short keys redacted."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pandas as pd
import pytest

from cli_helpers import cli, tiny_study
from forked_cli import run_cli
from llm_server import Reply, make_requests, serve, valid_text
from popnavshift.design.study import study_from_dict
from popnavshift.errors import ConfigError, RespondentError, TransportError
from popnavshift.progress import PlainLines
from popnavshift.redact import MASK, redact, register_secret
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.llm import OpenAIRespondent
from popnavshift.responses.respondent import sample_seed
from popnavshift.responses.schema import parse_answer

MACHINE_PATH = "/home/someone/models/qwen2.5-0.5b-instruct-q4_k_m.gguf"


@pytest.fixture
def server():
    with serve() as s:
        yield s


def personas_frame(n: int) -> pd.DataFrame:
    reqs = make_requests(n)
    return pd.DataFrame([{"persona_id": r.persona_id, "source": "test", **r.persona}
                         for r in reqs])


def make(server, tmp_path: Path, **kw) -> OpenAIRespondent:
    return OpenAIRespondent(base_url=server.openai_url, model="local", api_key_env=None,
                            cache_path=tmp_path / "cache.sqlite", timeout=5.0, max_retries=0,
                            **kw)


def test_each_sample_sends_its_own_seed_and_is_cached_apart(server, tmp_path):
    personas = personas_frame(4)
    responses, invalid, stats = collect_responses(personas, make(server, tmp_path, seed=7),
                                                  samples=3)
    assert invalid.empty and stats["samples"] == 3
    assert sorted(responses["sample"].value_counts().to_dict().items()) == [(0, 4), (1, 4),
                                                                             (2, 4)]
    seeds = {(r.body["seed"]) for r in server.requests}
    assert seeds == {sample_seed(7, s) for s in range(3)} and len(seeds) == 3
    assert sample_seed(7, 0) == 7  # a one-sample study asks what it always asked
    again, _, stats = collect_responses(personas, make(server, tmp_path, seed=7), samples=3)
    assert stats["calls"] == 0 and server.calls == 12
    pd.testing.assert_frame_equal(again, responses)
    _, _, stats = collect_responses(personas, make(server, tmp_path, seed=8), samples=1)
    assert stats["calls"] == 4  # another seed is another request


def test_samples_without_a_seed_are_refused_before_any_call(server, tmp_path):
    with pytest.raises(ConfigError, match="several samples need a seed"):
        collect_responses(personas_frame(2), make(server, tmp_path, seed=None), samples=2)
    assert server.calls == 0


def test_extra_body_reaches_the_request_and_the_key(server, tmp_path):
    reqs = make_requests(2)
    make(server, tmp_path).answer_all(reqs)
    make(server, tmp_path, extra_body={"cache_prompt": False}).answer_all(reqs)
    make(server, tmp_path, extra_body={"cache_prompt": False}).answer_all(reqs)
    assert server.calls == 4
    assert [r.body.get("cache_prompt") for r in server.requests] == [None, None, False, False]
    with pytest.raises(ConfigError, match="extra_body.seed is refused: set by the respondent"):
        make(server, tmp_path, extra_body={"seed": 3}).answer_all(reqs)


def llama_listing() -> Reply:
    return Reply(raw=json.dumps({"object": "list", "data": [
        {"id": "local", "object": "model", "created": 1, "owned_by": "llamacpp",
         "meta": {"n_params": 494032768, "size": 397807616}}]}).encode())


def llama_props() -> Reply:
    return Reply(raw=json.dumps({"model_path": MACHINE_PATH,
                                 "build_info": "b6123-abcdef0"}).encode())


def test_the_served_model_is_recorded_by_file_name_never_by_path(server, tmp_path):
    server.enqueue_models(llama_listing(), llama_props())
    server.responder = lambda rec: Reply(raw=json.dumps({
        "model": "local", "system_fingerprint": "b6123-abcdef0", "choices": [{
            "message": {"content": valid_text()},
            "finish_reason": "stop"}]}).encode())
    responses, _, stats = collect_responses(personas_frame(3), make(server, tmp_path))
    row = responses.iloc[0]
    assert row["model_file"] == "qwen2.5-0.5b-instruct-q4_k_m.gguf"
    assert row["model_quant"] == "Q4_K_M"
    assert (row["model_size"], row["model_params"]) == (397807616.0, 494032768.0)
    assert row["server_build"] == "b6123-abcdef0" == row["system_fingerprint"]
    assert stats["served"]["model_file"] == "qwen2.5-0.5b-instruct-q4_k_m.gguf"
    assert "/home/someone" not in responses.to_csv() + json.dumps(stats)
    # offline replay (the server loading): the same table from the cache and the last identity
    server.enqueue_models(Reply(status=503))
    again, _, stats = collect_responses(personas_frame(3), make(server, tmp_path))
    assert stats["calls"] == 0
    pd.testing.assert_frame_equal(again, responses)


@pytest.mark.parametrize("name, tag", [
    ("Llama-3.2-1B-Instruct-IQ3_XXS.gguf", "IQ3_XXS"), ("gemma-3-4b-it-Q8_0.gguf", "Q8_0"),
    ("Qwen2-7B-bf16.gguf", "BF16"), ("phi3-mini.gguf", None)])
def test_the_quantisation_is_the_file_name_tag(name, tag):
    from popnavshift.responses.llm.identity import quant_tag

    assert quant_tag(name) == tag


def test_a_rejected_key_reads_as_authentication_naming_the_url(server, tmp_path):
    server.enqueue_models(Reply(status=403))
    with pytest.raises(TransportError, match="authentication failed") as info:
        make(server, tmp_path).answer_all(make_requests(1))
    assert f"GET {server.openai_url}/models" in str(info.value)
    assert "API key" in str(info.value.hint)


def test_json_errors_do_not_say_at_at():
    with pytest.raises(RespondentError) as info:
        parse_answer('{"actions": "unterminated')
    assert "at at" not in str(info.value) and "starting at char" in str(info.value)


def test_a_short_key_is_redacted_where_it_stands_alone():
    register_secret("k3y9")
    assert redact("key k3y9 rejected") == f"key {MASK} rejected"
    assert redact("monk3y9s") == "monk3y9s"  # inside a longer word: not a key, left alone


def test_plain_progress_lines_count_calls_retries_and_failures(capsys):
    with PlainLines("probing (openai)", 4, "records", lambda: "7 calls, 3 retries, 0 failed",
                    every=0.05) as lines:
        lines.advance(2)
        time.sleep(0.2)
    err = capsys.readouterr().err.splitlines()
    assert "probing (openai): 2/4 records, 7 calls, 3 retries, 0 failed" in err


def test_study_samples_and_the_removed_replicate():
    study = study_from_dict({"name": "s", "respondent": {"name": "openai", "samples": 2},
                             "parts": {"main": {}}})
    assert study.respondent.samples == 2
    with pytest.raises(ConfigError, match="replicate was removed"):
        study_from_dict({"name": "s", "respondent": {"name": "openai",
                                                     "options": {"replicate": 1}},
                         "parts": {"main": {}}})


def test_a_study_with_two_samples_end_to_end(tmp_path):
    with serve() as server:
        options = (f"{{base_url: '{server.openai_url}', model: test-model, api_key_env: null, "
                   "temperature: 0.7, extra_body: {cache_prompt: false}}")
        respondent = f"respondent: {{name: openai, samples: 2, options: {options}}}\n"
        proc = cli("run", str(tiny_study(tmp_path, n=30, respondent=respondent)),
                   "--out", str(tmp_path / "s"), "--no-report", "-w", "1")
        assert proc.returncode == 0, proc.stderr
        assert server.calls == 2 * 40  # 30 personas + 10 matched, twice
        assert len({r.body["seed"] for r in server.requests}) == 2
    responses = pd.read_parquet(tmp_path / "s" / "responses.parquet")
    assert len(responses) == 80 and set(responses["sample"]) == {0, 1}
    profiles = pd.read_parquet(tmp_path / "s" / "profiles.parquet")
    assert not profiles.duplicated(["persona_id", "variant", "mapping"]).any()
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())["respondent"]
    assert manifest["endpoint"] == server.openai_url + "/chat/completions"
    assert manifest["samples"] == 2 and manifest["extra_body"] == {"cache_prompt": False}
    assert "median" in manifest["aggregation"]
    audit = run_cli("audit", str(tmp_path / "s"), "--permutations", "319", "--boot", "100")
    assert audit.returncode == 0, audit.stderr
    assert "test–retest: 2 samples of 40 records" in audit.stdout  # its tables are its output


def test_samples_without_a_seed_are_refused_by_the_study_check_before_any_stage():
    from popnavshift.engine.validate import validate_study
    from popnavshift.episodes.specs import all_episodes

    data = {"name": "s", "parts": {"main": {"populations": ["mixed"]}},
            "respondent": {"name": "openai", "samples": 2,
                           "options": {"seed": None, "api_key_env": None,
                                       "base_url": "http://127.0.0.1:9/v1"}}}
    with pytest.raises(ConfigError, match="samples 2 need a seed"):
        validate_study(study_from_dict(data), all_episodes(0))
    data["respondent"]["samples"] = 1
    validate_study(study_from_dict(data), all_episodes(0))  # one sample needs none
