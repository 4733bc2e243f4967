"""Time limits and request fields that hold: the stage's deadline (calls in flight
included), a hanging server named within a few timeouts, a Retry-After beyond the cap,
the requests in flight on the progress line, a validated ``extra_body``, ``api_key_env``
none, and the Python API's one-line errors."""

from __future__ import annotations

import threading
import time

import pytest

from llm_server import Reply, make_requests, rate_limited, serve
from popnavshift.errors import ConfigError, TransportError
from popnavshift.responses.llm import OpenAIRespondent
from popnavshift.responses.llm.settings import MAX_EXTRA_BODY


@pytest.fixture
def server():
    with serve() as s:
        yield s


def make(server, tmp_path=None, **kw) -> OpenAIRespondent:
    kw.setdefault("model", "test-model")
    kw.setdefault("api_key_env", None)
    kw.setdefault("backoff_base", 0.001)
    kw.setdefault("backoff_cap", 0.01)
    if tmp_path is not None:
        kw.setdefault("cache_path", tmp_path / "cache.sqlite")
    return OpenAIRespondent(base_url=server.openai_url, **kw)


def hang(server, seconds: float = 30.0) -> None:
    """Every route accepts the request and answers nothing for ``seconds``."""
    server.enqueue_models(*[Reply(delay=seconds)] * 5)
    server.responder = lambda rec: Reply(delay=seconds)


def test_the_deadline_bounds_the_whole_stage_against_a_hanging_server(server, tmp_path):
    hang(server)
    started = time.monotonic()
    with pytest.raises(TransportError, match=r"deadline of 2 s was reached.*0 of 6 records"):
        make(server, tmp_path, deadline=2.0, max_concurrency=2).answer_all(make_requests(6))
    assert time.monotonic() - started < 2.0 + 3.0


def test_the_deadline_stops_calls_in_flight_and_keeps_what_was_answered(server, tmp_path):
    server.enqueue(Reply(), Reply())  # two answered at once, then the server hangs
    server.responder = lambda rec: Reply(delay=30)
    started = time.monotonic()
    with pytest.raises(TransportError, match=r"2 of 5 records answered.*run the same command"):
        make(server, tmp_path, deadline=4.0, max_concurrency=1, timeout=60
             ).answer_all(make_requests(5))
    assert time.monotonic() - started < 4.0 + 3.0
    server.responder = None  # the server recovers: the two answered are not asked again
    before = server.calls
    answers = make(server, tmp_path).answer_all(make_requests(5))
    assert all(a.answer is not None for a in answers) and server.calls - before == 3


def test_a_hanging_server_is_named_within_two_timeouts(server, tmp_path):
    server.responder = lambda rec: Reply(delay=30)  # its model list answers, chats hang
    started = time.monotonic()
    with pytest.raises(TransportError, match="answered nothing for .* the server hangs"):
        make(server, tmp_path, timeout=1.0, max_retries=5, max_concurrency=2
             ).answer_all(make_requests(8))
    assert time.monotonic() - started < 1.0 * 2 + 3.0


def test_a_retry_after_beyond_the_cap_stops_at_once_with_one_line(server, tmp_path):
    server.responder = lambda rec: rate_limited("3600")
    started = time.monotonic()
    with pytest.raises(TransportError) as err:
        make(server, tmp_path, max_retry_after=60).answer_all(make_requests(4))
    assert time.monotonic() - started < 5
    text = str(err.value)
    assert "asks to wait 3600 s (Retry-After), more than max_retry_after 60 s" in text
    assert "--max-retry-after" in text and "\n" not in text


def test_the_progress_note_counts_requests_in_flight(server):
    release = threading.Event()
    server.responder = lambda rec: (release.wait(10), Reply())[1]
    respondent = make(server, max_concurrency=3)
    worker = threading.Thread(target=respondent.answer_all, args=(make_requests(3),))
    worker.start()
    try:
        for _ in range(100):
            if respondent.progress_note().startswith("3 in flight"):
                break
            time.sleep(0.05)
        assert respondent.progress_note().startswith("3 in flight, 0 calls")
    finally:
        release.set()
        worker.join(10)
    assert respondent.progress_note().startswith("0 in flight, 3 calls")


@pytest.mark.parametrize(("extra", "said"), [
    ("cache_prompt", "extra_body must be a mapping of request fields"),
    ([["cache_prompt", False]], "extra_body must be a mapping of request fields"),
    ({"stream": True}, "extra_body.stream is refused: the respondent reads one JSON reply"),
    ({"n": 3}, "extra_body.n is refused: asks for several completions, all billed"),
    ({"seed": 3}, "extra_body.seed is refused: set by the respondent's own option"),
    ({"pad": "x" * MAX_EXTRA_BODY}, "more than 4,096"),
    ({"when": object()}, "extra_body must hold JSON values only"),
])
def test_extra_body_is_checked_before_any_call_with_a_reason(server, extra, said):
    with pytest.raises(ConfigError, match=said.replace("(", r"\(")):
        make(server, extra_body=extra).answer_all(make_requests(1))
    assert server.calls == 0 and server.model_checks == 0


@pytest.mark.parametrize("value", ["none", "None", "", "null"])
def test_api_key_env_none_sends_no_key_in_the_api_as_on_the_cli(server, monkeypatch, value):
    monkeypatch.delenv("none", raising=False)
    make(server, api_key_env=value).answer_all(make_requests(1))
    assert "authorization" not in server.requests[0].headers


def test_a_key_given_as_api_key_env_is_refused_without_echoing_it(server):
    secret = "sk-live-0123456789abcdef"
    with pytest.raises(ConfigError) as err:
        make(server, api_key_env=secret).answer_all(make_requests(1))
    assert secret not in str(err.value) and "api_key_env must name an environment" in str(
        err.value)


def test_the_removed_replicate_option_gets_the_cli_s_message_in_the_api():
    with pytest.raises(ConfigError, match="replicate was removed.*samples"):
        OpenAIRespondent(replicate=1)
