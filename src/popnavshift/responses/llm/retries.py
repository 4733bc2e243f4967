"""Transport retries: which failures are retried, how long to wait, how fast to send.

HTTP 408/429/5xx, timeouts and connection errors are retried up to ``max_retries``
times (:func:`send_with_retries`), waiting the server's ``Retry-After`` when given
(capped at :data:`MAX_RETRY_AFTER`) and otherwise
``min(backoff_cap, backoff_base * 2**(retry - 1))`` seconds; other 4xx replies are
final. A session (one per run, :class:`Session`) turns one HTTP exchange into a
:class:`Reply` or raises :class:`RetryableError` / :class:`FinalError`.
"""

from __future__ import annotations

import email.utils
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from ...errors import TransportError
from ...redact import redact

log = logging.getLogger("popnavshift.responses.llm")

#: Longest ``Retry-After`` honoured by default (s); a longer one is shortened to this
#: (a server asking for an hour would otherwise hold a run for ``max_retries`` hours).
MAX_RETRY_AFTER = 60.0
#: a failed call or a wait this long (s) is reported without ``-v``: a run must never sit
#: silent on a hanging or rate-limiting server
WAIT_NOTICE = 5.0
RETRY_STATUSES = frozenset({408, 429, 500, 502, 503, 504})
FATAL_STATUSES = frozenset({401, 403, 404})

class RetryableError(Exception):
    """Raised by a session for a failure worth retrying (``reason`` is one line);
    ``heard``: the server replied (an HTTP status, a body), as against a timeout or a
    connection error."""

    def __init__(self, reason: str, retry_after: float | None = None, *,
                 heard: bool = False) -> None:
        super().__init__(reason)
        self.reason = reason
        self.retry_after = retry_after
        self.heard = heard


class FinalError(Exception):
    """Raised by a session for a failure that retrying cannot fix."""

    def __init__(self, reason: str, *, fatal: bool = False) -> None:
        super().__init__(reason)
        self.reason = reason
        self.fatal = fatal  # wrong for every record: stop the run


class TransportFailure(TransportError):
    """The transport gave up on one request after ``calls`` network calls."""

    def __init__(self, message: str, *, calls: int, fatal: bool = False,
                 hint: str | None = None) -> None:
        super().__init__(redact(message), hint=hint)  # servers echo credentials in bodies
        self.calls = calls
        self.fatal = fatal


@dataclass
class Reply:
    """What one successful HTTP exchange returned."""

    text: str | None
    tokens: dict[str, int] = field(default_factory=dict)  # prompt, completion, total
    note: str | None = None  # why the text may be incomplete (finish reason, refusal)
    truncated: bool = False  # cut at the token limit (finish_reason length / MAX_TOKENS)
    model: str | None = None  # the model that served the request, as the server names it
    fingerprint: str | None = None  # the server's build fingerprint (system_fingerprint)


class Session(Protocol):
    def send(self, body: dict[str, Any], timeout: float | None = None) -> Reply:
        """One exchange; ``timeout`` (s) shortens the session's own (a stage deadline)."""

    def check_ready(self) -> None:
        """Return when the server answers; raise :class:`~.readiness.NotReady` otherwise."""

    def close(self) -> None: ...


def check_status(status: int, retry_after: str | None, message: str) -> None:
    """Raise RetryableError/FinalError for a non-2xx HTTP status."""
    if status < 400:
        return
    if status in RETRY_STATUSES or status >= 500:
        raise RetryableError(f"HTTP {status}", parse_retry_after(retry_after), heard=True)
    raise FinalError(f"HTTP {status}: {message}", fatal=status in FATAL_STATUSES)


def parse_retry_after(value: str | None) -> float | None:
    """Seconds to wait from a ``Retry-After`` header (delta-seconds or HTTP date)."""
    if value is None or not value.strip():
        return None
    try:
        seconds = float(value)
    except ValueError:
        try:
            when = email.utils.parsedate_to_datetime(value)
        except (TypeError, ValueError):
            return None
        seconds = when.timestamp() - time.time()
    return seconds if math.isfinite(seconds) and seconds > 0 else 0.0


@dataclass(frozen=True)
class Clock:
    """A stage's deadline on the monotonic clock (``end`` None: none)."""

    end: float | None = None
    seconds: float | None = None  # the deadline as given, for messages

    @classmethod
    def after(cls, seconds: float | None) -> Clock:
        return cls(None if seconds is None else time.monotonic() + seconds, seconds)

    def left(self) -> float:
        """Seconds left (inf without a deadline; ≤ 0 once it passed)."""
        return math.inf if self.end is None else self.end - time.monotonic()

    def bound(self, seconds: float) -> float:
        """``seconds`` cut to what is left (at least a millisecond: a call needs one)."""
        return max(1e-3, min(seconds, self.left()))

    @property
    def passed(self) -> bool:
        return self.left() <= 0


