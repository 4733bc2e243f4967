"""The gemini respondent (google-genai SDK) against a scripted server on 127.0.0.1."""

from __future__ import annotations

import json
import logging
import sys

import pytest

from llm_server import (
    Reply,
    make_requests,
    malformed,
    rate_limited,
    serve,
    server_error,
    slow,
    truncated,
    valid_answer,
    wrong_enum,
)
from popnavshift.errors import ConfigError, MissingKeyError
from popnavshift.responses.llm import GeminiRespondent, ResponseCache
from popnavshift.responses.prompt import SYSTEM_PROMPT, build_prompt
from popnavshift.responses.schema import response_json_schema

pytest.importorskip("google.genai")

KEY = "AIza-test-SECRET-9876543210fedcba"


@pytest.fixture
def server():
    with serve() as s:
        yield s


@pytest.fixture(autouse=True)
def _key(monkeypatch):
    monkeypatch.delenv("GOOGLE_API_KEY", raising=False)
    monkeypatch.setenv("GEMINI_API_KEY", KEY)


def make(server, tmp_path=None, **kw) -> GeminiRespondent:
    kw.setdefault("model", "gemini-test")
    kw.setdefault("max_retries", 2)
    kw.setdefault("backoff_base", 0.001)
    kw.setdefault("backoff_cap", 0.01)
    kw.setdefault("timeout", 5.0)
    if tmp_path is not None:
        kw.setdefault("cache_path", tmp_path / "cache.sqlite")
    return GeminiRespondent(base_url=server.root, **kw)


def test_request_body_headers_and_answer(server, tmp_path):
    req = make_requests(1)[0]
    respondent = make(server, tmp_path, temperature=0.2, seed=5)
    [ans] = respondent.answer_all([req])
    assert ans.error is None
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts, ans.cached) == (1, 1, False)
    assert ans.tokens == {"prompt": 100, "completion": 20, "total": 120}
    [rec] = server.requests
    assert rec.path == "/v1beta/models/gemini-test:generateContent"
    assert rec.headers["x-goog-api-key"] == KEY
    gen = rec.body["generationConfig"]
    assert gen["responseMimeType"] == "application/json"
    assert gen["responseJsonSchema"] == response_json_schema()
    assert "responseSchema" not in gen
    assert (gen["temperature"], gen["seed"]) == (0.2, 5)
    assert rec.body["systemInstruction"]["parts"] == [{"text": SYSTEM_PROMPT}]
    assert rec.body["contents"] == [{"parts": [{"text": build_prompt(req.persona)}],
                                     "role": "user"}]
    # The cache key is computed from exactly the body that went over the wire.
    assert rec.body == respondent._body(req.persona, ())
    assert respondent.endpoint == server.root + rec.path


def test_invalid_content_is_reasked_then_capped(server, tmp_path):
    server.enqueue(malformed(), wrong_enum(), wrong_enum())
    [ans] = make(server, tmp_path).answer_all(make_requests(1))
    assert ans.answer is None
    assert ans.error.startswith("invalid after 3 attempts")
    assert (ans.calls, ans.attempts) == (3, 3)
    assert ans.tokens == {"prompt": 300, "completion": 60, "total": 360}
    contents = server.requests[2].body["contents"]
    assert [c["role"] for c in contents] == ["user", "model", "user", "model", "user"]
    assert "not valid" in contents[2]["parts"][0]["text"]
    with ResponseCache(tmp_path / "cache.sqlite") as cache:
        assert cache.count() == 0
        errors = [f["error"] for f in cache.failures()]
        assert len(errors) == 3


def test_max_output_tokens_is_sent_and_doubled_after_a_cut_reply(server, tmp_path):
    server.enqueue(truncated(), Reply(model="gemini-test-001"))
    [ans] = make(server, tmp_path, max_tokens=256).answer_all(make_requests(1))
    assert ans.answer == valid_answer() and ans.served_model == "gemini-test-001"
    limits = [r.body["generationConfig"]["maxOutputTokens"] for r in server.requests]
    assert limits == [256, 512]
    assert len(server.requests[1].body["contents"]) == 1  # sent again, not re-asked


