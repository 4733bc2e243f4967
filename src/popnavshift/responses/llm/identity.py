"""Which model a server serves: an identity for the cache key.

A model name is not an identity: a llama.cpp server restarted on the same port with
another ``-m`` (or behind the same ``--alias``) answers to the same name. The
OpenAI-compatible respondent asks ``GET /models`` before the cache is read and takes
:func:`listing_identity` of the listing; :func:`served_identity` keeps the last one per
endpoint and model in the cache, so that a run that cannot ask (no key, server down or
loading) replays what it last saw (docs/llm.md, "The served model's identity").

Besides the fingerprint, an :class:`Identity` carries what the server says of the model
for the responses table and the manifest (:func:`listing_details`, :func:`props_details`):
llama.cpp's file size and parameter count, the model file's *name* (never its path: a
machine's folders do not belong in a table) and the server's build.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from typing import Any

from ...errors import MissingKeyError, TransportError
from ...hashing import digest
from .cache import Identity, ResponseCache
from .readiness import NotReady

log = logging.getLogger("popnavshift.responses.llm")


def listing_entry(listing: Any, model: str) -> dict[str, Any] | None:
    """The entry of a ``GET /models`` listing served as ``model``: the one whose id is
    ``model``, else the only one (llama.cpp serves one model under its file name or
    alias); None when the listing names neither."""
    data = listing.get("data") if isinstance(listing, dict) else None
    entries = [e for e in data if isinstance(e, dict)] if isinstance(data, list) else []
    match = [e for e in entries if e.get("id") == model] or (entries if len(entries) == 1
                                                             else [])
    return match[0] if match else None


def listing_details(entry: dict[str, Any]) -> dict[str, Any]:
    """Size (bytes) and parameter count from a llama.cpp listing entry's ``meta``."""
    meta = entry.get("meta")
    if not isinstance(meta, dict):
        return {}
    out = {"model_size": meta.get("size"), "model_params": meta.get("n_params")}
    return {k: float(v) for k, v in out.items() if isinstance(v, int | float)
            and not isinstance(v, bool)}


def props_details(props: Any) -> dict[str, Any]:
    """The model file's name (``model_path`` without its folders) and the build
    (``build_info``) from llama.cpp's ``GET /props``."""
    if not isinstance(props, dict):
        return {}
    out: dict[str, Any] = {}
    path = props.get("model_path")
    if isinstance(path, str) and path.strip():
        out["model_file"] = file_name(path)
        quant = quant_tag(out["model_file"])
        if quant is not None:
            out["model_quant"] = quant
    if isinstance(props.get("build_info"), str):
        out["server_build"] = props["build_info"]
    return out


#: a GGUF file name's quantisation tag (llama.cpp's naming: Q4_K_M, IQ3_XXS, Q8_0, F16, …)
_QUANT = re.compile(r"(?i)(?<![A-Za-z0-9])(I?Q\d(?:_[A-Z0-9]+)*|BF16|F16|F32)(?![A-Za-z0-9])")


def quant_tag(name: str) -> str | None:
    """The quantisation tag of a GGUF file name, upper-cased (the last one when several);
    None without one. llama.cpp reports no quantisation, so the file name is the record."""
    found = _QUANT.findall(name.removesuffix(".gguf"))
    return found[-1].upper() if found else None


def file_name(path: str) -> str:
    """The last component of a POSIX or Windows path: a table never holds a machine path."""
    return re.split(r"[\\/]", path.rstrip("/\\"))[-1]



def listing_identity(listing: Any, model: str) -> str | None:
    """A fingerprint (sha256 hex) of the model a ``GET /models`` listing says is served as
    ``model``: its entry (the one whose id is ``model``, else the only one: llama.cpp
    serves one model under its file name or alias) without ``created`` (llama.cpp puts
    the time of the request there). llama.cpp's entry carries the file's size and
    parameter count, so another file behind the same alias is another identity. None
    when the listing names neither."""
    entry = listing_entry(listing, model)
    return entry_identity(entry) if entry else None


def entry_identity(entry: dict[str, Any]) -> str:
    """sha256 hex of a listing entry without ``created`` (llama.cpp puts the time of the
    request there)."""
    return digest({k: v for k, v in entry.items() if k != "created"})


def served_identity(ask: Callable[[], Identity | None], cache: ResponseCache | None,
                    endpoint: str, model: str, name: str) -> tuple[str | None, dict[str, Any]]:
    """(key, details) of the identity ``ask()`` gets from the server ((None, {}): the
    server names none), remembered in ``cache``; the remembered one when ``ask`` cannot
    reach it (MissingKeyError, a NotReady that is not final). A rejected key (a final
    NotReady) raises TransportError: an authentication problem, naming the URL asked."""
    known = cache.identity(endpoint, model) if cache is not None else None
    try:
        found = ask()
    except MissingKeyError:
        return (known.key, known.details) if known else (None, {})
    except NotReady as exc:
        if exc.fatal:
            raise TransportError(f"{name}: authentication failed: {exc.reason}",
                                 hint="check the API key in the environment variable "
                                 "api_key_env names (--api-key-env)") from None
        log.info("%s: cannot ask %s which model it serves (%s)", name, endpoint, exc.reason)
        return (known.key, known.details) if known else (None, {})
    if found is not None and cache is not None:
        if known is not None and known.key != found.key:
            log.warning("%s %s at %s: the server now serves another model; answers cached "
                        "from the former are not used", name, model, endpoint)
        cache.remember_identity(endpoint, model, found.key, found.details)
    return (found.key, found.details) if found else (None, {})
