"""Settings checks shared by the network respondents, and the key from the environment."""

from __future__ import annotations

import math
import os

from ...errors import ConfigError, MissingKeyError
from ...redact import register_secret


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