def test_sdk_retries_are_off_and_ours_are_counted(server):
    server.enqueue(rate_limited("0"), server_error(500), Reply())
    [ans] = make(server).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts, server.calls) == (3, 1, 3)


def test_retry_info_delay_is_honoured(server):
    body = {"error": {"code": 429, "status": "RESOURCE_EXHAUSTED", "message": "quota",
                      "details": [{"@type": "type.googleapis.com/google.rpc.RetryInfo",
                                   "retryDelay": "0.6s"}]}}
    server.enqueue(Reply(status=429, raw=json.dumps(body).encode()), Reply())
    [ans] = make(server).answer_all(make_requests(1))
    assert ans.calls == 2
    assert server.requests[1].time - server.requests[0].time >= 0.55


def test_exhausted_retries_and_timeouts(server):
    server.enqueue(slow(1.0), Reply())
    [ok] = make(server, timeout=0.3).answer_all(make_requests(1))
    assert (ok.answer is not None, ok.calls) == (True, 2)
    server.responder = lambda rec: server_error(503)
    [bad] = make(server).answer_all(make_requests(1))
    assert bad.error == "transport: HTTP 503 after 2 retries"
    assert bad.calls == 3


def test_second_run_zero_calls_and_key_never_stored_or_logged(server, tmp_path, caplog):
    caplog.set_level(logging.DEBUG)
    server.enqueue(wrong_enum())
    reqs = make_requests(4)
    first = make(server, tmp_path, max_concurrency=2).answer_all(reqs)
    assert all(a.answer is not None for a in first)
    assert server.calls == 5
    second = make(server, tmp_path).answer_all(reqs)
    assert server.calls == 5
    assert all(a.cached and a.calls == 0 for a in second)
    for f in tmp_path.glob("cache.sqlite*"):
        assert KEY.encode() not in f.read_bytes()
    assert caplog.records
    assert KEY not in caplog.text


def test_google_api_key_fallback_and_missing_key(server, monkeypatch):
    monkeypatch.delenv("GEMINI_API_KEY")
    monkeypatch.setenv("GOOGLE_API_KEY", "fallback-key")
    make(server).answer_all(make_requests(1))
    assert server.requests[0].headers["x-goog-api-key"] == "fallback-key"
    monkeypatch.delenv("GOOGLE_API_KEY")
    with pytest.raises(MissingKeyError, match="GEMINI_API_KEY or GOOGLE_API_KEY"):
        make(server).answer_all(make_requests(1))
    with pytest.raises(MissingKeyError, match="VERTEX_KEY"):
        make(server, api_key_env="VERTEX_KEY").answer_all(make_requests(1))
    assert server.calls == 1


def test_missing_sdk_gives_install_hint(server, monkeypatch):
    monkeypatch.setitem(sys.modules, "google.genai", None)
    with pytest.raises(ConfigError, match=r"pip install 'popnavshift\[gemini\]'"):
        make(server).answer_all(make_requests(1))
    assert server.calls == 0


def test_concurrency_limit_is_respected(server):
    server.responder = lambda rec: slow(0.15)
    answers = make(server, max_concurrency=2).answer_all(make_requests(6))
    assert all(a.answer is not None for a in answers)
    assert server.max_in_flight == 2


def test_each_sample_sends_its_own_generation_seed(server, tmp_path):
    import dataclasses

    from popnavshift.responses.respondent import sample_seed

    reqs = make_requests(2)
    asked = [*reqs, *(dataclasses.replace(r, sample=1) for r in reqs)]
    answers = make(server, tmp_path, seed=5).answer_all(asked)
    assert all(a.answer is not None for a in answers) and server.calls == 4
    seeds = sorted(r.body["generationConfig"]["seed"] for r in server.requests)
    assert seeds == sorted([5, 5, sample_seed(5, 1), sample_seed(5, 1)])
    assert make(server, tmp_path, seed=5).answer_all(asked)[3].cached and server.calls == 4
