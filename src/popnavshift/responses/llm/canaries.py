"""A behavioural fingerprint of the served model: its answers to fixed canary prompts.

What a server says of its model (name, file name, size, parameter count, quantisation,
build: :mod:`.identity`) does not change when only the weights do: a fine-tuned or
otherwise edited GGUF file copied over the old one, with the same name, size and
metadata, is served under the same listing. Its answers differ, though. Before the cache
is read, the respondent asks :data:`CANARY_PROMPTS` at reproducible settings (temperature
0, seed 0, :data:`CANARY_TOKENS` tokens, one at a time) and keeps the sha256 of the
answers with the cache (``fingerprints``, per endpoint, model and listed identity). The
fingerprint enters the cache key, so a model that answers them differently is asked
again, and :func:`behaviour` decides what a new answer means:

* the same as one seen before for this listed model: that model (its answers come back);
* new, and the same when asked a second time: another model behind the same name (its
  records are asked again; :func:`.identity.served_identity` says why in one line);
* new, and different again: the server does not answer the canaries reproducibly (a
  hosted API at temperature 0, llama.cpp batching several slots): a swap cannot be seen
  this way, the fingerprint last seen is kept (nothing is asked again) and one line says so.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from ...hashing import digest
from .cache import ResponseCache

log = logging.getLogger("popnavshift.responses.llm")

#: short prompts whose continuations differ between models: counting, a sentence, a
#: translation. Fixed: changing one changes every fingerprint (every record asked again)
CANARY_PROMPTS: tuple[str, ...] = (
    "Continue this list with the next five numbers: 2, 3, 5, 7, 11,",
    "In one sentence, describe a pedestrian waiting at a crosswalk.",
    "Translate into French: The robot stops to let the child pass.",
)
#: most tokens of one canary answer: enough to tell models apart, cheap on any server
CANARY_TOKENS = 24

Ask = Callable[[], tuple[str, ...] | None]


def fingerprint(answers: tuple[str, ...]) -> str:
    """sha256 hex of the canary answers, in the order of :data:`CANARY_PROMPTS`."""
    return digest(list(answers))


def behaviour(ask: Ask, cache: ResponseCache | None, endpoint: str, model: str,
              listed: str | None, where: str) -> str | None:
    """The fingerprint that identifies the served model's behaviour (module docstring), or
    None when it cannot be taken (the canaries failed and none was seen before). ``ask()``
    asks every canary once and returns the answers (None when a call failed); ``listed``
    is the identity the server's listing gave ("" keyed when none)."""
    known = cache.fingerprints(endpoint, model, listed or "") if cache is not None else []
    first = ask()
    if first is None:
        return known[0] if known else None
    found = fingerprint(first)
    if not known or found in known:
        _remember(cache, endpoint, model, listed, found, first)
        return found
    second = ask()  # new: a new model, or a server that does not answer alike twice?
    again = fingerprint(second) if second is not None else None
    if again in known:
        _remember(cache, endpoint, model, listed, again, second)
        return again
    if again == found:
        _remember(cache, endpoint, model, listed, found, first)
        return found
    log.warning("%s: the server answered the canary prompts differently twice in a row (not "
                "reproducible at temperature 0): a model swapped behind the same name and "
                "file cannot be detected this way; the cached answers are used (set "
                "model_sha256 to name the model file, docs/llm.md)", where)
    return known[0]


def _remember(cache: ResponseCache | None, endpoint: str, model: str, listed: str | None,
              found: str, answers: tuple[str, ...] | None) -> None:
    if cache is not None and answers is not None:
        cache.remember_fingerprint(endpoint, model, listed or "", found, answers)
