"""The SQLite response cache: content addressing, validation on read, failures, threads."""

from __future__ import annotations

import json
import logging
import sqlite3
import threading

import pytest

from llm_server import valid_answer, valid_text
from popnavshift.errors import RespondentError
from popnavshift.responses.llm.cache import SCHEMA_VERSION, ResponseCache, request_key

TOKENS = {"prompt": 10, "completion": 5, "total": 15}


def _put(cache: ResponseCache, key: str, raw: str | None = None, persona: str = "p1") -> None:
    cache.put(key, persona_id=persona, variant="baseline", model="m",
              raw=raw or valid_text(), attempts=1, tokens=TOKENS)


def test_request_key_is_content_addressed():
    body = {"messages": [{"role": "user", "content": "x"}], "seed": 0}
    key = request_key("http://h/v1/chat/completions", "m", body, 0)
    assert key == request_key("http://h/v1/chat/completions", "m", dict(reversed(body.items())))
    assert len(key) == 64
    others = {
        request_key("http://other/v1/chat/completions", "m", body, 0),
        request_key("http://h/v1/chat/completions", "m2", body, 0),
        request_key("http://h/v1/chat/completions", "m", {**body, "seed": 1}, 0),
        request_key("http://h/v1/chat/completions", "m", body, 1),
    }
    assert key not in others
    assert len(others) == 4


def test_wal_mode_indexes_and_roundtrip(tmp_path):
    path = tmp_path / "sub" / "cache.sqlite"
    with ResponseCache(path) as cache:
        assert cache.get("k1") is None
        _put(cache, "k1")
        hit = cache.get("k1")
        assert hit is not None
        assert hit.answer == valid_answer()
        assert hit.raw == valid_text()
        assert hit.tokens == TOKENS
        assert (cache.stats.hits, cache.stats.misses, cache.stats.stored) == (1, 1, 1)
    db = sqlite3.connect(path)
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    indexes = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='index'")}
    assert {"responses_persona", "failures_persona"} <= indexes
    db.close()
    with ResponseCache(path) as again:  # persisted across connections
        assert again.get("k1") is not None
        assert again.count() == 1


def test_only_valid_answers_are_stored(tmp_path):
    with ResponseCache(tmp_path / "c.sqlite") as cache:
        bad = valid_answer()
        bad["actions"]["P1"] = "fly"
        with pytest.raises(RespondentError, match="P1"):
            _put(cache, "k1", raw=json.dumps(bad))
        assert cache.count() == 0
        assert cache.stats.stored == 0


def test_failures_are_logged_and_never_served(tmp_path):
    with ResponseCache(tmp_path / "c.sqlite") as cache:
        cache.put_failure("k1", persona_id="p1", variant="deadline", model="m",
                          error="response is not valid JSON", raw="{oops")
        cache.put_failure("k2", persona_id="p2", variant="baseline", model="m",
                          error="transport: HTTP 500 after 5 retries", raw=None)
        assert cache.get("k1") is None
        assert cache.count() == 0
        rows = cache.failures()
        assert [r["persona_id"] for r in rows] == ["p1", "p2"]
        assert rows[0]["raw"] == "{oops"
        assert rows[0]["variant"] == "deadline"
        assert [r["request_hash"] for r in cache.failures("p2")] == ["k2"]
        assert cache.stats.failures == 2


def test_stored_row_that_no_longer_validates_is_a_reported_miss(tmp_path, caplog):
    path = tmp_path / "c.sqlite"
    with ResponseCache(path) as cache:
        _put(cache, "k1")
    db = sqlite3.connect(path)
    db.execute("UPDATE responses SET raw = ? WHERE request_hash = 'k1'", ('{"actions": {}}',))
    db.commit()
    db.close()
    with caplog.at_level(logging.WARNING), ResponseCache(path) as cache:
        assert cache.get("k1") is None
        assert (cache.stats.invalid, cache.stats.misses, cache.stats.hits) == (1, 1, 0)
    assert "no longer validates" in caplog.text


def test_concurrent_threads_share_one_cache(tmp_path):
    errors: list[BaseException] = []
    with ResponseCache(tmp_path / "c.sqlite") as cache:

        def work(t: int) -> None:
            try:
                for i in range(25):
                    key = f"t{t}-{i}"
                    _put(cache, key, persona=f"p{t}")
                    assert cache.get(key) is not None
                    cache.put_failure(key, persona_id=f"p{t}", variant="baseline", model="m",
                                      error="x", raw=None)
            except BaseException as exc:  # surfaced below: threads swallow exceptions
                errors.append(exc)

        threads = [threading.Thread(target=work, args=(t,)) for t in range(8)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        assert errors == []
        assert cache.count() == 200
        assert len(cache.failures()) == 200
        assert cache.stats.hits == 200


@pytest.mark.parametrize("version", [1, 2])
def test_an_older_cache_file_is_migrated_and_still_answers(tmp_path, version):
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    served = ", served_model TEXT" if version == 2 else ""
    db.executescript(f"""
        CREATE TABLE responses (request_hash TEXT PRIMARY KEY, persona_id TEXT, variant TEXT,
            model TEXT, raw TEXT, attempts INTEGER, prompt_tokens INTEGER,
            completion_tokens INTEGER, total_tokens INTEGER, created REAL{served});
        CREATE TABLE identities (endpoint TEXT, model TEXT, identity TEXT, seen REAL,
            PRIMARY KEY (endpoint, model));
        PRAGMA user_version={version};""")
    db.execute("INSERT INTO responses VALUES (?, 'p1', 'baseline', 'm', ?, 1, 10, 5, 15, 0"
               + (", NULL)" if version == 2 else ")"), ("k", valid_text()))
    db.execute("INSERT INTO identities VALUES ('e', 'm', 'abc', 0)")
    db.commit()
    db.close()
    with ResponseCache(path) as cache:
        hit = cache.get("k")
        assert hit is not None and hit.fingerprint is None and hit.served_model is None
        known = cache.identity("e", "m")
        assert known is not None and (known.key, known.details) == ("abc", {})
        cache.put("k2", persona_id="p1", variant="baseline", model="m", raw=valid_text(),
                  attempts=1, tokens=TOKENS, fingerprint="fp_1")
        assert cache.get("k2").fingerprint == "fp_1"
    assert sqlite3.connect(path).execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 4
