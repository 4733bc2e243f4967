"""Fail fast when the server is down: a readiness wait before the batch, a circuit
breaker during it.

Without these, an unreachable or broken server costs every record its full retry
budget (``max_retries`` backoffs each) and the run ends with zero valid answers
after many minutes. Instead:

* :func:`wait_until_ready` asks the session whether the server answers (for an
  OpenAI-compatible server, ``GET {base_url}/models``) before the first record is
  sent. A local server that is starting or loading its model refuses connections
  or replies 503 for a while, so "not yet" is retried until ``ready_timeout`` s;
  a rejected key (401/403) stops at once, as an authentication error naming the URL.
* :class:`Breaker` counts records that failed at the transport level (every retry
  spent) in a row; at ``threshold`` it trips, and the run stops with one error
  instead of trying the remaining records.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from ...errors import TransportError

log = logging.getLogger("popnavshift.responses.llm")

#: longest pause between two readiness checks (s)
MAX_READY_POLL = 2.0
#: a readiness check still unanswered after this long (s) is said without -v
WAIT_NOTICE = 5.0


class NotReady(Exception):
    """The server does not answer yet (``reason`` is one line)."""

    def __init__(self, reason: str, *, fatal: bool = False) -> None:
        super().__init__(reason)
        self.reason = reason
        self.fatal = fatal  # retrying cannot help (a rejected key)


@contextmanager
def announced(where: str) -> Iterator[None]:
    """Say (without -v) what the run waits for once a call has gone unanswered for
    :data:`WAIT_NOTICE` s: a hanging server otherwise says nothing for minutes."""
    notice = threading.Timer(WAIT_NOTICE, log.warning,
                             ("waiting for %s: no answer after %.0f s", where, WAIT_NOTICE))
    notice.daemon = True
    notice.start()
    try:
        yield
    finally:
        notice.cancel()


def wait_until_ready(check: Callable[[], None], where: str, ready_timeout: float) -> None:
    """Call ``check`` until it returns (ready), for at most ``ready_timeout`` s.

    ``check`` raises :class:`NotReady` while the server is not ready. Raises
    TransportError naming ``where`` when the wait runs out or the failure is final.
    """
    started = time.monotonic()
    deadline = started + ready_timeout
    told = False  # the wait was said without -v (once it grew long)
    pause = 0.25
    while True:
        try:
            with announced(where):
                check()
            return
        except NotReady as exc:
            left = deadline - time.monotonic()
            if exc.fatal:  # 401/403: the key, not the server, is the problem
                raise TransportError(f"{where}: authentication failed: {exc.reason}",
                                     hint="check the API key in the environment variable "
                                     "api_key_env names (--api-key-env)") from None
            if left <= 0:
                raise TransportError(
                    f"{where} is not ready after waiting {ready_timeout:g} s: {exc.reason}",
                    hint="check the server and base_url; --ready-timeout sets the wait",
                ) from None
            tell = not told and time.monotonic() - started >= WAIT_NOTICE
            log.log(logging.WARNING if tell else logging.INFO,
                    "waiting for %s (not ready: %s); up to %.0f s more", where, exc.reason, left)
            told = told or tell
            time.sleep(min(pause, left))
            pause = min(MAX_READY_POLL, pause * 2)


@dataclass
class Breaker:
    """Trips after ``threshold`` records in a row failed at the transport level."""

    threshold: int
    in_a_row: int = 0
    tripped: str | None = None  # why, once tripped
    lock: threading.Lock = field(default_factory=threading.Lock)

    def trip(self, why: str) -> None:
        """Trip now (a server that answers nothing at all: no record will do better)."""
        with self.lock:
            self.tripped = self.tripped or why

    def record(self, failure: str | None) -> None:
        """Count one finished record: ``failure`` is its transport error, None if the
        server replied."""
        with self.lock:
            if failure is None:
                self.in_a_row = 0
                return
            self.in_a_row += 1
            if self.in_a_row >= self.threshold and self.tripped is None:
                self.tripped = f"{self.in_a_row} records in a row failed (last: {failure})"
