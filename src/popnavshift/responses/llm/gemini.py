"""The ``gemini`` respondent: Google's native ``google-genai`` client (optional extra).

``google-genai`` is imported only when a request actually has to be sent, so
the package (and replaying a filled cache) works without the ``gemini`` extra.

Choices (checked against google-genai 3.4):

* The schema goes in ``response_json_schema`` (plain JSON Schema, which keeps
  ``additionalProperties: false``) rather than ``response_schema`` (an OpenAPI
  subset that the SDK converts), with ``response_mime_type="application/json"``.
  The reply text is validated locally with ``parse_answer`` all the same.
* The SDK's own retries are switched off (``HttpRetryOptions(attempts=1)``):
  retries happen in :mod:`.transport` so that they are counted in
  ``Answer.calls`` and behave exactly as for the ``openai`` respondent.
  ``Retry-After`` is honoured, and so is the API's ``RetryInfo.retryDelay``.
* The cache key is built from the REST body the SDK sends (``contents``,
  ``systemInstruction``, ``generationConfig``), never from the key.
* Token usage: prompt = ``prompt_token_count``; completion = candidates +
  thinking tokens (both are billed as output); total = ``total_token_count``.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any, NoReturn

from ...errors import ConfigError
from ...redact import redact
from ..prompt import SYSTEM_PROMPT, build_prompt
from ..schema import response_json_schema
from .retries import Clock, FinalError, Reply, RetryableError, check_status
from .settings import check_key_variable, check_setting, env_key, is_http_url, key_variable
from .transport import REASK, LLMRespondent

DEFAULT_BASE_URL = "https://generativelanguage.googleapis.com"
API_VERSION = "v1beta"


class GeminiRespondent(LLMRespondent):
    """Gemini API respondent. Times in s, ``rate_limit`` in calls/s.

    The key comes from ``api_key_env`` (default ``GEMINI_API_KEY``, falling back
    to ``GOOGLE_API_KEY``). ``base_url`` overrides the API root (a proxy, a test
    server). Sample ``s`` of a record sends its own ``generationConfig.seed``
    (:meth:`request_seed`).
    """

    name = "gemini"

    def __init__(
        self,
        *,
        model: str = "gemini-2.5-flash",
        api_key_env: str = "GEMINI_API_KEY",
        base_url: str | None = None,
        **settings: Any,
    ) -> None:
        super().__init__(model=model, **settings)
        self.api_key_env = key_variable(api_key_env)  # "none": no key, as on the CLI
        self.base_url = base_url

    @property
    def endpoint(self) -> str:
        root = (self.base_url or DEFAULT_BASE_URL).rstrip("/")
        return f"{root}/{API_VERSION}/models/{self.model}:generateContent"

    def validate(self) -> None:
        super().validate()
        check_setting(self.api_key_env is not None, "api_key_env", "an environment "
                      "variable name (Gemini needs a key)", self.api_key_env)
        check_key_variable(self.api_key_env)
        check_setting(self.base_url is None or is_http_url(self.base_url), "base_url",
                      "None or an http(s) URL", self.base_url)

    def _api_key(self) -> str:
        if self.api_key_env == "GEMINI_API_KEY":
            return env_key("GEMINI_API_KEY", "GOOGLE_API_KEY")
        return env_key(str(self.api_key_env))

    def _body(self, persona: Mapping[str, Any], reasks: Sequence[tuple[str, str]],
              max_tokens: int | None = None, sample: int = 0) -> dict:
        contents = [{"parts": [{"text": build_prompt(persona)}], "role": "user"}]
        for raw, error in reasks:
            contents.append({"parts": [{"text": raw}], "role": "model"})
            contents.append({"parts": [{"text": REASK.format(error=error)}], "role": "user"})
        config: dict[str, Any] = {}
        if self.temperature is not None:
            config["temperature"] = self.temperature
        seed = self.request_seed(sample)
        if seed is not None:
            config["seed"] = seed
        limit = max_tokens or self.max_tokens
        if limit is not None:
            config["maxOutputTokens"] = limit
        config["responseMimeType"] = "application/json"
        config["responseJsonSchema"] = response_json_schema()
        return {
            "contents": contents,
            "systemInstruction": {"parts": [{"text": SYSTEM_PROMPT}], "role": "user"},
            "generationConfig": config,
        }

    def _connect(self, key: str | None, clock: Clock = Clock()) -> _GeminiSession:
        try:
            from google import genai
            from google.genai import errors, types
        except ImportError:
            raise ConfigError(
                "the gemini respondent needs the google-genai package",
                hint="pip install 'popnavshift[gemini]'",
            ) from None
        options = types.HttpOptions(
            base_url=self.base_url, api_version=API_VERSION,
            timeout=max(1, round(self.timeout * 1000)),  # the SDK takes ms
            retry_options=types.HttpRetryOptions(attempts=1),  # retries are ours
        )

        def make_client() -> Any:
            return genai.Client(api_key=key, vertexai=False, http_options=options)

        return _GeminiSession(make_client, self.model, self.timeout, errors, types, clock)


class _GeminiSession:
    """One SDK client per worker thread (the SDK does not promise thread safety)."""

    def __init__(self, make_client: Any, model: str, timeout: float, errors: Any,
                 types: Any, clock: Clock) -> None:
        self._make_client = make_client
        self.model = model
        self.timeout = timeout
        self.clock = clock
        self._errors = errors
        self._types = types
        self._transient = _transient_errors()
        self._local = threading.local()
        self._clients: list[Any] = []
        self._lock = threading.Lock()

    def _client(self) -> Any:
        client = getattr(self._local, "client", None)
        if client is None:
            client = self._local.client = self._make_client()
            with self._lock:
                self._clients.append(client)
        return client

    def send(self, body: dict[str, Any], timeout: float | None = None) -> Reply:
        types = self._types
        gen = body["generationConfig"]
        wait = self.clock.bound(self.timeout if timeout is None else timeout)
        config = types.GenerateContentConfig(
            http_options=types.HttpOptions(timeout=max(1, round(wait * 1000))),  # ms
            system_instruction=body["systemInstruction"]["parts"][0]["text"],
            temperature=gen.get("temperature"),
            seed=gen.get("seed"),
            max_output_tokens=gen.get("maxOutputTokens"),
            response_mime_type=gen["responseMimeType"],
            response_json_schema=gen["responseJsonSchema"],
            automatic_function_calling=types.AutomaticFunctionCallingConfig(disable=True),
        )
        try:
            resp = self._client().models.generate_content(
                model=self.model, contents=body["contents"], config=config
            )
        except self._errors.APIError as exc:
            _raise_api_error(exc)
        except self._transient as exc:
            if "Timeout" in type(exc).__name__:
                raise RetryableError(f"timeout after {wait:g} s") from None
            raise RetryableError(f"connection error ({type(exc).__name__})") from None
        except ValueError:  # the SDK could not decode the reply body
            raise RetryableError("malformed response body", heard=True) from None
        return _reply(resp)

    def check_ready(self) -> None:
        """No separate probe: the SDK has no cheap call, so the breaker guards the run."""

    def close(self) -> None:
        with self._lock:
            for client in self._clients:
                client.close()
            self._clients.clear()


def _raise_api_error(exc: Any) -> NoReturn:
    headers = getattr(getattr(exc, "response", None), "headers", None) or {}
    retry_after = headers.get("retry-after")
    if retry_after is None:
        retry_after = _retry_info_delay(exc.details)
    message = redact(" ".join(str(exc.message or exc.status or "").split())[:200])
    check_status(int(exc.code or 500), retry_after, message)
    raise FinalError(f"HTTP {exc.code}: {message}")  # a non-error status cannot get here


def _retry_info_delay(details: Any) -> str | None:
    """``retryDelay`` ("12s") of a google.rpc.RetryInfo in an API error body, as seconds."""
    err = details.get("error", details) if isinstance(details, dict) else {}
    for item in err.get("details") or []:
        delay = item.get("retryDelay") if isinstance(item, dict) else None
        if isinstance(delay, str) and delay.endswith("s"):
            return delay[:-1]
    return None


def _reply(resp: Any) -> Reply:
    note = None
    if resp.candidates:
        finish = resp.candidates[0].finish_reason
        finish_name = getattr(finish, "name", finish)
        if finish_name not in (None, "STOP"):
            note = f"finish_reason={finish_name}"
    elif resp.prompt_feedback is not None and resp.prompt_feedback.block_reason is not None:
        note = f"prompt blocked: {resp.prompt_feedback.block_reason}"
    usage = resp.usage_metadata
    tokens: dict[str, int] = {}
    if usage is not None:
        prompt = usage.prompt_token_count or 0
        completion = (usage.candidates_token_count or 0) + (usage.thoughts_token_count or 0)
        tokens = {"prompt": prompt, "completion": completion,
                  "total": usage.total_token_count or prompt + completion}
    text = resp.text if resp.candidates else None
    served = getattr(resp, "model_version", None)
    return Reply(text, tokens, note, truncated=note == "finish_reason=MAX_TOKENS",
                 model=served if isinstance(served, str) else None)


def _transient_errors() -> tuple[type[BaseException], ...]:
    """Network errors of whichever httpx flavour the SDK uses (httpx or its fork httpx2)."""
    import httpx

    found: list[type[BaseException]] = [httpx.TransportError]
    try:
        import httpx2  # type: ignore[import-not-found]

        found.append(httpx2.TransportError)
    except ImportError:
        pass
    return tuple(found)
