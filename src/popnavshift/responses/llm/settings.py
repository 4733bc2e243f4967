"""The settings every network respondent takes, declared once, their checks, and the key
from the environment."""

from __future__ import annotations

import inspect
import json
import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ...errors import ConfigError, MissingKeyError
from ...redact import register_secret
from .retries import MAX_RETRY_AFTER


class LLMSettings:
    """The settings every LLM respondent takes, with their defaults: keyword options in a
    study file's ``respondent: {options: ...}`` and in ``popnavshift probe``. Declared once
    here; :class:`~.transport.LLMRespondent` inherits them as typed attributes, takes them
    as keywords and lists them in every subclass's signature (:func:`with_settings`), so a
    subclass's ``__init__`` names only its own options and passes ``**settings`` on.
    Times are in s, ``rate_limit`` in calls/s."""

    temperature: float | None = 0.0  # None: left out of the request
    seed: int | None = 0  # None: left out of the request (then one sample only)
    cache_path: str | Path | None = None
    max_concurrency: int = 4
    rate_limit: float | None = None
    timeout: float = 60.0
    max_retries: int = 5
    max_reasks: int = 2
    backoff_base: float = 0.5
    backoff_cap: float = 30.0
    max_tokens: int | None = None  # None: the server's default limit
    ready_timeout: float = 30.0
    max_consecutive_failures: int = 5
    max_retry_after: float = MAX_RETRY_AFTER  # longest Retry-After honoured; beyond: stop
    #: the whole stage's network work (identity, readiness, every call and wait, calls in
    #: flight); None: no bound
    deadline: float | None = None
    #: ask the fixed canary prompts before the cache is read (a behavioural fingerprint
    #: of the served model in every cache key: :mod:`.canaries`)
    fingerprint: bool = True
    #: sha256 of the model file when the user knows it: part of the identity and records
    model_sha256: str | None = None


#: the names of :class:`LLMSettings`, in their declared order
SETTING_NAMES: tuple[str, ...] = tuple(LLMSettings.__annotations__)


def with_settings(init) -> inspect.Signature:
    """The signature of a respondent class whose ``__init__`` is ``init`` (its own keyword
    options, then ``**settings``): its own options followed by every :class:`LLMSettings`
    field with its default, so the registry names a mistyped option and lists them all."""
    own = [p for p in list(inspect.signature(init).parameters.values())[1:]
           if p.kind is not p.VAR_KEYWORD]
    taken = {p.name for p in own}
    extra = [inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY,
                               default=getattr(LLMSettings, n),
                               annotation=LLMSettings.__annotations__[n])
             for n in SETTING_NAMES if n not in taken]
    return inspect.Signature(own + extra)


def env_key(*names: str) -> str:
    """The first non-empty environment variable of ``names``; MissingKeyError otherwise."""
    for name in names:
        value = os.environ.get(name, "").strip()
        if value:
            register_secret(value)  # masked in every message and log from now on
            return value
    listed = " or ".join(names)
    raise MissingKeyError(
        f"API key environment variable {listed} is not set",
        hint=f"export {names[0]}=... (keys are read from the environment only)",
    )


def check_settings(s: LLMSettings) -> None:
    """ConfigError naming the first bad setting of ``s`` (and ``model``), with what it
    must be and what it is."""
    model = getattr(s, "model", None)
    checks = [
        ("model", isinstance(model, str) and model.strip() != "", "a non-empty model name"),
        ("max_concurrency", is_int(s.max_concurrency, 1), "an int ≥ 1"),
        ("rate_limit", s.rate_limit is None or is_pos(s.rate_limit), "None or calls/s > 0"),
        ("timeout", is_pos(s.timeout), "seconds > 0"),
        ("max_retries", is_int(s.max_retries, 0), "an int ≥ 0"),
        ("max_reasks", is_int(s.max_reasks, 0), "an int ≥ 0"),
        ("backoff_base", is_pos(s.backoff_base) or s.backoff_base == 0, "seconds ≥ 0"),
        ("backoff_cap", is_pos(s.backoff_cap) or s.backoff_cap == 0, "seconds ≥ 0"),
        ("max_tokens", s.max_tokens is None or is_int(s.max_tokens, 1), "None or an int ≥ 1"),
        ("ready_timeout", is_pos(s.ready_timeout) or s.ready_timeout == 0, "seconds ≥ 0"),
        ("max_consecutive_failures", is_int(s.max_consecutive_failures, 1), "an int ≥ 1"),
        ("max_retry_after", is_pos(s.max_retry_after) or s.max_retry_after == 0,
         "seconds ≥ 0"),
        ("deadline", s.deadline is None or is_pos(s.deadline), "None or seconds > 0"),
        ("fingerprint", isinstance(s.fingerprint, bool), "true or false"),
        ("model_sha256", s.model_sha256 is None or is_sha256(s.model_sha256),
         "None or the 64 hex digits of the model file's sha256"),
    ]
    for name, ok, expected in checks:
        check_setting(ok, name, expected, getattr(s, name, model))


