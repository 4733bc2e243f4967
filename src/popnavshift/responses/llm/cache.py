"""A content-addressed SQLite cache of LLM answers (SPEC §3).

One row per request in ``responses``, keyed by :func:`request_key`: the sha256 of
the canonical JSON of the exact request (endpoint, model, body including the
messages and the schema, replicate index) and of the served model's identity when the
server gives one (``identities`` keeps the last one per endpoint and model). The API
key and the headers never enter the key nor the file. Only *valid* answers are stored
there; the raw text is kept and validated again on every read, so a row that no longer parses (the
schema changed, the file was edited) is a miss, counted in ``stats.invalid`` and
logged, never served. Invalid replies and transport failures go to a separate
``failures`` table that is never read back as an answer.

The database runs in WAL mode so that other processes can read while a run
writes; within a process one connection is shared behind a lock (writes are
tiny next to a network round trip).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...errors import ConfigError, RespondentError
from ...hashing import digest
from ..schema import parse_answer

log = logging.getLogger(__name__)

#: 2: responses.served_model; 3: responses.system_fingerprint, identities.details; 4: the
#: fingerprints table (older files are migrated on open)
SCHEMA_VERSION = 4

_DDL = """
CREATE TABLE IF NOT EXISTS responses (
    request_hash TEXT PRIMARY KEY,
    persona_id TEXT NOT NULL,
    variant TEXT NOT NULL,
    model TEXT NOT NULL,
    raw TEXT NOT NULL,
    attempts INTEGER NOT NULL,
    prompt_tokens INTEGER NOT NULL,
    completion_tokens INTEGER NOT NULL,
    total_tokens INTEGER NOT NULL,
    created REAL NOT NULL,
    served_model TEXT,
    system_fingerprint TEXT
);
CREATE INDEX IF NOT EXISTS responses_persona ON responses (persona_id, variant);
CREATE TABLE IF NOT EXISTS failures (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    request_hash TEXT NOT NULL,
    persona_id TEXT NOT NULL,
    variant TEXT NOT NULL,
    model TEXT NOT NULL,
    error TEXT NOT NULL,
    raw TEXT,
    created REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS failures_persona ON failures (persona_id, variant);
CREATE INDEX IF NOT EXISTS failures_request ON failures (request_hash);
CREATE TABLE IF NOT EXISTS identities (
    endpoint TEXT NOT NULL,
    model TEXT NOT NULL,
    identity TEXT NOT NULL,
    seen REAL NOT NULL,
    details TEXT,
    PRIMARY KEY (endpoint, model)
);
CREATE TABLE IF NOT EXISTS fingerprints (
    endpoint TEXT NOT NULL,
    model TEXT NOT NULL,
    listed TEXT NOT NULL,
    fingerprint TEXT NOT NULL,
    answers TEXT NOT NULL,
    seen REAL NOT NULL,
    PRIMARY KEY (endpoint, model, listed, fingerprint)
);
"""


def request_key(endpoint: str, model: str, body: dict[str, Any], sample: int = 0,
                identity: str | None = None) -> str:
    """sha256 hex of the exact request (its body carries the sample's seed), its sample
    index and, when the server named it, the identity of the model it serves (so a model
    swapped behind one URL is a new request); never include credentials or headers in
    ``body``. The sample is keyed under its former name, ``replicate``: a cache filled
    before samples existed still answers sample 0."""
    request = {"endpoint": endpoint, "model": model, "body": body, "replicate": sample}
    return digest(request if identity is None else {**request, "identity": identity})


@dataclass(frozen=True)
class CachedAnswer:
    """A stored valid answer, re-validated on read."""

    answer: dict[str, Any]
    raw: str
    attempts: int
    tokens: dict[str, int]
    served_model: str | None = None
    fingerprint: str | None = None  # the reply's system_fingerprint


@dataclass(frozen=True)
class Identity:
    """``key``: the served model's fingerprint, in every cache key; ``details``: what the
    server said of the model (keys of :data:`popnavshift.tables.IDENTITY_COLUMNS`)."""

    key: str
    details: dict[str, Any] = field(default_factory=dict)


@dataclass
class CacheStats:
    hits: int = 0
    misses: int = 0
    stored: int = 0
    invalid: int = 0  # stored rows that failed validation on read (served as misses)
    failures: int = 0  # rows written to the failures table


class ResponseCache:
    """SQLite cache of valid answers plus a log of failures; usable from many threads.

    ``path`` is the database file (created with its parent folder). Use as a
    context manager or call :meth:`close`.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.stats = CacheStats()
        self._lock = threading.Lock()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, timeout=30.0, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            version = self._db.execute("PRAGMA user_version").fetchone()[0]
            if version in (1, 2, 3):
                self._migrate(version)
            elif version not in (0, SCHEMA_VERSION):
                raise ConfigError(
                    f"response cache {self.path} has schema version {version}, "
                    f"expected {SCHEMA_VERSION}",
                    hint="use a new cache_path",
                )
            self._db.executescript(_DDL)
            self._db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            self._db.commit()
        except sqlite3.DatabaseError as exc:
            raise ConfigError(f"cannot open response cache {self.path}: {exc}") from None

    def _migrate(self, version: int) -> None:
        """Add the columns a version-1 or -2 file lacks (a version-3 file lacks only the
        fingerprints table, which the DDL creates)."""
        added = [("responses", "served_model")] if version == 1 else []
        added += [("responses", "system_fingerprint"), ("identities", "details")
                  ] if version < 3 else []
        for table, column in added:
            exists = self._db.execute("SELECT name FROM sqlite_master WHERE name = ?",
                                      (table,)).fetchone()
            if exists:
                self._db.execute(f"ALTER TABLE {table} ADD COLUMN {column} TEXT")

    def get(self, request_hash: str) -> CachedAnswer | None:
        """The valid answer stored for ``request_hash``, or None (a miss)."""
        with self._lock:
            row = self._db.execute(
                "SELECT raw, attempts, prompt_tokens, completion_tokens, total_tokens, "
                "served_model, system_fingerprint FROM responses WHERE request_hash = ?",
                (request_hash,),
            ).fetchone()
            if row is None:
                self.stats.misses += 1
                return None
            raw, attempts, prompt, completion, total, served_model, fingerprint = row
            try:
                answer = parse_answer(raw)
            except RespondentError as exc:
                self.stats.invalid += 1
                self.stats.misses += 1
                log.warning("cached answer %s no longer validates (%s); asking again",
                            request_hash[:12], exc)
                return None
            self.stats.hits += 1
        tokens = {"prompt": prompt, "completion": completion, "total": total}
        return CachedAnswer(answer, raw, attempts, tokens, served_model, fingerprint)

    def put(
        self,
        request_hash: str,
        *,
        persona_id: str,
        variant: str,
        model: str,
        raw: str,
        attempts: int,
        tokens: dict[str, int],
        served_model: str | None = None,
        fingerprint: str | None = None,
    ) -> None:
        """Store a valid answer (raises RespondentError if ``raw`` does not validate)."""
        parse_answer(raw)  # only valid answers may ever be served from this table
        with self._lock:
            self._db.execute(
                "INSERT OR REPLACE INTO responses (request_hash, persona_id, variant, model, "
                "raw, attempts, prompt_tokens, completion_tokens, total_tokens, created, "
                "served_model, system_fingerprint) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (request_hash, persona_id, variant, model, raw, attempts,
                 tokens.get("prompt", 0), tokens.get("completion", 0), tokens.get("total", 0),
                 time.time(), served_model, fingerprint),
            )
            self._db.commit()
            self.stats.stored += 1

    def put_failure(
        self,
        request_hash: str,
        *,
        persona_id: str,
        variant: str,
        model: str,
        error: str,
        raw: str | None,
    ) -> None:
        """Log one invalid reply or transport failure (never served as an answer)."""
        with self._lock:
            self._db.execute(
                "INSERT INTO failures (request_hash, persona_id, variant, model, error, raw, "
                "created) VALUES (?, ?, ?, ?, ?, ?, ?)",
                (request_hash, persona_id, variant, model, error, raw, time.time()),
            )
            self._db.commit()
            self.stats.failures += 1

    def identity(self, endpoint: str, model: str) -> Identity | None:
        """The identity the server at ``endpoint`` last gave for ``model`` (None: never)."""
        with self._lock:
            row = self._db.execute("SELECT identity, details FROM identities WHERE endpoint = "
                                   "? AND model = ?", (endpoint, model)).fetchone()
        return None if row is None else Identity(str(row[0]), json.loads(row[1] or "{}"))

    def remember_identity(self, endpoint: str, model: str, identity: str,
                          details: dict[str, Any] | None = None) -> None:
        """Keep the identity the server gave, for a run that cannot ask it (offline replay)."""
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO identities (endpoint, model, identity, "
                             "seen, details) VALUES (?, ?, ?, ?, ?)",
                             (endpoint, model, identity, time.time(),
                              json.dumps(details or {}, sort_keys=True)))
            self._db.commit()

    def fingerprints(self, endpoint: str, model: str, listed: str) -> list[str]:
        """The behavioural fingerprints seen for ``model`` at ``endpoint`` under the listed
        identity ``listed`` (:mod:`.canaries`), the most recent first."""
        with self._lock:
            rows = self._db.execute(
                "SELECT fingerprint FROM fingerprints WHERE endpoint = ? AND model = ? AND "
                "listed = ? ORDER BY seen DESC", (endpoint, model, listed)).fetchall()
        return [str(r[0]) for r in rows]

    def remember_fingerprint(self, endpoint: str, model: str, listed: str, fingerprint: str,
                             answers: tuple[str, ...]) -> None:
        """Keep a behavioural fingerprint with the canary answers it digests."""
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO fingerprints (endpoint, model, listed, "
                             "fingerprint, answers, seen) VALUES (?, ?, ?, ?, ?, ?)",
                             (endpoint, model, listed, fingerprint, json.dumps(list(answers)),
                              time.time()))
            self._db.commit()

    def failures(self, persona_id: str | None = None) -> list[dict[str, Any]]:
        """Logged failures, oldest first (optionally for one persona)."""
        sql = "SELECT request_hash, persona_id, variant, model, error, raw, created FROM failures"
        args: tuple[str, ...] = ()
        if persona_id is not None:
            sql, args = sql + " WHERE persona_id = ?", (persona_id,)
        with self._lock:
            cur = self._db.execute(sql + " ORDER BY id", args)
            cols = [c[0] for c in cur.description]
            return [dict(zip(cols, row, strict=True)) for row in cur.fetchall()]

    def count(self) -> int:
        """Number of stored answers."""
        with self._lock:
            return self._db.execute("SELECT COUNT(*) FROM responses").fetchone()[0]

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def __enter__(self) -> ResponseCache:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

