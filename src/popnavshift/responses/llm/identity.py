"""Which model a server serves: an identity for the cache key.

A model name is not an identity: a llama.cpp server restarted on the same port with
another ``-m`` (or behind the same ``--alias``) answers to the same name. The
OpenAI-compatible respondent asks ``GET /models`` before the cache is read and takes
:func:`listing_identity` of the listing; :func:`served_identity` keeps the last one per
endpoint and model in the cache, so that a run that cannot ask (no key, server down or
loading) replays what it last saw (docs/llm.md, "The served model's identity").
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from ...errors import MissingKeyError, TransportError
from ...hashing import digest
from .cache import ResponseCache
from .readiness import NotReady

log = logging.getLogger("popnavshift.responses.llm")


def listing_identity(listing: Any, model: str) -> str | None:
    """A fingerprint (sha256 hex) of the model a ``GET /models`` listing says is served as
    ``model``: its entry (the one whose id is ``model``, else the only one: llama.cpp
    serves one model under its file name or alias) without ``created`` (llama.cpp puts
    the time of the request there). llama.cpp's entry carries the file's size and
    parameter count, so another file behind the same alias is another identity. None
    when the listing names neither."""
    data = listing.get("data") if isinstance(listing, dict) else None
    entries = [e for e in data if isinstance(e, dict)] if isinstance(data, list) else []
    match = [e for e in entries if e.get("id") == model] or (entries if len(entries) == 1
                                                             else [])
    return digest({k: v for k, v in match[0].items() if k != "created"}) if match else None


def served_identity(ask: Callable[[], str | None], cache: ResponseCache | None,
                    endpoint: str, model: str, name: str) -> str | None:
    """The identity ``ask()`` gets from the server (None: the server names none),
    remembered in ``cache``; the remembered one when ``ask`` cannot reach it
    (MissingKeyError, a NotReady that is not final). A rejected key (a final NotReady)
    raises TransportError naming ``name`` and ``endpoint``."""
    known = cache.identity(endpoint, model) if cache is not None else None
    try:
        found = ask()
    except MissingKeyError:
        return known
    except NotReady as exc:
        if exc.fatal:
            raise TransportError(f"{name} server {endpoint}: {exc.reason}",
                                 hint="check the API key") from None
        log.info("%s: cannot ask %s which model it serves (%s)", name, endpoint, exc.reason)
        return known
    if found is not None and cache is not None:
        if known not in (None, found):
            log.warning("%s %s at %s: the server now serves another model; answers cached "
                        "from the former are not used", name, model, endpoint)
        cache.remember_identity(endpoint, model, found)
    return found
