"""The openai respondent against a scripted chat-completions server on 127.0.0.1."""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from pathlib import Path

import pytest

from llm_server import (
    Reply,
    fenced,
    make_requests,
    malformed,
    missing_keys,
    rate_limited,
    serve,
    server_error,
    slow,
    truncated,
    valid_answer,
    valid_text,
    wrong_enum,
)
from popnavshift.errors import ConfigError, MissingKeyError, TransportError
from popnavshift.responses.llm import OpenAIRespondent, ResponseCache
from popnavshift.responses.prompt import SYSTEM_PROMPT, build_prompt
from popnavshift.responses.schema import response_json_schema

KEY = "sk-test-SECRET-0123456789abcdef"


@pytest.fixture
def server():
    with serve() as s:
        yield s


@pytest.fixture(autouse=True)
def _key(monkeypatch):
    monkeypatch.setenv("OPENAI_API_KEY", KEY)


def make(server, tmp_path: Path | None = None, **kw) -> OpenAIRespondent:
    kw.setdefault("model", "test-model")
    kw.setdefault("max_retries", 2)
    kw.setdefault("backoff_base", 0.001)
    kw.setdefault("backoff_cap", 0.01)
    kw.setdefault("timeout", 5.0)
    if tmp_path is not None:
        kw.setdefault("cache_path", tmp_path / "cache.sqlite")
    return OpenAIRespondent(base_url=server.openai_url, **kw)


def test_request_body_headers_and_answer(server, tmp_path):
    req = make_requests(1)[0]
    [ans] = make(server, tmp_path, temperature=0.3, seed=11).answer_all([req])
    assert ans.error is None
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts, ans.cached) == (1, 1, False)
    assert ans.tokens == {"prompt": 100, "completion": 20, "total": 120}
    [rec] = server.requests
    assert rec.path == "/v1/chat/completions"
    assert rec.headers["authorization"] == f"Bearer {KEY}"
    body = rec.body
    assert (body["model"], body["temperature"], body["seed"]) == ("test-model", 0.3, 11)
    assert body["messages"] == [
        {"role": "system", "content": SYSTEM_PROMPT},
        {"role": "user", "content": build_prompt(req.persona)},
    ]
    fmt = body["response_format"]
    assert fmt["type"] == "json_schema"
    assert fmt["json_schema"]["strict"] is True
    assert fmt["json_schema"]["name"] == "probe_answers"
    assert fmt["json_schema"]["schema"] == response_json_schema()


def test_none_temperature_and_seed_are_left_out(server):
    make(server, temperature=None, seed=None).answer_all(make_requests(1))
    assert "temperature" not in server.requests[0].body
    assert "seed" not in server.requests[0].body


def test_fenced_json_is_accepted_without_reask(server):
    server.enqueue(fenced())
    [ans] = make(server).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts) == (1, 1)


@pytest.mark.parametrize("bad", [wrong_enum, missing_keys, malformed])
def test_invalid_content_is_reasked_in_the_conversation(server, tmp_path, bad):
    first = bad()
    server.enqueue(first, Reply(usage=(130, 25)))
    respondent = make(server, tmp_path)
    [ans] = respondent.answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts) == (2, 2)
    assert ans.tokens == {"prompt": 230, "completion": 45, "total": 275}
    reask = server.requests[1].body["messages"]
    assert len(reask) == 4
    assert reask[2] == {"role": "assistant", "content": first.text}
    assert reask[3]["role"] == "user"
    assert "not valid" in reask[3]["content"]
    with ResponseCache(tmp_path / "cache.sqlite") as cache:
        [failure] = cache.failures()
        assert failure["raw"] == first.text
        assert cache.count() == 1


def test_reasks_are_capped_and_invalid_record_is_not_cached(server, tmp_path):
    server.responder = lambda rec: wrong_enum()
    respondent = make(server, tmp_path)
    [ans] = respondent.answer_all(make_requests(1))
    assert ans.answer is None
    assert ans.error.startswith("invalid after 3 attempts")
    assert "teleport" in ans.error
    assert (ans.calls, ans.attempts, server.calls) == (3, 3, 3)
    assert ans.tokens["total"] == 3 * 120
    with ResponseCache(tmp_path / "cache.sqlite") as cache:
        assert cache.count() == 0
        failures = cache.failures()
        assert len(failures) == 3
        assert len({f["request_hash"] for f in failures}) == 3  # each re-ask is a new request
    # A failure is never served: the next run asks again.
    [again] = respondent.answer_all(make_requests(1))
    assert (again.cached, again.calls, server.calls) == (False, 3, 6)


