"""Keep credentials out of every message, log line and stored error.

Keys are read from the environment only (:func:`popnavshift.responses.llm.transport.env_key`
registers each one here). A server may still echo a key back, in an error body
for instance, so every text that leaves the process through the CLI, the logs or
the failure tables passes through :func:`redact`: it masks the registered keys and
anything shaped like a bearer token or an OpenAI-style ``sk-`` key.
"""

from __future__ import annotations

import logging
import re
import threading

MASK = "***"
_SECRETS: set[str] = set()
_LOCK = threading.Lock()
#: ``Bearer <token>`` (any token) and ``sk-…`` keys (OpenAI, Anthropic, most proxies)
_TOKEN_SHAPES = re.compile(r"(?i)\bbearer\s+[^\s\"',;]+|\bsk-[A-Za-z0-9_\-]{16,}")
#: shorter secrets are masked only where they stand alone (not inside a longer word,
#: which a 3-letter key would garble), longer ones wherever they appear
_MIN_SECRET = 6


def register_secret(value: str | None) -> None:
    """Mask ``value`` in every later :func:`redact` call (for the life of the process)."""
    if value:
        with _LOCK:
            _SECRETS.add(value)


def redact(text: str) -> str:
    """``text`` with the registered secrets and token-shaped strings replaced by ``***``."""
    with _LOCK:
        secrets = sorted(_SECRETS, key=len, reverse=True)  # longest first: no partial leftovers
    for secret in secrets:
        if len(secret) >= _MIN_SECRET:
            text = text.replace(secret, MASK)
        else:
            text = re.sub(rf"(?<![A-Za-z0-9]){re.escape(secret)}(?![A-Za-z0-9])", MASK, text)

    def mask(match: re.Match[str]) -> str:
        word = match.group(0)
        return f"{word.split()[0]} {MASK}" if word.lower().startswith("bearer") else MASK

    return _TOKEN_SHAPES.sub(mask, text)


class RedactingFilter(logging.Filter):
    """A logging filter that renders each record's message and redacts it."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg = redact(record.getMessage())
        record.args = None
        return True
