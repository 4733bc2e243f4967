"""The ``openai`` respondent: any OpenAI-compatible ``/chat/completions`` server.

Works with OpenAI, Ollama (``http://localhost:11434/v1``), vLLM and llama.cpp's
server. The answer format is enforced with ``response_format`` of type
``json_schema`` (strict) and validated again locally with
:func:`~popnavshift.responses.schema.parse_answer`. The key is read from the
environment variable ``api_key_env`` and only ever placed in the
``Authorization`` header; ``api_key_env=None`` sends no key (local servers).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import httpx

from ...redact import redact
from ..prompt import SYSTEM_PROMPT, build_prompt
from ..schema import response_json_schema
from .identity import listing_identity
from .readiness import NotReady
from .retries import MAX_RETRY_AFTER, Reply, RetryableError, check_status
from .transport import REASK, LLMRespondent, check_setting, env_key, is_http_url


class OpenAIRespondent(LLMRespondent):
    """Chat-completions respondent. Times in s, ``rate_limit`` in calls/s.

    ``temperature``/``seed`` = None leave the field out of the request (for
    servers or models that reject it). ``replicate`` only separates cache
    entries of otherwise identical requests.
    """

    name = "openai"

    def __init__(
        self,
        *,
        base_url: str = "https://api.openai.com/v1",
        model: str = "gpt-4o-mini",
        api_key_env: str | None = "OPENAI_API_KEY",
        temperature: float | None = 0.0,
        seed: int | None = 0,
        replicate: int = 0,
        cache_path: str | Path | None = None,
        max_concurrency: int = 4,
        rate_limit: float | None = None,
        timeout: float = 60.0,
        max_retries: int = 5,
        max_reasks: int = 2,
        backoff_base: float = 0.5,
        backoff_cap: float = 30.0,
        max_tokens: int | None = None,
        ready_timeout: float = 30.0,
        max_consecutive_failures: int = 5,
        max_retry_after: float = MAX_RETRY_AFTER,
        deadline: float | None = None,
    ) -> None:
        super().__init__(
            model=model, temperature=temperature, seed=seed, replicate=replicate,
            cache_path=cache_path, max_concurrency=max_concurrency, rate_limit=rate_limit,
            timeout=timeout, max_retries=max_retries, max_reasks=max_reasks,
            backoff_base=backoff_base, backoff_cap=backoff_cap, max_tokens=max_tokens,
            ready_timeout=ready_timeout, max_consecutive_failures=max_consecutive_failures,
            max_retry_after=max_retry_after, deadline=deadline,
        )
        self.base_url = base_url
        self.api_key_env = api_key_env

    @property
    def endpoint(self) -> str:
        return self.base_url.rstrip("/") + "/chat/completions"

    def validate(self) -> None:
        super().validate()
        check_setting(is_http_url(self.base_url), "base_url",
                      "an http(s) URL such as 'http://localhost:11434/v1'", self.base_url)

    def _api_key(self) -> str | None:
        return env_key(self.api_key_env) if self.api_key_env else None

    def _body(self, persona: Mapping[str, Any], reasks: Sequence[tuple[str, str]],
              max_tokens: int | None = None) -> dict:
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
        if self.seed is not None:
            body["seed"] = self.seed
        limit = max_tokens or self.max_tokens
        if limit is not None:
            body["max_tokens"] = limit
        return body

    def _connect(self, key: str | None) -> _ChatSession:
        return _ChatSession(self.endpoint, key, self.timeout, self.max_concurrency,
                            self.base_url.rstrip("/") + "/models")

    def _ask_identity(self) -> str | None:
        session = self._connect(self._api_key())
        try:
            return session.identity(self.model)
        finally:
            session.close()


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
        if message.get("refusal"):
            note = f"refusal: {message['refusal']}"
        tokens = {
            "prompt": usage.get("prompt_tokens") or 0,
            "completion": usage.get("completion_tokens") or 0,
            "total": usage.get("total_tokens") or 0,
        }
        return Reply(message.get("content"), tokens, note, truncated=finish == "length",
                     model=served)

    def _models(self) -> httpx.Response | None:
        """``GET {base_url}/models``: the reply, or None from a server without that route
        (404, 405, 501); raises NotReady when the server does not answer or refuses
        (fatal: 401/403)."""
        try:
            resp = self._client.get(self.models_url)
        except httpx.TimeoutException:
            raise NotReady(f"no reply within {self.timeout:g} s") from None
        except httpx.TransportError as exc:
            raise NotReady(f"connection error ({type(exc).__name__})") from None
        if resp.status_code in (404, 405, 501):
            return None
        if resp.status_code >= 400:
            raise NotReady(f"GET /models: HTTP {resp.status_code}: {_error_message(resp)}",
                           fatal=resp.status_code in (401, 403))
        return resp

    def check_ready(self) -> None:
        """``GET {base_url}/models``: 2xx is ready; a server without that route is taken
        as ready and the first request tells; 401/403 is final."""
        self._models()

    def identity(self, model: str) -> str | None:
        """:func:`listing_identity` of ``GET {base_url}/models`` (None without that route
        or a listing); raises NotReady when the server does not answer (fatal: 401/403)."""
        resp = self._models()
        if resp is None:
            return None
        try:
            return listing_identity(resp.json(), model)
        except ValueError:
            return None

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