def test_max_reasks_zero_means_one_attempt(server):
    server.responder = lambda rec: malformed()
    [ans] = make(server, max_reasks=0).answer_all(make_requests(1))
    assert (ans.calls, ans.attempts) == (1, 1)
    assert ans.error.startswith("invalid after 1 attempts")


def test_429_and_5xx_are_retried_without_a_reask(server, tmp_path):
    server.enqueue(rate_limited("0"), server_error(503), Reply())
    [ans] = make(server, tmp_path).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts) == (3, 1)
    assert ans.tokens["total"] == 120  # failed exchanges carry no usage


def test_retry_after_is_honoured(server):
    server.enqueue(rate_limited("1"), Reply())
    [ans] = make(server, backoff_cap=0.01).answer_all(make_requests(1))
    assert ans.calls == 2
    gap = server.requests[1].time - server.requests[0].time
    assert gap >= 0.95


def test_transport_failure_after_retries_is_reported_not_raised(server, tmp_path):
    server.responder = lambda rec: server_error(503)
    reqs = make_requests(2)
    answers = make(server, tmp_path, max_retries=3).answer_all(reqs)
    assert [a.error for a in answers] == ["transport: HTTP 503 after 3 retries"] * 2
    assert [a.calls for a in answers] == [4, 4]
    assert server.calls == 8
    with ResponseCache(tmp_path / "cache.sqlite") as cache:
        assert cache.count() == 0
        assert len(cache.failures()) == 2


def test_timeout_is_retried(server):
    server.enqueue(slow(3.0), Reply())
    t0 = time.monotonic()
    [ans] = make(server, timeout=0.25).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert ans.calls == 2
    assert time.monotonic() - t0 < 2.0  # the slow reply was abandoned, not awaited


def test_an_unreachable_server_stops_the_run_after_the_readiness_wait(tmp_path):
    with serve() as gone:
        url = gone.openai_url
    respondent = OpenAIRespondent(base_url=url, max_retries=5, backoff_base=0.001,
                                  ready_timeout=0.6)
    t0 = time.monotonic()
    with pytest.raises(TransportError, match=r"not ready after waiting 0.6 s: connection error"):
        respondent.answer_all(make_requests(20))
    assert 0.6 <= time.monotonic() - t0 < 5.0  # bounded, not 20 records × 5 retries


def test_a_loading_server_is_waited_for(server, tmp_path):
    """llama.cpp answers 503 while it loads the model: wait, then run."""
    server.enqueue_models(Reply(status=503), Reply(status=503))
    [ans] = make(server, tmp_path, ready_timeout=10).answer_all(make_requests(1))
    assert ans.answer == valid_answer() and server.model_checks == 3 and server.calls == 1


def test_a_rejected_key_stops_at_the_readiness_check(server, tmp_path):
    server.enqueue_models(Reply(status=401, raw=json.dumps(
        {"error": {"message": f"Incorrect API key provided: {KEY}"}}).encode()))
    with pytest.raises(TransportError, match="HTTP 401") as info:
        make(server, tmp_path).answer_all(make_requests(3))
    assert server.calls == 0 and server.model_checks == 1
    assert KEY not in str(info.value) and "***" in str(info.value)


def test_consecutive_transport_failures_trip_the_breaker(server, tmp_path):
    server.responder = lambda rec: Reply(status=500)
    respondent = make(server, tmp_path, max_concurrency=1, max_consecutive_failures=3)
    with pytest.raises(TransportError, match="3 records in a row failed"):
        respondent.answer_all(make_requests(50))
    assert server.calls == 3 * 3  # three records × (1 call + 2 retries), then stop


def test_a_success_resets_the_breaker(server, tmp_path):
    server.enqueue(*[Reply(status=500)] * 6, Reply(), *[Reply(status=500)] * 6, Reply())
    answers = make(server, tmp_path, max_concurrency=1, max_retries=2,
                   max_consecutive_failures=3).answer_all(make_requests(6))
    assert [a.answer is not None for a in answers] == [False, False, True] * 2


