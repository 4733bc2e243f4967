"""The ``openai`` respondent: any OpenAI-compatible ``/chat/completions`` server.

Works with OpenAI, Ollama (``http://localhost:11434/v1``), vLLM and llama.cpp's
server. The answer format is enforced with ``response_format`` of type
``json_schema`` (strict) and validated again locally with
:func:`~popnavshift.responses.schema.parse_answer`. The key is read from the
environment variable ``api_key_env`` and only ever placed in the
``Authorization`` header; ``api_key_env=None`` sends no key (local servers).
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

import httpx

from ...redact import redact
from ..prompt import SYSTEM_PROMPT, build_prompt
from ..schema import response_json_schema
from .cache import Identity, ResponseCache
from .canaries import CANARY_PROMPTS, CANARY_TOKENS, behaviour
from .identity import (
    combine,
    listing_details,
    listing_entry,
    model_identity,
    portable,
    props_details,
)
from .readiness import NotReady
from .retries import Clock, FinalError, Reply, RetryableError, check_status
from .settings import (
    check_extra_body,
    check_key_variable,
    check_setting,
    env_key,
    is_http_url,
    key_variable,
)
from .transport import REASK, LLMRespondent

log = logging.getLogger("popnavshift.responses.llm")
#: longest wait (s) for the model list and ``/props``: cheap routes that a server which
#: is up answers at once; a hanging one is named after this, not after ``timeout``
LIST_TIMEOUT = 15.0


class OpenAIRespondent(LLMRespondent):
    """Chat-completions respondent. Times in s, ``rate_limit`` in calls/s.

    ``temperature``/``seed`` = None leave the field out of the request (for
    servers or models that reject it). Sample ``s`` of a record sends its own ``seed``
    (:meth:`request_seed`). ``extra_body`` adds server-specific fields to every request
    (e.g. ``{"cache_prompt": False}`` for llama.cpp, whose prompt cache otherwise makes
    answers depend on the request before); being in the body, they are in the cache key.
    """

    name = "openai"

    def __init__(
        self,
        *,
        base_url: str = "https://api.openai.com/v1",
        model: str = "gpt-4o-mini",
        api_key_env: str | None = "OPENAI_API_KEY",
        extra_body: Mapping[str, Any] | None = None,
        **settings: Any,
    ) -> None:
        super().__init__(model=model, **settings)
        self.base_url = base_url
        self.api_key_env = key_variable(api_key_env)  # "none" means no key, as on the CLI
        self.extra_body = {} if extra_body is None else extra_body

    @property
    def endpoint(self) -> str:
        return self.base_url.rstrip("/") + "/chat/completions"

    def validate(self) -> None:
        super().validate()
        check_setting(is_http_url(self.base_url), "base_url",
                      "an http(s) URL such as 'http://localhost:11434/v1'", self.base_url)
        check_key_variable(self.api_key_env)
        check_extra_body(self.extra_body)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "extra_body": self.extra_body}

    def _api_key(self) -> str | None:
        return env_key(str(self.api_key_env)) if self.api_key_env else None

    def _body(self, persona: Mapping[str, Any], reasks: Sequence[tuple[str, str]],
              max_tokens: int | None = None, sample: int = 0) -> dict:
        messages = [
            {"role": "system", "content": SYSTEM_PROMPT},
            {"role": "user", "content": build_prompt(persona)},
        ]
        for raw, error in reasks:
            messages.append({"role": "assistant", "content": raw})
            messages.append({"role": "user", "content": REASK.format(error=error)})
        body: dict[str, Any] = {
            "model": self.model,
            "messages": messages,
            "response_format": {
                "type": "json_schema",
                "json_schema": {"name": "probe_answers", "strict": True,
                                "schema": response_json_schema()},
            },
        }
        if self.temperature is not None:
            body["temperature"] = self.temperature
        seed = self.request_seed(sample)
        if seed is not None:
            body["seed"] = seed
        limit = max_tokens or self.max_tokens
        if limit is not None:
            body["max_tokens"] = limit
        return {**body, **self.extra_body}

    def _connect(self, key: str | None, clock: Clock = Clock()) -> _ChatSession:
        return _ChatSession(self.endpoint, key, self.timeout, self.max_concurrency,
                            self.base_url.rstrip("/") + "/models", clock)

    def _ask_identity(self, cache: ResponseCache | None, clock: Clock) -> Identity | None:
        """The listed identity (:meth:`_ChatSession.identity`) and, with ``fingerprint``,
        the answers to the canary prompts (:func:`.canaries.behaviour`), combined."""
        session = self._connect(self._api_key(), clock)
        try:
            listed = session.identity(self.model)
            found = (behaviour(partial(self._canaries, session), cache, self.endpoint,
                               self.model, listed.key if listed else None,
                               f"{self.name} {self.model} at {self.endpoint}")
                     if self.fingerprint else None)
        finally:
            session.close()
        return combine(listed, found)

    def _canaries(self, session: _ChatSession) -> tuple[str, ...] | None:
        """The served model's answers to :data:`CANARY_PROMPTS` (temperature 0, seed 0,
        one at a time: no batching), or None at the first call that fails."""
        answers = []
        for prompt in CANARY_PROMPTS:
            body = {"model": self.model, "messages": [{"role": "user", "content": prompt}],
                    "temperature": 0, "seed": 0, "max_tokens": CANARY_TOKENS,
                    **self.extra_body}
            sent = time.monotonic()
            try:
                answers.append(session.send(body).text or "")
            except (RetryableError, FinalError) as exc:
                if isinstance(exc, RetryableError) and not exc.heard:
                    self._silent_since = sent  # a hang: the run's clock starts here
                log.info("%s: canary prompt not answered (%s): no behavioural fingerprint "
                         "this run", self.name, exc.reason)
                return None
        return tuple(answers)


class _ChatSession:
    """One pooled httpx client shared by the worker threads (httpx.Client is thread-safe)."""

    def __init__(self, url: str, key: str | None, timeout: float, connections: int,
                 models_url: str, clock: Clock) -> None:
        self.url = url
        self.models_url = models_url
        self.timeout = timeout
        self.clock = clock
        headers = {"Authorization": f"Bearer {key}"} if key else {}
        self._client = httpx.Client(
            headers=headers, timeout=httpx.Timeout(timeout),
            limits=httpx.Limits(max_connections=connections),
        )

    def send(self, body: dict[str, Any], timeout: float | None = None) -> Reply:
        wait = self.clock.bound(self.timeout if timeout is None else timeout)
        try:
            resp = self._client.post(self.url, json=body, timeout=httpx.Timeout(wait))
        except httpx.TimeoutException:
            raise RetryableError(f"timeout after {wait:g} s") from None
        except httpx.TransportError as exc:
            raise RetryableError(f"connection error ({type(exc).__name__})") from None
        check_status(resp.status_code, resp.headers.get("retry-after"), _error_message(resp))
        try:
            data = resp.json()
            choice = data["choices"][0]
            message = choice["message"]
            usage = data.get("usage") or {}
        except (ValueError, KeyError, IndexError, TypeError):
            raise RetryableError("malformed response body", heard=True) from None
        finish = choice.get("finish_reason")
        note = None if finish in (None, "stop") else f"finish_reason={finish}"
        served = portable(data["model"]) if isinstance(data.get("model"), str) else None
        fingerprint = data.get("system_fingerprint")
        if message.get("refusal"):
            note = f"refusal: {message['refusal']}"
        tokens = {
            "prompt": usage.get("prompt_tokens") or 0,
            "completion": usage.get("completion_tokens") or 0,
            "total": usage.get("total_tokens") or 0,
        }
        return Reply(message.get("content"), tokens, note, truncated=finish == "length",
                     model=served,
                     fingerprint=fingerprint if isinstance(fingerprint, str) else None)

    def _get(self, url: str) -> httpx.Response | None:
        """``GET url``: the reply, or None from a server without that route (404, 405,
        501); raises NotReady when the server does not answer or refuses (fatal: 401/403,
        worded as the authentication problem it is)."""
        wait = self.clock.bound(min(self.timeout, LIST_TIMEOUT))
        try:
            resp = self._client.get(url, timeout=httpx.Timeout(wait))
        except httpx.TimeoutException:
            raise NotReady(f"no reply within {wait:g} s") from None
        except httpx.TransportError as exc:
            raise NotReady(f"connection error ({type(exc).__name__})") from None
        if resp.status_code in (404, 405, 501):
            return None
        if resp.status_code in (401, 403):
            raise NotReady(f"GET {url} was refused (HTTP {resp.status_code}: "
                           f"{_error_message(resp)}): the server rejected the API key, or "
                           "needs one", fatal=True)
        if resp.status_code >= 400:
            raise NotReady(f"GET {url}: HTTP {resp.status_code}: {_error_message(resp)}")
        return resp

    def _models(self) -> httpx.Response | None:
        return self._get(self.models_url)

    def check_ready(self) -> None:
        """``GET {base_url}/models``: 2xx is ready; a server without that route is taken
        as ready and the first request tells; 401/403 is final."""
        self._models()

    def identity(self, model: str) -> Identity | None:
        """:func:`.identity.model_identity` of ``GET {base_url}/models`` (None without that
        route or a listing) with what the server says of the model: a llama.cpp entry's
        size, parameters and quantisation, and its ``GET /props`` (asked of llama.cpp only:
        an entry with ``meta``); raises NotReady when the server does not answer (fatal:
        401/403)."""
        resp = self._models()
        try:
            listing = resp.json() if resp is not None else None
        except ValueError:
            return None
        entry = listing_entry(listing, model)
        if entry is None:
            return None
        details = listing_details(entry)
        if isinstance(entry.get("meta"), dict):  # llama.cpp: its /props at the server root
            props = self._get(self.models_url.removesuffix("/models").removesuffix("/v1")
                              + "/props")
            with contextlib.suppress(ValueError):  # an unreadable /props tells nothing
                details.update(props_details(props.json() if props is not None else None))
        return Identity(model_identity(entry, details), details)

    def close(self) -> None:
        self._client.close()


def _error_message(resp: httpx.Response) -> str:
    """The server's error message, shortened to one line."""
    try:
        err = resp.json().get("error")
        msg = err.get("message") if isinstance(err, dict) else err
    except (ValueError, AttributeError):
        msg = None
    text = str(msg) if msg else resp.text
    return redact(" ".join(text.split())[:200] or resp.reason_phrase)
