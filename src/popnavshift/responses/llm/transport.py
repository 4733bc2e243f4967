"""How a request reaches an LLM server and comes back valid.

Two loops, kept apart (SPEC §3):

* **Transport retries** (:func:`.retries.send_with_retries`): HTTP 408/429/5xx, timeouts
  and connection errors are retried up to ``max_retries`` times, waiting the
  server's ``Retry-After`` when given (capped at :data:`MAX_RETRY_AFTER`) and
  otherwise ``min(backoff_cap, backoff_base * 2**(retry - 1))`` seconds. There is
  no jitter: waits are reproducible, and with a handful of workers behind one
  rate limiter there is no herd to spread. Other 4xx replies are final; 401,
  403 and 404 mean the key, the model or the URL is wrong for every record, so
  they stop the whole run.
* **Re-asks** (:meth:`LLMRespondent._ask`): a reply that arrives but does not
  validate is answered, in the same conversation, with the validation error and
  a request to reply again: at most ``max_reasks`` times. Each re-ask is a new
  request (the conversation grew), so it has its own hash in the failures log,
  and the cache (which stores valid answers only) can never serve it a failure.

:class:`LLMRespondent` runs both for many records on a thread pool of
``max_concurrency`` workers behind a shared :class:`RateLimiter`, with the
:class:`~.cache.ResponseCache` in front: a valid answer is stored under the hash
of the record's *first* request (and of the served model's identity, when the server
names it: one cheap call before the cache is read), so a second identical run makes no
request.
"""

from __future__ import annotations

import logging
import threading
from abc import abstractmethod
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

from ...errors import ConfigError, RespondentError, TransportError
from ...redact import redact
from ..probes import PROBE_SET_HASH
from ..respondent import Answer, ProbeRequest, Progress, Respondent, sample_seed
from ..schema import parse_answer
from .cache import CacheStats, ResponseCache, request_key
from .identity import Identity, served_identity
from .readiness import Breaker, announced, wait_until_ready
from .retries import (
    RateLimiter,
    RetryPolicy,
    Session,
    TransportFailure,
    add_tokens,
    send_with_retries,
)
from .settings import SETTING_NAMES, LLMSettings, check_setting, is_int, is_pos, with_settings

log = logging.getLogger("popnavshift.responses.llm")

REASK = (
    "Your previous reply was not valid: {error}. Reply again with only the JSON object "
    "matching the schema, with every encounter and every item."
)


@dataclass
class _Run:
    """State shared by the workers of one ``answer_all`` call."""

    session: Session
    cache: ResponseCache | None
    limiter: RateLimiter
    breaker: Breaker
    fatal: TransportFailure | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    counts: dict[str, int] = field(
        default_factory=lambda: {"calls": 0, "retries": 0, "failed": 0})

    def count(self, what: str, n: int = 1) -> None:
        with self.lock:
            self.counts[what] += n

    def stopped(self) -> bool:
        return self.fatal is not None or self.breaker.tripped is not None

    @staticmethod
    def redact(text: str) -> str:
        # Defence in depth: servers sometimes echo credentials in error bodies.
        return redact(text)


