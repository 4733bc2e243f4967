"""The respondent contract and registry (:data:`RESPONDENTS`).

A respondent answers the probe battery for many personas at once
(``answer_all``) so that network respondents can run requests concurrently.
It never raises for one bad record: a record that stays invalid comes back as an
:class:`Answer` with ``error`` set, and the caller lists it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ..hashing import stable_seed
from ..registry import Registry


@dataclass(frozen=True)
class ProbeRequest:
    """One persona to ask; ``persona`` already carries the variant's field values."""

    persona_id: str
    variant: str  # "baseline" | "deadline"
    persona: Mapping[str, Any]
    #: independent sample index, from 0: a network respondent sends sample s with its own
    #: seed (:func:`sample_seed`); a deterministic respondent answers every sample alike
    sample: int = 0


@dataclass
class Answer:
    """The outcome for one request. Exactly one of ``answer``/``error`` is set."""

    persona_id: str
    variant: str
    answer: dict[str, Any] | None = None
    error: str | None = None
    raw: str | None = None
    calls: int = 0  # network calls made (0 on a cache hit or for offline respondents)
    seconds: float = 0.0  # time those calls took, waits between retries excluded (s)
    attempts: int = 0  # content attempts (1 + re-asks)
    cached: bool = False
    tokens: dict[str, int] = field(default_factory=dict)  # summed over all attempts
    served_model: str | None = None  # the model the server says answered (None: not told)
    #: the server's build fingerprint for this reply (OpenAI ``system_fingerprint``)
    fingerprint: str | None = None


Progress = Callable[[int], None]


def sample_seed(seed: int, sample: int) -> int:
    """The seed sent for independent sample ``sample`` of a respondent seeded ``seed``:
    ``seed`` itself for sample 0 (a one-sample study asks what it always asked, and its
    cache still answers), else a stable hash of both below 2**31 (servers take a 32-bit
    seed; llama.cpp an unsigned one)."""
    return seed if sample == 0 else stable_seed("sample", seed, sample) % (1 << 31)


class Respondent(ABC):
    """Base class. Subclasses set ``name`` and implement ``answer_all``.

    ``uses_cache`` True declares a respondent that answers from a network model and
    takes a ``cache_path``: the population pipeline then gives it the study folder's
    response cache (``cache/llm.sqlite``) unless the options name another.
    """

    name: str = "respondent"
    uses_cache: ClassVar[bool] = False

    @property
    def model(self) -> str:
        """Model identifier recorded in tables and manifests."""
        return self.name

    def describe(self) -> dict[str, Any]:
        """Settings that determine the answers (for the manifest); never secrets."""
        return {"respondent": self.name, "model": self.model}

    @abstractmethod
    def answer_all(
        self, requests: Sequence[ProbeRequest], progress: Progress | None = None
    ) -> list[Answer]:
        """Answer every request, in order; call ``progress(n)`` as records finish."""


RESPONDENTS: Registry[Respondent] = Registry(
    "respondent", base=Respondent, hint="subclass popnavshift.responses.respondent.Respondent")
# The built-ins, by "module:Class": imported on first use, so an offline study never
# imports the network clients, and rule.py can import this module.
RESPONDENTS.register("rule", "popnavshift.responses.rule:RuleRespondent")
RESPONDENTS.register("openai", "popnavshift.responses.llm.openai:OpenAIRespondent")
RESPONDENTS.register("gemini", "popnavshift.responses.llm.gemini:GeminiRespondent")
