"""Which model a server serves: an identity for the cache key.

A model name is not an identity: a llama.cpp server restarted on the same port with
another ``-m`` (or behind the same ``--alias``) answers to the same name. The
OpenAI-compatible respondent asks ``GET /models`` (and llama.cpp's ``/props``) before the
cache is read and takes :func:`model_identity`: what defines the model, none of the
server's configuration (slots, context); :func:`combine` adds the behavioural fingerprint
of :mod:`.canaries`; :func:`served_identity` keeps the last identity per endpoint and
model in the cache, so that a run that cannot ask (no key, server down or loading)
replays what it last saw, and says in one line why a changed one is another model
(docs/llm.md, "The served model's identity").

Besides its key, an :class:`Identity` carries what the server says of the model for the
responses table and the manifest (:func:`listing_details`, :func:`props_details`):
llama.cpp's file size, parameter count and quantisation, the model file's *name* (never
its path: a machine's folders do not belong in a table), the server's build and the
fingerprint.
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


#: what a llama.cpp listing entry's ``meta`` says of the model itself. Left out: ``n_ctx``
#: (the context of one slot: ``-c`` / ``-np``, the server's configuration, not the model)
MODEL_META: tuple[str, ...] = ("vocab_type", "n_vocab", "n_ctx_train", "n_embd", "n_params",
                               "size", "ftype")
#: the fields that name a model in a listing entry (OpenAI, vLLM, Ollama, llama.cpp).
#: Left out: ``created`` (llama.cpp puts the time of the request there), vLLM's
#: ``permission`` (a new random id on every call) and ``max_model_len`` (configuration)
ENTRY_FIELDS: tuple[str, ...] = ("id", "owned_by", "root", "parent")
#: the fields of :func:`props_details` that define the model (the key's share of it)
DEFINING_DETAILS: tuple[str, ...] = ("model_file", "model_quant", "server_build")


def listing_details(entry: dict[str, Any]) -> dict[str, Any]:
    """Size (bytes), parameter count and quantisation (``ftype``) from a llama.cpp listing
    entry's ``meta``."""
    meta = entry.get("meta")
    if not isinstance(meta, dict):
        return {}
    out = {"model_size": meta.get("size"), "model_params": meta.get("n_params")}
    found: dict[str, Any] = {k: float(v) for k, v in out.items()
                             if isinstance(v, int | float) and not isinstance(v, bool)}
    if isinstance(meta.get("ftype"), str) and meta["ftype"].strip():
        found["model_quant"] = meta["ftype"].strip()
    return found


def props_details(props: Any) -> dict[str, Any]:
    """The model file's name (``model_path`` without its folders), its quantisation
    (``model_ftype``, else the file name's tag) and the build (``build_info``) from
    llama.cpp's ``GET /props``."""
    if not isinstance(props, dict):
        return {}
    out: dict[str, Any] = {}
    path = props.get("model_path")
    if isinstance(path, str) and path.strip():
        out["model_file"] = file_name(path)
        quant = quant_tag(out["model_file"])
        if quant is not None:
            out["model_quant"] = quant
    if isinstance(props.get("model_ftype"), str) and props["model_ftype"].strip():
        out["model_quant"] = props["model_ftype"].strip()
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


#: a machine path: absolute POSIX, home-relative, Windows drive or UNC
_PATH = re.compile(r"^(/|~|[A-Za-z]:[\\/]|\\\\)")


def portable(name: str | None) -> str | None:
    """``name`` as a record may hold it: a machine path (a llama.cpp server started without
    ``--alias`` names its model by the file's path) becomes the file's name; a model id
    such as ``Qwen/Qwen2.5-7B-Instruct`` is kept."""
    if isinstance(name, str) and (_PATH.match(name) or name.lower().endswith(".gguf")):
        return file_name(name)
    return name


def model_identity(entry: dict[str, Any], details: dict[str, Any]) -> str:
    """sha256 hex of what defines the served model: the listing entry's naming fields
    (:data:`ENTRY_FIELDS`, a path reduced to its file name), llama.cpp's model
    ``meta`` (:data:`MODEL_META`) and, from ``/props``, the file name, quantisation and
    server build (:data:`DEFINING_DETAILS`). Nothing of the server's configuration (slots,
    context, the time of the request) enters it, so a restart with other ``-c`` or
    ``-np`` keeps it and a file renamed or moved to another folder does too."""
    named = {k: portable(entry[k]) if isinstance(entry[k], str) else entry[k]
             for k in ENTRY_FIELDS if k in entry}
    meta: dict[str, Any] = entry["meta"] if isinstance(entry.get("meta"), dict) else {}
    return digest({"entry": named, "meta": {k: meta[k] for k in MODEL_META if k in meta},
                   "details": {k: details[k] for k in DEFINING_DETAILS if k in details}})


def listing_identity(listing: Any, model: str) -> str | None:
    """:func:`model_identity` of the listing's entry served as ``model`` (without
    ``/props``); None when the listing names none."""
    entry = listing_entry(listing, model)
    return model_identity(entry, {}) if entry else None


def combine(listed: Identity | None, behaviour: str | None) -> Identity | None:
    """One identity of the listed model and its behavioural fingerprint
    (:mod:`.canaries`), either possibly missing; None when both are."""
    if listed is None and behaviour is None:
        return None
    details = dict(listed.details) if listed is not None else {}
    if behaviour is not None:
        details["model_canaries"] = behaviour
    return Identity(digest({"listed": listed.key if listed else None, "behaviour": behaviour}),
                    details)


def why_changed(before: dict[str, Any], now: dict[str, Any]) -> str:
    """What tells the model the server serves now from the one before, in words."""
    changed = [k for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k)]
    if changed == ["model_canaries"]:
        return ("its name, file, size, parameters and build are the same, but it answers "
                "the canary prompts differently: another model (its weights changed)")
    shown = [f"{k} {before.get(k)!s} → {now.get(k)!s}" for k in changed
             if k != "model_canaries"]
    return "it serves another model (" + ("; ".join(shown) or "its listing changed") + ")"


def served_identity(ask: Callable[[], Identity | None], cache: ResponseCache | None,
                    endpoint: str, model: str, name: str) -> Identity | None:
    """The identity ``ask()`` gets from the server (None: the server names none),
    remembered in ``cache``; the remembered one when ``ask`` cannot reach it
    (MissingKeyError, a NotReady that is not final). When it differs from the one
    remembered, one line says why, and that only this model's answers are taken from the
    cache (a new model is asked again; one seen before gets its own). A rejected key
    (a final NotReady) raises TransportError: an authentication problem, naming the URL."""
    known = cache.identity(endpoint, model) if cache is not None else None
    try:
        found = ask()
    except MissingKeyError:
        return known
    except NotReady as exc:
        if exc.fatal:
            raise TransportError(f"{name}: authentication failed: {exc.reason}",
                                 hint="check the API key in the environment variable "
                                 "api_key_env names (--api-key-env)") from None
        log.info("%s: cannot ask %s which model it serves (%s)", name, endpoint, exc.reason)
        return known
    if found is not None and cache is not None:
        if known is not None and known.key != found.key:
            # true of a model new to the cache and of one seen before coming back
            log.warning("%s %s at %s: %s; only answers this model gave are taken from the "
                        "cache (a model new to it is asked every record again), the former's "
                        "come back when it does", name, model, endpoint,
                        why_changed(known.details, found.details))
        cache.remember_identity(endpoint, model, found.key, found.details)
    return found
