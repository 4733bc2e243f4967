"""The settings every network respondent takes, declared once, their checks, and the key
from the environment."""

from __future__ import annotations

import inspect
import math
import os
from pathlib import Path

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
    max_retry_after: float = MAX_RETRY_AFTER  # longest Retry-After honoured
    deadline: float | None = None  # one request's calls and waits together; None: no bound


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
