"""A scripted loopback LLM server for the respondent tests (127.0.0.1, port 0).

It speaks both wire formats the LLM respondents use:

* OpenAI chat completions: ``POST /v1/chat/completions`` →
  ``{"choices": [{"message": {"content": ...}}], "usage": {...}}``
* Gemini generateContent: ``POST /v1beta/models/{model}:generateContent`` →
  ``{"candidates": [{"content": {"parts": [{"text": ...}]}}], "usageMetadata": {...}}``

``GET /v1/models`` (the readiness check) answers from its own FIFO
(:meth:`LLMServer.enqueue_models`), else 200 with a model list; those requests are
counted in ``model_checks``, not in ``requests``. The canary prompts of the behavioural
fingerprint (:mod:`popnavshift.responses.llm.canaries`) are answered by ``weights`` (a
stand-in for the model's weights: change it and the canary answers change) and counted
in ``canary_calls``, not in ``requests``.

Every POST request is recorded (path, headers, JSON body). Replies come from a FIFO
script (:meth:`LLMServer.enqueue`), then from a ``responder`` callable, then
default to a valid answer. A :class:`Reply` is format-agnostic: the server wraps
its ``text`` in the envelope of the path that was called.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from popnavshift.personas.fields import REQUIRED_FIELDS, vocabulary
from popnavshift.responses.llm.canaries import CANARY_PROMPTS
from popnavshift.responses.probes import PROBE_IDS
from popnavshift.responses.respondent import ProbeRequest
from popnavshift.responses.schema import LEVELS
from popnavshift.tables import ACTIONS, BLOCK_ITEMS


def make_requests(n: int, variant: str = "baseline") -> list[ProbeRequest]:
    """``n`` distinct synthetic personas (field values cycle through the vocabularies)."""
    out = []
    for i in range(n):
        persona = {f: vocabulary(f)[(i + j) % len(vocabulary(f))]
                   for j, f in enumerate(REQUIRED_FIELDS)}
        persona["time_pressure"] = vocabulary("time_pressure")[i % 4]
        persona["risk_tolerance"] = vocabulary("risk_tolerance")[i // 4 % 5]
        out.append(ProbeRequest(f"p{i:03d}", variant, persona))
    return out


def valid_answer(shift: int = 0) -> dict[str, Any]:
    """A schema-valid answer; ``shift`` varies the values deterministically."""
    return {
        "actions": {p: ACTIONS[(i + shift) % len(ACTIONS)] for i, p in enumerate(PROBE_IDS)},
        "block": {k: LEVELS[(i + shift) % len(LEVELS)] for i, k in enumerate(BLOCK_ITEMS)},
    }


def valid_text(shift: int = 0) -> str:
    return json.dumps(valid_answer(shift))


@dataclass
class Reply:
    """One scripted reply. ``raw`` (bytes) replaces the whole response body."""

    status: int = 200
    text: str | None = None  # model output; None → a valid answer
    headers: dict[str, str] = field(default_factory=dict)
    delay: float = 0.0  # s before replying (to exceed the client timeout)
    usage: tuple[int, int] = (100, 20)  # prompt, completion tokens
    finish: str = "stop"
    raw: bytes | None = None
    model: str | None = None  # the served model the envelope reports


# Named failure modes used across the tests.
def fenced() -> Reply:
    return Reply(text="```json\n" + valid_text() + "\n```")


def wrong_enum() -> Reply:
    bad = valid_answer()
    bad["actions"]["P3"] = "teleport"
    return Reply(text=json.dumps(bad))


def missing_keys() -> Reply:
    bad = valid_answer()
    del bad["block"]["trust"]
    return Reply(text=json.dumps(bad))


def malformed() -> Reply:
    return Reply(text="Sure! Here is my answer: {actions: slow")


def truncated() -> Reply:
    return Reply(text=valid_text()[:57], finish="length")


def rate_limited(retry_after: str = "0") -> Reply:
    return Reply(status=429, headers={"Retry-After": retry_after})


def server_error(status: int = 500) -> Reply:
    return Reply(status=status)


def slow(delay: float) -> Reply:
    return Reply(delay=delay)


@dataclass
class Recorded:
    path: str
    headers: dict[str, str]
    body: dict[str, Any]
    time: float  # time.monotonic() on arrival


class LLMServer(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False

    def __init__(self) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.requests: list[Recorded] = []
        self.script: deque[Reply] = deque()
        self.models_script: deque[Reply] = deque()
        self.model_checks = 0
        self.canary_calls = 0
        #: what the canaries are answered from: another value stands for other weights
        self.weights = "model-a"
        #: answer each canary differently every time (a server that is not reproducible)
        self.unstable_canaries = False
        self.responder: Callable[[Recorded], Reply] | None = None
        self.in_flight = 0
        self.max_in_flight = 0
        self.lock = threading.Lock()

    @property
    def root(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}"

    @property
    def openai_url(self) -> str:
        return self.root + "/v1"

    @property
    def calls(self) -> int:
        return len(self.requests)

    def enqueue(self, *replies: Reply) -> None:
        with self.lock:
            self.script.extend(replies)

    def enqueue_models(self, *replies: Reply) -> None:
        """Script the replies of ``GET /v1/models`` (a status, or ``raw`` bytes)."""
        with self.lock:
            self.models_script.extend(replies)

    def next_models_reply(self) -> Reply:
        with self.lock:
            self.model_checks += 1
            return self.models_script.popleft() if self.models_script else Reply()

    def next_reply(self, rec: Recorded) -> Reply:
        with self.lock:
            self.requests.append(rec)
            self.in_flight += 1
            self.max_in_flight = max(self.max_in_flight, self.in_flight)
            if self.script:
                return self.script.popleft()
        return self.responder(rec) if self.responder else Reply()

    def done(self) -> None:
        with self.lock:
            self.in_flight -= 1

    def handle_error(self, request, client_address) -> None:
        # The client gave up on a slow reply and closed the socket: expected.
        pass


class _Handler(BaseHTTPRequestHandler):
    server: LLMServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args: Any) -> None:  # keep test output clean
        pass

    def do_GET(self) -> None:  # noqa: N802 (http.server naming)
        reply = self.server.next_models_reply()
        if reply.delay:
            time.sleep(reply.delay)
        if reply.raw is None and reply.status == 200:
            reply = Reply(raw=json.dumps(
                {"object": "list", "data": [{"id": "test-model", "object": "model"}]}).encode())
        self._send(reply, gemini=False)

    def do_POST(self) -> None:  # noqa: N802 (http.server naming)
        length = int(self.headers.get("Content-Length", 0))
        data = self.rfile.read(length)
        try:
            body = json.loads(data or b"{}")
        except json.JSONDecodeError:
            body = {"_unparsed": data.decode("utf-8", "replace")}
        rec = Recorded(self.path, {k.lower(): v for k, v in self.headers.items()}, body,
                       time.monotonic())
        canary = _canary_text(self.server, body)
        if canary is not None:
            self._send(Reply(text=canary, finish="length"), gemini=False)
            return
        reply = self.server.next_reply(rec)
        try:
            if reply.delay:
                time.sleep(reply.delay)
            self._send(reply, gemini=":generateContent" in self.path)
        finally:
            self.server.done()

    def _send(self, reply: Reply, *, gemini: bool) -> None:
        if reply.raw is not None:
            payload = reply.raw
        elif reply.status != 200:
            payload = json.dumps(
                {"error": {"code": reply.status, "message": "scripted failure",
                           "status": "UNAVAILABLE"}}).encode()
        else:
            text = valid_text() if reply.text is None else reply.text
            envelope = _gemini(text, reply) if gemini else _openai(text, reply)
            payload = json.dumps(envelope).encode()
        self.send_response(reply.status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(payload)))
        for k, v in reply.headers.items():
            self.send_header(k, v)
        self.end_headers()
        self.wfile.write(payload)


def _canary_text(server: LLMServer, body: Any) -> str | None:
    """The answer to a canary prompt (None: ``body`` asks none), from the server's
    ``weights``."""
    messages = body.get("messages") if isinstance(body, dict) else None
    prompt = messages[-1].get("content") if isinstance(messages, list) and messages else None
    if prompt not in CANARY_PROMPTS:
        return None
    with server.lock:
        server.canary_calls += 1
        salt = server.canary_calls if server.unstable_canaries else 0
    return f"{server.weights}:{CANARY_PROMPTS.index(prompt)}:{salt}"


def _openai(text: str, reply: Reply) -> dict[str, Any]:
    p, c = reply.usage
    return {
        "id": "chatcmpl-test", "object": "chat.completion",
        **({"model": reply.model} if reply.model else {}),
        "choices": [{"index": 0, "finish_reason": reply.finish,
                     "message": {"role": "assistant", "content": text}}],
        "usage": {"prompt_tokens": p, "completion_tokens": c, "total_tokens": p + c},
    }


def _gemini(text: str, reply: Reply) -> dict[str, Any]:
    p, c = reply.usage
    finish = {"stop": "STOP", "length": "MAX_TOKENS"}.get(reply.finish, reply.finish)
    return {
        "candidates": [{"content": {"parts": [{"text": text}], "role": "model"},
                        "finishReason": finish, "index": 0}],
        "usageMetadata": {"promptTokenCount": p, "candidatesTokenCount": c,
                          "totalTokenCount": p + c},
        "modelVersion": reply.model or "test",
    }


@contextmanager
def serve() -> Iterator[LLMServer]:
    """Run an :class:`LLMServer` in a background thread for the ``with`` block."""
    server = LLMServer()
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05},
                              daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)