def check_setting(ok: bool, name: str, expected: str, got: object) -> None:
    if not ok:
        raise ConfigError(f"{name} must be {expected}; got {got!r}")


def is_http_url(value: object) -> bool:
    return isinstance(value, str) and value.startswith(("http://", "https://"))


def is_int(value: object, low: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def is_pos(value: object) -> bool:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0)


#: an environment variable's name (POSIX shells)
_VARIABLE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: values of ``api_key_env`` that mean "send no key" (a local server), in YAML as on the
#: command line: YAML's ``null`` and ``none``/``"none"``/``""`` alike
NO_KEY = ("", "none", "null")


def key_variable(value: object) -> object:
    """``api_key_env`` as the respondent reads it: None for no key (:data:`NO_KEY`, any
    case), else the value as given (checked by :func:`check_key_variable`)."""
    if isinstance(value, str) and value.strip().lower() in NO_KEY:
        return None
    return value


def check_key_variable(value: object) -> None:
    """ConfigError unless ``value`` is None or an environment variable's name. The value
    is not echoed when it does not look like one: it may be the key itself."""
    if value is None or (isinstance(value, str) and _VARIABLE.match(value)):
        return
    raise ConfigError("api_key_env must name an environment variable (letters, digits, _) "
                      "or be none; the value given is not one (not shown: it may be a key)",
                      hint="export the key, e.g. export OPENAI_API_KEY=..., and pass its name")


#: most bytes of ``extra_body`` (canonical JSON): it is sent with every request and
#: recorded in responses.json and the manifest
MAX_EXTRA_BODY = 4096
#: request fields ``extra_body`` may not set, with the reason
REFUSED_EXTRA: dict[str, str] = {
    **dict.fromkeys(("model", "messages", "response_format", "temperature", "seed",
                     "max_tokens"), "set by the respondent's own option"),
    "max_completion_tokens": "set by max_tokens (--max-tokens)",
    "stream": "the respondent reads one JSON reply, not a stream of chunks",
    "stream_options": "the respondent reads one JSON reply, not a stream of chunks",
    "n": "asks for several completions, all billed, of which one is read; ask samples "
         "(--samples) instead",
    "best_of": "generates several completions, all billed, of which one is returned",
    "logprobs": "changes what the reply carries (and its size), not the answer",
    "top_logprobs": "changes what the reply carries (and its size), not the answer",
    "echo": "returns the prompt inside the reply",
    "tools": "the reply must be the answer JSON, not a tool call",
    "tool_choice": "the reply must be the answer JSON, not a tool call",
    "functions": "the reply must be the answer JSON, not a function call",
    "function_call": "the reply must be the answer JSON, not a function call",
    "service_tier": "changes the price and latency class of every request",
    "audio": "asks for (billed) audio output",
    "modalities": "asks for (billed) output other than text",
    "prediction": "a predicted output is billed and changes nothing of the answer",
}


def check_extra_body(value: object) -> None:
    """ConfigError unless ``value`` is a mapping of string keys to JSON values, none of
    them :data:`REFUSED_EXTRA`, of at most :data:`MAX_EXTRA_BODY` bytes."""
    if not isinstance(value, Mapping):
        raise ConfigError(f"extra_body must be a mapping of request fields, e.g. "
                          f"{{cache_prompt: false}}; got a {type(value).__name__}")
    for key in value:
        if not isinstance(key, str):
            raise ConfigError(f"extra_body: field names must be strings; got {key!r}")
        if key in REFUSED_EXTRA:
            raise ConfigError(f"extra_body.{key} is refused: {REFUSED_EXTRA[key]}")
    try:
        size = len(json.dumps(value, sort_keys=True, allow_nan=False).encode())
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"extra_body must hold JSON values only (strings, numbers, "
                          f"booleans, null, lists, mappings): {exc}") from None
    if size > MAX_EXTRA_BODY:
        raise ConfigError(f"extra_body is {size:,} bytes of JSON, more than {MAX_EXTRA_BODY:,} "
                          "(it is sent with every request and recorded in the manifest)")


def is_sha256(value: object) -> bool:
    return isinstance(value, str) and re.fullmatch(r"[0-9a-fA-F]{64}", value) is not None


def sent_extra(value: Mapping[str, Any] | None) -> dict[str, Any]:
    """A copy of a checked ``extra_body`` (None: empty)."""
    return dict(value) if value else {}
