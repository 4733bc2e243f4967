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
of the record's *first* request (and of the served model's identity: its listing and its
answers to the canary prompts, a few cheap calls before the cache is read), so a second
identical run asks no record again. The stage's ``deadline`` bounds all of it, calls in
flight included (:class:`~.retries.Clock`), and a server that answers nothing for two
request timeouts stops the run (:mod:`.run_state`).
"""

from __future__ import annotations

import logging
import time
from abc import abstractmethod
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from concurrent.futures import TimeoutError as FuturesTimeout
from dataclasses import replace
from functools import partial
from typing import Any

from ...errors import ConfigError, RespondentError, TransportError
from ...hashing import digest
from ..probes import PROBE_SET_HASH
from ..respondent import Answer, ProbeRequest, Progress, Respondent, sample_seed
from ..schema import parse_answer
from .cache import CacheStats, ResponseCache, request_key
from .identity import Identity, portable, served_identity
from .readiness import Breaker, announced, wait_until_ready
from .retries import (
    Clock,
    DeadlineReached,
    RateLimiter,
    RetryPolicy,
    Session,
    TransportFailure,
    add_tokens,
    send_with_retries,
)
from .run_state import Run, stop_error
from .settings import SETTING_NAMES, LLMSettings, check_settings, with_settings

log = logging.getLogger("popnavshift.responses.llm")

#: seconds the stage waits past its deadline for the calls in flight (cut to end at it)
DEADLINE_GRACE = 2.0

REASK = (
    "Your previous reply was not valid: {error}. Reply again with only the JSON object "
    "matching the schema, with every encounter and every item."
)


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
        if unknown:  # the message a study file gets from the registry, for the Python API
            raise ConfigError(f"{type(self).__name__}: unknown option {unknown[0]!r}"
                              + (" (replicate was removed: ask independent samples with "
                                 "samples=k, each sent with its own seed)"
                                 if unknown[0] == "replicate" else ""),
                              hint="accepted: " + ", ".join(SETTING_NAMES))
        self._model = model
        for name, value in settings.items():
            setattr(self, name, value)
        self.cache_stats: CacheStats | None = None  # counts of the last answer_all
        self._served_identity: str | None = None  # of the last answer_all's server
        #: what the server said of its model (file name, size, parameters, build) in the
        #: last answer_all, or last told (offline replay): the responses' identity columns
        self.served_details: dict[str, Any] = {}
        self._counts: dict[str, int] = {}  # the current run's calls, retries, failures
        #: when a canary call went unanswered (monotonic s): the run's hang clock starts there
        self._silent_since: float | None = None

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
    def _connect(self, key: str | None, clock: Clock = Clock()) -> Session:
        """Open a session (clients, connection pool) for one run; no call outlasts
        ``clock``'s deadline."""

    def describe(self) -> dict[str, Any]:
        return {
            "respondent": self.name, "model": self.model, "endpoint": self.endpoint,
            "temperature": self.temperature, "seed": self.seed,
            "max_reasks": self.max_reasks, "max_tokens": self.max_tokens,
            "probe_set": PROBE_SET_HASH,
            **({"model_sha256": self.model_sha256} if self.model_sha256 else {}),
        }

    def progress_note(self) -> str:
        """The current run's requests in flight, network calls, transport retries and failed
        records so far, for the progress lines."""
        c = self._counts
        return (f"{c.get('in_flight', 0)} in flight, {c.get('calls', 0)} calls, "
                f"{c.get('retries', 0)} retries, {c.get('failed', 0)} failed")

    def validate(self) -> None:
        """Raise ConfigError for a bad setting (``answer_all`` calls this first)."""
        check_settings(self)

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
        clock = Clock.after(self.deadline)
        cache = ResponseCache(self.cache_path) if self.cache_path is not None else None
        self.cache_stats = None
        self._silent_since = None
        try:
            with announced(f"{self.name} server {self.endpoint} (its model list and "
                           "canary prompts)"):
                self._identify(cache, clock)
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
                self._ask_all(requests, keys, list(todo.values()), answers, cache, tick, clock)
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

    def _identify(self, cache: ResponseCache | None, clock: Clock) -> None:
        """Learn which model the server serves (:func:`.identity.served_identity`, with the
        user's ``model_sha256``): the identity in every cache key, and the records'
        identity columns."""
        found = served_identity(partial(self._ask_identity, cache, clock), cache,
                                self.endpoint, self.model, self.name)
        details = dict(found.details) if found is not None else {}
        key = found.key if found is not None else None
        if self.model_sha256:
            details["model_sha256"] = self.model_sha256.lower()
            key = digest({"served": key, "sha256": self.model_sha256.lower()})
        self._served_identity, self.served_details = key, details

    def _ask_all(
        self,
        requests: Sequence[ProbeRequest],
        keys: list[str],
        todo: list[int],
        answers: dict[int, Answer],
        cache: ResponseCache | None,
        tick: Progress,
        clock: Clock,
    ) -> None:
        secret = self._api_key()  # MissingKeyError before any network call
        run = Run(self._connect(secret, clock), cache, RateLimiter(self.rate_limit),
                  Breaker(self.max_consecutive_failures), clock, self.timeout,
                  self._silent_since or time.monotonic())
        self._counts = run.counts
        pool = ThreadPoolExecutor(self.max_concurrency, "popnavshift-llm")
        try:
            self._wait_ready(run)
            futures = ({pool.submit(self._ask, requests[i], keys[i], run): i for i in todo}
                       if run.deadline is None else {})
            # calls in flight end at the deadline (their timeouts are cut to it): wait a
            # moment beyond it, never for a call the server will not answer
            wait = None if clock.end is None else max(clock.left(), 0.0) + DEADLINE_GRACE
            try:
                for fut in as_completed(futures, timeout=wait):
                    answers[futures[fut]] = fut.result()
                    tick(1)
            except FuturesTimeout:
                run.deadline = run.deadline or "calls still in flight at the deadline"
        finally:
            # A no-op after a normal finish; on Ctrl-C or a bug it drops the queued records.
            pool.shutdown(wait=False, cancel_futures=True)
            run.session.close()
        error = stop_error(run, self.name, self.endpoint, answers, len(requests))
        if error is not None:
            raise error

    def _wait_ready(self, run: Run) -> None:
        """Wait for the server (:func:`.readiness.wait_until_ready`) within the stage's
        deadline; a wait the deadline cut short stops the run as the deadline."""
        if run.clock.passed:
            run.deadline = "before the first record"
            return
        try:
            wait_until_ready(run.session.check_ready, f"{self.name} server {self.endpoint}",
                             min(self.ready_timeout, max(run.clock.left(), 0.0)))
        except TransportError:
            if not run.clock.passed:
                raise
            run.deadline = "waiting for the server to be ready"

    def _key(self, body: dict, sample: int) -> str:
        return request_key(self.endpoint, self.model, body, sample, self._served_identity)

    def _ask_identity(self, cache: ResponseCache | None, clock: Clock) -> Identity | None:
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
                      served_model=portable(hit.served_model), fingerprint=hit.fingerprint)

    def _ask(self, req: ProbeRequest, key: str, run: Run) -> Answer:
        """One record: up to 1 + max_reasks content attempts, each with transport retries.

        A reply cut at the token limit is not re-asked with the same limit (it would be
        cut again): the request is sent again with twice the limit, or, when no limit
        was set (the server's own), the record fails with a hint to set one."""
        ans = Answer(req.persona_id, req.variant, tokens={"prompt": 0, "completion": 0, "total": 0})
        policy = RetryPolicy(self.max_retries, self.backoff_base, self.backoff_cap,
                             self.max_retry_after)
        reasks: list[tuple[str, str]] = []
        limit = self.max_tokens
        for attempt in range(self.max_reasks + 1):
            if run.stopped():
                ans.error = f"skipped: {run.fatal or run.breaker.tripped or run.deadline}"
                return ans
            body = self._body(req.persona, reasks, limit, req.sample)
            ans.attempts = attempt + 1
            try:
                send = partial(run.send, body, f"{self.name} server {self.endpoint}",
                               ans)
                reply, calls = send_with_retries(send, policy, run.limiter, run.clock,
                                                 run.stopped, partial(run.count, "retries"))
            except DeadlineReached as exc:
                run.deadline = run.deadline or str(exc)
                ans.error = f"not answered: {exc}"
                return ans
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

    def _log_failure(self, run: Run, req: ProbeRequest, body: dict, error: str,
                     raw: str | None) -> None:
        if run.cache is not None:
            run.cache.put_failure(self._key(body, req.sample), persona_id=req.persona_id,
                                  variant=req.variant, model=self.model, error=error, raw=raw)


def _copy(asked: Answer, req: ProbeRequest) -> Answer:
    """The answer to an identical request, for another record of the same batch."""
    return replace(asked, persona_id=req.persona_id, variant=req.variant, calls=0, seconds=0.0,
                   cached=asked.answer is not None, tokens=dict(asked.tokens))