class LLMRespondent(LLMSettings, Respondent):
    """Shared engine of the network respondents (cache, retries, re-asks, pool).

    Subclasses set ``name``, :attr:`endpoint`, and implement :meth:`_api_key`,
    :meth:`_body` and :meth:`_connect`. Times are in s, ``rate_limit`` in calls/s.
    """

    uses_cache = True

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if "__init__" in vars(cls):  # its own options, then every shared setting
            cls.__signature__ = with_settings(cls.__init__)  # type: ignore[attr-defined]

    def __init__(self, *, model: str, **settings: Any) -> None:
        """``model`` and any of the :class:`~.settings.LLMSettings` (the rest keep their
        defaults, the class attributes)."""
        unknown = [k for k in settings if k not in SETTING_NAMES]
        if unknown:
            raise TypeError(f"unexpected keyword argument {unknown[0]!r}")
        self._model = model
        for name, value in settings.items():
            setattr(self, name, value)
        self.cache_stats: CacheStats | None = None  # counts of the last answer_all
        self._served_identity: str | None = None  # of the last answer_all's server
        #: what the server said of its model (file name, size, parameters, build) in the
        #: last answer_all, or last told (offline replay): the responses' identity columns
        self.served_details: dict[str, Any] = {}
        self._counts: dict[str, int] = {}  # the current run's calls, retries, failures

    @property
    def model(self) -> str:
        return self._model

    @property
    @abstractmethod
    def endpoint(self) -> str:
        """URL the requests are posted to (part of every cache key)."""

    @abstractmethod
    def _api_key(self) -> str | None:
        """The key from the environment; raise MissingKeyError naming the variable."""

    @abstractmethod
    def _body(self, persona: Mapping[str, Any], reasks: Sequence[tuple[str, str]],
              max_tokens: int | None = None, sample: int = 0) -> dict:
        """The exact request body; ``reasks`` holds (invalid raw reply, error) turns;
        ``max_tokens`` overrides :attr:`max_tokens` (a retry after a truncated reply);
        ``sample`` selects the seed sent (:meth:`request_seed`)."""

    def request_seed(self, sample: int) -> int | None:
        """The seed sent with independent sample ``sample`` (None: no seed is sent)."""
        return None if self.seed is None else sample_seed(self.seed, sample)

    @abstractmethod
    def _connect(self, key: str | None) -> Session:
        """Open a session (clients, connection pool) for one run."""

    def describe(self) -> dict[str, Any]:
        return {
            "respondent": self.name, "model": self.model, "endpoint": self.endpoint,
            "temperature": self.temperature, "seed": self.seed,
            "max_reasks": self.max_reasks, "max_tokens": self.max_tokens,
            "probe_set": PROBE_SET_HASH,
        }

    def progress_note(self) -> str:
        """The current run's network calls, transport retries and failed records so far,
        for the progress lines."""
        c = self._counts
        return (f"{c.get('calls', 0)} calls, {c.get('retries', 0)} retries, "
                f"{c.get('failed', 0)} failed")

    def validate(self) -> None:
        """Raise ConfigError for a bad setting (``answer_all`` calls this first)."""
        checks = [
            ("model", isinstance(self.model, str) and self.model.strip() != "",
             "a non-empty model name"),
            ("max_concurrency", is_int(self.max_concurrency, 1), "an int ≥ 1"),
            ("rate_limit", self.rate_limit is None or is_pos(self.rate_limit),
             "None or calls/s > 0"),
            ("timeout", is_pos(self.timeout), "seconds > 0"),
            ("max_retries", is_int(self.max_retries, 0), "an int ≥ 0"),
            ("max_reasks", is_int(self.max_reasks, 0), "an int ≥ 0"),
            ("backoff_base", is_pos(self.backoff_base) or self.backoff_base == 0, "seconds ≥ 0"),
            ("backoff_cap", is_pos(self.backoff_cap) or self.backoff_cap == 0, "seconds ≥ 0"),
            ("max_tokens", self.max_tokens is None or is_int(self.max_tokens, 1),
             "None or an int ≥ 1"),
            ("ready_timeout", is_pos(self.ready_timeout) or self.ready_timeout == 0,
             "seconds ≥ 0"),
            ("max_consecutive_failures", is_int(self.max_consecutive_failures, 1),
             "an int ≥ 1"),
            ("max_retry_after", is_pos(self.max_retry_after) or self.max_retry_after == 0,
             "seconds ≥ 0"),
            ("deadline", self.deadline is None or is_pos(self.deadline), "None or seconds > 0"),
        ]
        for name, ok, expected in checks:
            check_setting(ok, name, expected, getattr(self, name))

    def answer_all(
        self, requests: Sequence[ProbeRequest], progress: Progress | None = None
    ) -> list[Answer]:
        """Answer every request in order; cached answers first, then the network.

        Never raises for one record (it comes back with ``error`` set). Raises
        ConfigError / MissingKeyError before any call if the respondent cannot
        run, and TransportError once the pool stops if the server rejected the
        key, the model or the URL (HTTP 401/403/404). Records whose request is
        identical (same persona fields) are asked once; the copies count as cached.
        """
        self.validate()
        if self.seed is None and any(r.sample for r in requests):
            raise ConfigError("several samples need a seed: seed=None sends none, so the "
                              "samples would be one request asked again",
                              hint="set seed (--respondent-seed) or ask one sample")
        tick = progress or (lambda n: None)
        answers: dict[int, Answer] = {}
        todo: dict[str, int] = {}  # request hash → the record that asks it
        cache = ResponseCache(self.cache_path) if self.cache_path is not None else None
        self.cache_stats = None
        try:
            with announced(f"{self.name} server {self.endpoint} (its model list)"):
                self._served_identity, self.served_details = served_identity(
                    self._ask_identity, cache, self.endpoint, self.model, self.name)
            keys = [self._key(self._body(r.persona, (), sample=r.sample), r.sample)
                    for r in requests]
            for i, (req, key) in enumerate(zip(requests, keys, strict=True)):
                if key in todo:
                    continue
                hit = self._from_cache(req, key, cache)
                if hit is None:
                    todo[key] = i
                else:
                    answers[i] = hit
                    tick(1)
            if todo:
                self._ask_all(requests, keys, list(todo.values()), answers, cache, tick)
        finally:
            if cache is not None:
                self.cache_stats = cache.stats
                cache.close()
        for i, key in enumerate(keys):
            if i not in answers:
                answers[i] = _copy(answers[todo[key]], requests[i])
                tick(1)
        out = [answers[i] for i in range(len(requests))]
        log.info("%s %s: %d records, %d cached, %d invalid, %d calls", self.name, self.model,
                 len(out), sum(a.cached for a in out), sum(a.error is not None for a in out),
                 sum(a.calls for a in out))
        return out

    def _ask_all(
        self,
        requests: Sequence[ProbeRequest],
        keys: list[str],
        todo: list[int],
        answers: dict[int, Answer],
        cache: ResponseCache | None,
        tick: Progress,
    ) -> None:
        secret = self._api_key()  # MissingKeyError before any network call
        run = _Run(self._connect(secret), cache, RateLimiter(self.rate_limit),
                   Breaker(self.max_consecutive_failures))
        self._counts = run.counts
        pool = ThreadPoolExecutor(self.max_concurrency, "popnavshift-llm")
        try:
            wait_until_ready(run.session.check_ready, f"{self.name} server {self.endpoint}",
                             self.ready_timeout)
            futures = {pool.submit(self._ask, requests[i], keys[i], run): i for i in todo}
            for fut in as_completed(futures):
                answers[futures[fut]] = fut.result()
                tick(1)
        finally:
            # A no-op after a normal finish; on Ctrl-C or a bug it drops the queued records.
            pool.shutdown(wait=False, cancel_futures=True)
            run.session.close()
        if run.fatal is not None:
            raise TransportError(
                f"{self.name}: {run.fatal} from {self.endpoint}",
                hint="check the API key, the model name and base_url",
            )
        if run.breaker.tripped is not None:
            raise TransportError(
                f"{self.name}: stopped: {run.breaker.tripped} at {self.endpoint}",
                hint="check the server (-v shows every retry); --max-failures sets the "
                "threshold",
            )

    def _key(self, body: dict, sample: int) -> str:
        return request_key(self.endpoint, self.model, body, sample, self._served_identity)

    def _ask_identity(self) -> Identity | None:
        """The identity of the model the server serves, asked before the cache is read;
        None when the server does not say; raises NotReady (or MissingKeyError) when it
        cannot be asked. This base names none."""
        return None

    def _from_cache(
        self, req: ProbeRequest, key: str, cache: ResponseCache | None
    ) -> Answer | None:
        hit = cache.get(key) if cache is not None else None
        if hit is None:
            return None
        # A hit reports how the stored answer was obtained (attempts, tokens), so the
        # responses table does not depend on cache state; calls=0 says nothing was sent.
        return Answer(req.persona_id, req.variant, answer=hit.answer, raw=hit.raw, calls=0,
                      attempts=hit.attempts, cached=True, tokens=dict(hit.tokens),
                      served_model=hit.served_model, fingerprint=hit.fingerprint)

    def _ask(self, req: ProbeRequest, key: str, run: _Run) -> Answer:
        """One record: up to 1 + max_reasks content attempts, each with transport retries.

        A reply cut at the token limit is not re-asked with the same limit (it would be
        cut again): the request is sent again with twice the limit, or, when no limit
        was set (the server's own), the record fails with a hint to set one."""
        ans = Answer(req.persona_id, req.variant, tokens={"prompt": 0, "completion": 0, "total": 0})
        policy = RetryPolicy(self.max_retries, self.backoff_base, self.backoff_cap,
                             self.max_retry_after, self.deadline)
        reasks: list[tuple[str, str]] = []
        limit = self.max_tokens
        for attempt in range(self.max_reasks + 1):
            if run.stopped():
                ans.error = f"skipped: {run.fatal or run.breaker.tripped}"
                return ans
            body = self._body(req.persona, reasks, limit, req.sample)
            ans.attempts = attempt + 1
            try:
                reply, calls = send_with_retries(partial(run.session.send, body), policy,
                                                 run.limiter, run.stopped,
                                                 partial(run.count, "retries"))
            except TransportFailure as exc:
                run.count("calls", exc.calls)
                run.count("failed")
                ans.calls += exc.calls
                ans.error = run.redact(f"transport: {exc}")
                if exc.fatal:
                    with run.lock:
                        run.fatal = run.fatal or exc
                run.breaker.record(str(exc))
                self._log_failure(run, req, body, ans.error, None)
                return ans
            run.breaker.record(None)
            run.count("calls", calls)
            ans.calls += calls
            ans.served_model = reply.model or ans.served_model
            ans.fingerprint = reply.fingerprint or ans.fingerprint
            add_tokens(ans.tokens, reply.tokens)
            raw = run.redact(reply.text or "")
            try:
                ans.answer = parse_answer(raw)
            except RespondentError as exc:
                error = str(exc) if reply.note is None else f"{exc}; {reply.note}"
                # info, not warning: the records that stay invalid are listed at the end
                log.info("%s %s: invalid reply (attempt %d/%d): %s", req.persona_id,
                            req.variant, attempt + 1, self.max_reasks + 1, error)
                self._log_failure(run, req, body, error, raw)
                ans.raw = raw
                if reply.truncated:
                    if limit is None:
                        ans.error = (f"reply cut at the server's token limit ({reply.note}); "
                                     "set max_tokens (--max-tokens) to allow longer replies")
                        return ans
                    limit *= 2  # the same request with room to finish, not a re-ask
                    continue
                reasks.append((raw, error))
                continue
            ans.raw = raw
            if run.cache is not None:
                run.cache.put(key, persona_id=req.persona_id, variant=req.variant,
                              model=self.model, raw=raw, attempts=ans.attempts, tokens=ans.tokens,
                              served_model=ans.served_model, fingerprint=ans.fingerprint)
            return ans
        last = reasks[-1][1] if reasks else "reply cut at the token limit"
        ans.error = f"invalid after {ans.attempts} attempts: {last}"
        return ans

    def _log_failure(self, run: _Run, req: ProbeRequest, body: dict, error: str,
                     raw: str | None) -> None:
        if run.cache is not None:
            run.cache.put_failure(self._key(body, req.sample), persona_id=req.persona_id,
                                  variant=req.variant, model=self.model, error=error, raw=raw)


def _copy(asked: Answer, req: ProbeRequest) -> Answer:
    """The answer to an identical request, for another record of the same batch."""
    return replace(asked, persona_id=req.persona_id, variant=req.variant, calls=0,
                   cached=asked.answer is not None, tokens=dict(asked.tokens))
