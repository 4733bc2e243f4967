"""Check a study against what exists before anything runs.

``popnavshift plan`` and ``popnavshift run`` call :func:`validate_study` first, so a
typo fails in seconds, before the persona and probe stages (which, with an LLM
respondent, cost money), instead of after them or, worse, silently:

* a width, density, robot speed or variant that is not in the built-in grid would
  match no episode and quietly shrink the study; it is rejected with the values
  that exist and a did-you-mean (the grid is fixed by the paper's design, so a new
  value is a new scene design, not a study setting);
* a part whose filters together match no episode is one clear error;
* controllers, backends, mappings and the respondent (with its options) are
  resolved by name now, not when their stage is reached.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

from ..design.part import EpisodeSelection
from ..design.plan import select_episodes
from ..design.specs import RespondentSpec
from ..design.study import Study
from ..errors import ConfigError, UnknownNameError
from ..populations.perturb import STRUCTURE, ProfileSet
from ..profiles.mappings import MAPPINGS
from ..responses.respondent import RESPONDENTS
from ..sim.backends import BACKENDS
from ..sim.controllers import CONTROLLERS

#: selection field → (episode attribute, the word used in messages)
GRID_FIELDS = {
    "widths": ("width", "width"),
    "densities": ("density", "density"),
    "robot_speeds": ("robot_speed", "robot speed"),
    "variants": ("variant", "variant"),
}


def validate_study(study: Study, episodes: Iterable, report: bool = False) -> None:
    """Raise ConfigError for the first value of ``study`` that cannot run (with
    ``report``: or whose report cannot be written); its message starts with the study's
    file (or name)."""
    try:
        _validate(study, episodes)
        if report:
            _check_reportable(study)
    except ConfigError as err:
        if err.message.startswith(study.where):
            raise
        raise ConfigError(f"{study.where}: {err.message}", hint=err.hint) from None


def _validate(study: Study, episodes: Iterable) -> None:
    if not study.parts:
        raise ConfigError(f"{study.where}: parts: no part, so nothing would run",
                          hint="add a part, e.g. `parts: {main: {populations: [mixed]}}`")
    eps = list(episodes)
    for name, part in study.parts.items():
        where = f"{study.where}: parts.{name}"
        check_grid_values(part.episodes, eps, where)
        if not select_episodes(part.episodes, eps):
            raise ConfigError(f"{where}: its episode filters together match no episode",
                              hint="`popnavshift episodes` lists the grid")
    _check_names(study)


def check_grid_values(selection: EpisodeSelection, episodes: Sequence, where: str) -> None:
    """Every filter value must exist among the episodes of the selected scenes."""
    scenes = selection.scenes
    pool = [e for e in episodes if scenes is None or e.scene in scenes]
    for field, (attr, word) in GRID_FIELDS.items():
        wanted = getattr(selection, field)
        known = sorted({getattr(e, attr) for e in pool})
        for value in (wanted or ()) if known else ():  # no scene: the caller says so
            if not any(abs(float(value) - float(k)) < 1e-9 for k in known):
                closest = min(known, key=lambda k: abs(float(k) - float(value)))
                of = f" of {', '.join(scenes)}" if scenes else ""
                raise ConfigError(
                    f"{where}: {word} {value!r} is not in the grid{of}; known: "
                    f"{', '.join(repr(k) for k in known)}",
                    hint=f"did you mean {closest!r}?",
                )


def _check_reportable(study: Study) -> None:
    """The report ranks controllers on every seed set of a part: a part with extra
    seeds and one controller would run, then fail in the report."""
    for name, part in study.parts.items():
        if part.seeds and len(part.controllers) < 2:
            raise ConfigError(
                f"parts.{name}.seeds: the report ranks controllers on each seed set, which "
                f"needs at least 2 controllers; got {list(part.controllers)}",
                hint="add a controller, or run with --no-report")


def _check_names(study: Study) -> None:

    controllers = {c for part in study.parts.values() for c in part.controllers}
    for controller in sorted(controllers):
        CONTROLLERS.make(controller)
    for backend in sorted({b for part in study.parts.values() for b in part.backends}):
        BACKENDS.make(backend)
    known = known_mappings(study)
    for name, part in study.parts.items():
        for mapping in part.mappings:
            if mapping not in known:
                raise UnknownNameError(f"mapping (part {name})", mapping, known)
    _check_respondent(study.respondent, f"{study.where}: respondent")
    if study.respondent2 is not None:
        _check_respondent(study.respondent2, f"{study.where}: respondent2")


def profile_mappings(study: Study) -> tuple[str, ...]:
    """The mappings whose profiles the study's population stage builds: A, the study's
    ``mappings`` (default A–D), then any other registered mapping a part names."""
    named = [m for part in study.parts.values() for m in part.mappings if m in MAPPINGS]
    return tuple(dict.fromkeys(("A", *study.mappings, *named)))


def known_mappings(study: Study) -> list[str]:
    """Profile-set labels the study's population stage can build."""
    for mapping in study.mappings:
        if mapping not in MAPPINGS:
            raise UnknownNameError("mapping (study mappings)", mapping, MAPPINGS.names())
    sets = [ProfileSet(m) for m in profile_mappings(study)]
    sets += [ProfileSet("A", kind, arg) for kind, s in STRUCTURE.items() for arg in s.args]
    if study.respondent2 is not None:
        sets.append(ProfileSet("A", "second_respondent", study.respondent2.name))
    return sorted({s.label for s in sets})


def _check_respondent(spec: RespondentSpec, where: str) -> None:
    """Build the respondent (no call is made) and check its settings, here rather than when
    the probe stage starts: ``run --samples`` sets the samples after the file was read."""
    _check_finite(spec.options, f"{where}.options")
    respondent = RESPONDENTS.make(spec.name, **spec.options)
    if spec.samples > 1 and getattr(respondent, "seed", 0) is None:
        raise ConfigError(f"{where}: samples {spec.samples} need a seed (options.seed is "
                          "null, so every sample would be one request asked again)")
    validate = getattr(respondent, "validate", None)
    if callable(validate):
        validate()


def _check_finite(value: Any, where: str) -> None:
    """No NaN or infinity among option values (YAML's ``.nan`` passes every range check
    a respondent makes, then fails deep in a request)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(item, f"{where}.{key}")
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            _check_finite(item, f"{where}[{i}]")
    elif isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{where}: {value!r} is not a finite number")
