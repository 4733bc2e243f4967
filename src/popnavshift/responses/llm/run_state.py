"""The state the worker threads of one ``answer_all`` share: the session, the cache, the
rate limiter and the breaker, the counts the progress lines show, the stage's deadline,
and when the server was last heard from (a server that answers nothing for
:data:`HANG_TRIES` request timeouts hangs, and the run stops saying so)."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

from ...errors import TransportError
from ...redact import redact
from .cache import ResponseCache
from .readiness import Breaker
from .retries import (
    Clock,
    FinalError,
    RateLimiter,
    Reply,
    RetryableError,
    Session,
    TransportFailure,
)

#: request timeouts without any reply from the server (a status, a body) after which the
#: run stops: a hanging server is named within this many timeouts, not after every
#: record spent its retries
HANG_TRIES = 2


@dataclass
class Run:
    """State shared by the workers of one ``answer_all`` call; ``timeout`` is one
    request's (s), ``heard_at`` the monotonic time the server last replied (or the run
    started)."""

    session: Session
    cache: ResponseCache | None
    limiter: RateLimiter
    breaker: Breaker
    clock: Clock = field(default_factory=Clock)
    timeout: float = 60.0
    heard_at: float = field(default_factory=time.monotonic)
    fatal: TransportFailure | None = None
    deadline: str | None = None  # why the stage's deadline stopped the run
    lock: threading.Lock = field(default_factory=threading.Lock)
    counts: dict[str, int] = field(
        default_factory=lambda: {"calls": 0, "retries": 0, "failed": 0, "in_flight": 0})

    def count(self, what: str, n: int = 1) -> None:
        with self.lock:
            self.counts[what] += n

    def stopped(self) -> bool:
        return (self.fatal is not None or self.breaker.tripped is not None
                or self.deadline is not None)

    def heard(self) -> None:
        """The server replied (anything: a valid answer, an error status)."""
        with self.lock:
            self.heard_at = time.monotonic()

    def check_hang(self, reason: str, where: str) -> None:
        """Trip the breaker when nothing was heard for :data:`HANG_TRIES` timeouts."""
        silent = time.monotonic() - self.heard_at
        if silent >= HANG_TRIES * self.timeout:
            self.breaker.trip(f"{where} has answered nothing for {silent:.0f} s ({reason}; "
                              f"timeout {self.timeout:g} s): the server hangs or is "
                              "unreachable")

    @staticmethod
    def redact(text: str) -> str:
        # Defence in depth: servers sometimes echo credentials in error bodies.
        return redact(text)

    def send(self, body: dict[str, Any], where: str, record: Any,
             timeout: float | None) -> Reply:
        """One call, counted in flight and timed into ``record.seconds``; a reply of any
        kind is the server heard from, and a call unanswered when nothing was heard for
        long trips the breaker (a hang)."""
        self.count("in_flight")
        started = time.monotonic()
        try:
            reply = self.session.send(body, timeout)
        except RetryableError as exc:
            if exc.heard:
                self.heard()
            else:
                self.check_hang(exc.reason, where)
            raise
        except FinalError:
            self.heard()
            raise
        finally:
            self.count("in_flight", -1)
            record.seconds += time.monotonic() - started
        self.heard()
        return reply


def stop_error(run: Run, name: str, endpoint: str, answers: dict[int, Any],
               total: int) -> TransportError | None:
    """Why the run stopped, as one error (None: it did not): the stage's deadline, a
    failure every record would meet (a rejected key or model, a server asking to wait too
    long), or the breaker (failures in a row, a hanging server)."""
    if run.deadline is not None:
        done = sum(a.answer is not None for a in answers.values())
        return TransportError(
            f"{name}: the deadline of {run.clock.seconds:g} s was reached ({run.deadline}): "
            f"{done} of {total} records answered, the rest not",
            hint="the answers are cached: run the same command again to continue, or raise "
            "--deadline")
    if run.fatal is not None:
        return TransportError(f"{name}: {run.fatal.message} from {endpoint}",
                              hint=run.fatal.hint or "check the API key, the model name and "
                              "base_url")
    if run.breaker.tripped is not None:
        return TransportError(f"{name}: stopped: {run.breaker.tripped} at {endpoint}",
                              hint="check the server (-v shows every retry); --max-failures "
                              "sets the threshold")
    return None