class DeadlineReached(TransportError):
    """The stage's deadline (``--deadline``) passed: no call is started after it."""


@dataclass(frozen=True)
class RetryPolicy:
    """Bounded exponential backoff; times in s. A ``Retry-After`` longer than
    ``max_retry_after`` stops the run (every record would wait as long)."""

    max_retries: int = 5
    backoff_base: float = 0.5
    backoff_cap: float = 30.0
    max_retry_after: float = MAX_RETRY_AFTER

    def delay(self, retry: int, retry_after: float | None = None) -> float:
        """Wait before retry number ``retry`` (1-based); ``Retry-After`` wins when given."""
        if retry_after is not None:
            return min(retry_after, self.max_retry_after)
        return min(self.backoff_cap, self.backoff_base * 2 ** (retry - 1))

    def too_long(self, retry_after: float | None) -> bool:
        return retry_after is not None and retry_after > self.max_retry_after


class RateLimiter:
    """At most ``rate`` call starts per second across threads (None = unlimited)."""

    def __init__(self, rate: float | None) -> None:
        self.interval = 0.0 if rate is None else 1.0 / rate
        self._next = 0.0
        self._lock = threading.Lock()

    def wait(self) -> None:
        if self.interval == 0.0:
            return
        with self._lock:
            now = time.monotonic()
            slot = max(now, self._next)
            self._next = slot + self.interval
        if slot > now:
            time.sleep(slot - now)


def send_with_retries(
    send: Callable[[float | None], Reply], policy: RetryPolicy, limiter: RateLimiter,
    clock: Clock = Clock(), stopped: Callable[[], bool] = lambda: False,
    on_retry: Callable[[], None] = lambda: None,
) -> tuple[Reply, int]:
    """``(reply, calls)``; ``send(timeout)`` makes one call, ``timeout`` the time left
    before ``clock``'s deadline (None: no deadline). Raises :class:`TransportFailure`
    once retries are spent, before a retry once ``stopped()`` (the run is being stopped),
    at once (fatal) when the server asks to wait longer than ``max_retry_after``, and
    :class:`DeadlineReached` once the deadline passed. ``on_retry()`` is called before
    each retry (the progress lines count them as they happen)."""
    calls = 0
    exc_reason = ""
    while True:
        limiter.wait()
        if clock.passed:
            raise DeadlineReached("before a call" + (f" (after {exc_reason})" if calls else ""))
        calls += 1
        sent = time.monotonic()
        try:
            return send(clock.bound(math.inf) if clock.end is not None else None), calls
        except RetryableError as exc:
            exc_reason = exc.reason
            if policy.too_long(exc.retry_after):
                raise TransportFailure(
                    f"{exc.reason}: the server asks to wait {exc.retry_after:.0f} s "
                    f"(Retry-After), more than max_retry_after {policy.max_retry_after:g} s",
                    calls=calls, fatal=True, hint="try later, or allow the wait with "
                    "--max-retry-after (the respondent option max_retry_after)") from None
            wait = policy.delay(calls, exc.retry_after)
            if calls > policy.max_retries or stopped():
                why = (f"after {policy.max_retries} retries" if calls > policy.max_retries
                       else "(run stopped)")
                raise TransportFailure(f"{exc.reason} {why}", calls=calls) from None
            if clock.left() <= wait:
                raise DeadlineReached(f"before a retry after {exc.reason}") from None
            took = time.monotonic() - sent
            slow = wait >= WAIT_NOTICE or took >= WAIT_NOTICE
            log.log(logging.WARNING if slow else logging.INFO, "%s; retry %d/%d in %.2f s%s",
                    exc.reason, calls, policy.max_retries, wait,
                    f" (the call took {took:.0f} s)" if took >= WAIT_NOTICE else "")
            on_retry()
            time.sleep(wait)
        except FinalError as exc:
            raise TransportFailure(exc.reason, calls=calls, fatal=exc.fatal) from None


def add_tokens(total: dict[str, int], more: Mapping[str, int]) -> None:
    for k in ("prompt", "completion", "total"):
        total[k] = total.get(k, 0) + int(more.get(k) or 0)