def test_max_tokens_is_sent_and_a_truncated_reply_gets_twice_the_room(server, tmp_path):
    server.enqueue(truncated(), Reply())
    [ans] = make(server, tmp_path, max_tokens=300).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    first, second = (r.body for r in server.requests)
    assert first["max_tokens"] == 300 and second["max_tokens"] == 600
    assert len(second["messages"]) == 2  # sent again, not re-asked with the cut reply


def test_a_truncated_reply_without_a_limit_is_not_reasked(server, tmp_path):
    server.enqueue(truncated(), Reply())
    [ans] = make(server, tmp_path).answer_all(make_requests(1))
    assert ans.answer is None and "--max-tokens" in ans.error and server.calls == 1
    assert "max_tokens" not in server.requests[0].body


def test_the_served_model_is_recorded_and_cached(server, tmp_path):
    server.responder = lambda rec: Reply(model="test-model-2026-01-01")
    [ans] = make(server, tmp_path).answer_all(make_requests(1))
    assert ans.served_model == "test-model-2026-01-01"
    [again] = make(server, tmp_path).answer_all(make_requests(1))
    assert again.cached and again.served_model == "test-model-2026-01-01"


def test_other_4xx_is_final(server):
    server.enqueue(Reply(status=400))
    [ans] = make(server).answer_all(make_requests(1))
    assert ans.error == "transport: HTTP 400: scripted failure"
    assert server.calls == 1


def test_401_stops_the_run(server, tmp_path):
    server.responder = lambda rec: Reply(status=401)
    with pytest.raises(TransportError, match="HTTP 401") as info:
        make(server, tmp_path, max_concurrency=1).answer_all(make_requests(5))
    assert server.calls == 1
    assert KEY not in str(info.value)


def test_second_identical_run_makes_zero_calls(server, tmp_path):
    server.responder = lambda rec: Reply(text=valid_text(len(rec.body["messages"][1]["content"])))
    reqs = make_requests(6)
    first = make(server, tmp_path).answer_all(reqs)
    assert server.calls == 6
    ticks: list[int] = []
    respondent = make(server, tmp_path)
    second = respondent.answer_all(reqs, progress=ticks.append)
    assert server.calls == 6
    assert ticks == [1] * 6
    assert all(a.cached and a.calls == 0 for a in second)
    assert [a.answer for a in second] == [a.answer for a in first]
    assert [a.tokens for a in second] == [a.tokens for a in first]
    assert [a.persona_id for a in second] == [r.persona_id for r in reqs]
    stats = respondent.cache_stats
    assert (stats.hits, stats.misses, stats.stored) == (6, 0, 0)


def test_sample_and_model_change_the_key(server, tmp_path):
    reqs = make_requests(1)
    again = [dataclasses.replace(r, sample=1) for r in reqs]
    make(server, tmp_path).answer_all(reqs)
    make(server, tmp_path).answer_all(again)
    make(server, tmp_path, model="other").answer_all(reqs)
    make(server, tmp_path).answer_all(again)
    assert server.calls == 3
    seeds = [r.body["seed"] for r in server.requests]
    assert seeds[0] == 0 and seeds[1] not in (None, 0)  # sample 1 sends its own seed


def test_cached_answers_need_no_key(server, tmp_path, monkeypatch):
    reqs = make_requests(2)
    make(server, tmp_path).answer_all(reqs)
    monkeypatch.delenv("OPENAI_API_KEY")
    assert all(a.cached for a in make(server, tmp_path).answer_all(reqs))
    with pytest.raises(MissingKeyError, match="OPENAI_API_KEY"):
        make(server, tmp_path).answer_all(make_requests(3))
    assert server.calls == 2


