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
from collections.abc import Mapping, Sequence
from typing import Any

import httpx

from ...redact import redact
from ..prompt import SYSTEM_PROMPT, build_prompt
from ..schema import response_json_schema
from .cache import Identity
from .identity import entry_identity, listing_details, listing_entry, props_details
from .readiness import NotReady
from .retries import Reply, RetryableError, check_status
from .settings import check_setting, env_key, is_http_url
from .transport import REASK, LLMRespondent


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
        self.api_key_env = api_key_env
        self.extra_body = dict(extra_body or {})

    @property
    def endpoint(self) -> str:
        return self.base_url.rstrip("/") + "/chat/completions"

    def validate(self) -> None:
        super().validate()
        check_setting(is_http_url(self.base_url), "base_url",
                      "an http(s) URL such as 'http://localhost:11434/v1'", self.base_url)
        taken = sorted(set(self.extra_body) & OWN_FIELDS)
        check_setting(not taken and all(isinstance(k, str) for k in self.extra_body),
                      "extra_body", "a mapping of server-specific fields; "
                      f"{', '.join(sorted(OWN_FIELDS))} are set by their own options",
                      self.extra_body)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "extra_body": self.extra_body}

    def _api_key(self) -> str | None:
        return env_key(self.api_key_env) if self.api_key_env else None

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

    def _connect(self, key: str | None) -> _ChatSession:
        return _ChatSession(self.endpoint, key, self.timeout, self.max_concurrency,
                            self.base_url.rstrip("/") + "/models")

    def _ask_identity(self) -> Identity | None:
        session = self._connect(self._api_key())
        try:
            return session.identity(self.model)
        finally:
            session.close()


#: request fields the respondent sets from its own options (not through ``extra_body``)
OWN_FIELDS = frozenset({"model", "messages", "response_format", "temperature", "seed",
                        "max_tokens"})


class _ChatSession:
    """One pooled httpx client shared by the worker threads (httpx.Client is thread-safe)."""

    def __init__(self, url: str, key: str | None, timeout: float, connections: int,
                 models_url: str) -> None:
        self.url = url
        self.models_url = models_url
        self.timeout = timeout
        headers = {"Authorization": f"Bearer {key}"} if key else {}
        self._client = httpx.Client(
            headers=headers, timeout=httpx.Timeout(timeout),
            limits=httpx.Limits(max_connections=connections),
        )

    def send(self, body: dict[str, Any]) -> Reply:
        try:
            resp = self._client.post(self.url, json=body)
        except httpx.TimeoutException:
            raise RetryableError(f"timeout after {self.timeout:g} s") from None
        except httpx.TransportError as exc:
            raise RetryableError(f"connection error ({type(exc).__name__})") from None
        check_status(resp.status_code, resp.headers.get("retry-after"), _error_message(resp))
        try:
            data = resp.json()
            choice = data["choices"][0]
            message = choice["message"]
            usage = data.get("usage") or {}
        except (ValueError, KeyError, IndexError, TypeError):
            raise RetryableError("malformed response body") from None
        finish = choice.get("finish_reason")
        note = None if finish in (None, "stop") else f"finish_reason={finish}"
        served = data.get("model") if isinstance(data.get("model"), str) else None
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
        try:
            resp = self._client.get(url)
        except httpx.TimeoutException:
            raise NotReady(f"no reply within {self.timeout:g} s") from None
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
        """:func:`listing_identity` of ``GET {base_url}/models`` (None without that route
        or a listing) with what the server says of the model: a llama.cpp entry's size
        and parameters, and its ``GET /props`` (asked of llama.cpp only: an entry with
        ``meta``); raises NotReady when the server does not answer (fatal: 401/403)."""
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
        return Identity(entry_identity(entry), details)

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