def test_missing_key_raises_before_any_call(server, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY")
    with pytest.raises(MissingKeyError, match="OPENAI_API_KEY"):
        make(server).answer_all(make_requests(2))
    monkeypatch.setenv("MY_LLM_KEY", "")
    with pytest.raises(MissingKeyError, match="MY_LLM_KEY"):
        make(server, api_key_env="MY_LLM_KEY").answer_all(make_requests(2))
    assert server.calls == 0


def test_local_server_without_key(server, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY")
    [ans] = make(server, api_key_env=None).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert "authorization" not in server.requests[0].headers


def test_key_never_reaches_cache_file_or_logs(server, tmp_path, caplog):
    server.enqueue(rate_limited("0"), malformed(), Reply(status=400, raw=json.dumps(
        {"error": {"message": f"Incorrect API key provided: {KEY}"}}).encode()))
    caplog.set_level(logging.DEBUG)
    answers = make(server, tmp_path).answer_all(make_requests(4))
    assert sum(a.answer is not None for a in answers) == 3
    assert server.requests[0].headers["authorization"] == f"Bearer {KEY}"  # it was sent
    files = list(tmp_path.glob("cache.sqlite*"))
    assert files
    for f in files:
        assert KEY.encode() not in f.read_bytes()
    assert caplog.records
    assert KEY not in caplog.text
    assert all(KEY not in (a.error or "") for a in answers)


def test_concurrency_limit_is_respected(server):
    server.responder = lambda rec: slow(0.25)
    answers = make(server, max_concurrency=3).answer_all(make_requests(9))
    assert all(a.answer is not None for a in answers)
    assert server.max_in_flight == 3


def test_rate_limit_spaces_calls(server):
    make(server, rate_limit=20.0, max_concurrency=4).answer_all(make_requests(5))
    times = sorted(r.time for r in server.requests)
    assert times[-1] - times[0] >= 4 / 20 - 0.02


def test_stale_cache_row_is_asked_again(server, tmp_path):
    import sqlite3

    reqs = make_requests(1)
    make(server, tmp_path).answer_all(reqs)
    db = sqlite3.connect(tmp_path / "cache.sqlite")
    db.execute("UPDATE responses SET raw = 'not json'")
    db.commit()
    db.close()
    respondent = make(server, tmp_path)
    [ans] = respondent.answer_all(reqs)
    assert (ans.cached, server.calls) == (False, 2)
    assert respondent.cache_stats.invalid == 1


@pytest.mark.parametrize(
    ("kw", "name"),
    [({"max_concurrency": 0}, "max_concurrency"), ({"timeout": -1}, "timeout"),
     ({"rate_limit": 0}, "rate_limit"), ({"max_reasks": 1.5}, "max_reasks"),
     ({"base_url": "localhost:11434"}, "base_url")],
)
def test_bad_settings_name_the_parameter(server, kw, name):
    with pytest.raises(ConfigError, match=name):
        OpenAIRespondent(**{"base_url": server.openai_url, **kw}).answer_all(make_requests(1))
    assert server.calls == 0


def test_describe_has_no_secret():
    desc = OpenAIRespondent(model="m").describe()
    assert desc["respondent"] == "openai"
    assert desc["endpoint"] == "https://api.openai.com/v1/chat/completions"
    assert KEY not in json.dumps(desc)


def test_malformed_envelope_is_retried(server):
    server.enqueue(Reply(raw=b"<html>bad gateway</html>"), Reply())
    [ans] = make(server).answer_all(make_requests(1))
    assert ans.answer == valid_answer()
    assert (ans.calls, ans.attempts) == (2, 1)


def test_backoff_is_exponential_capped_and_retry_after_wins():
    from datetime import UTC, datetime, timedelta
    from email.utils import format_datetime

    from popnavshift.responses.llm import RetryPolicy
    from popnavshift.responses.llm.retries import MAX_RETRY_AFTER, parse_retry_after

    policy = RetryPolicy(max_retries=5, backoff_base=0.5, backoff_cap=3.0)
    assert [policy.delay(n) for n in range(1, 6)] == [0.5, 1.0, 2.0, 3.0, 3.0]
    assert policy.delay(4, retry_after=0.0) == 0.0
    assert policy.delay(1, retry_after=7.0) == 7.0
    assert policy.delay(1, retry_after=1e6) == MAX_RETRY_AFTER
    assert parse_retry_after("2.5") == 2.5
    assert parse_retry_after("-3") == 0.0
    assert parse_retry_after(None) is None
    assert parse_retry_after("soon") is None
    later = format_datetime(datetime.now(UTC) + timedelta(seconds=30), usegmt=True)
    assert 25 < parse_retry_after(later) <= 30


def test_identical_requests_in_one_batch_are_asked_once(server, tmp_path):
    from popnavshift.responses.respondent import ProbeRequest

    base = make_requests(2)
    twin = ProbeRequest("p999", "baseline", dict(base[0].persona))
    answers = make(server, tmp_path).answer_all([base[0], base[1], twin])
    assert server.calls == 2
    assert [a.persona_id for a in answers] == ["p000", "p001", "p999"]
    assert (answers[2].cached, answers[2].calls) == (True, 0)
    assert answers[2].answer == answers[0].answer
    with ResponseCache(tmp_path / "cache.sqlite") as cache:
        assert cache.count() == 2
