"""A study part as data: which episodes, populations (or a null design standing in for
them), controllers, backends, profile sets and seeds it runs, and its role: what the
analysis does with it (:data:`PART_ROLES`). A study (:mod:`.study`) is named parts.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field, field_validator, model_serializer, model_validator

from ..controller_ids import controller_id
from ..errors import ConfigError, UnknownNameError
from ..paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from ..populations.build import POPULATIONS, SPLIT_HALVES, is_known, known
from ..populations.identity import NULL_KINDS, PopulationSpec, null_populations
from ..populations.perturb import ProfileSet
from ..strict import Names, Number, Seed, Strict, Unique

SCENES = ("sidewalk", "head_on", "crossing", "bottleneck", "obstruction")


class EpisodeSelection(Strict):
    """Which episodes of the 104-cell grid a part runs (``None`` = all values)."""

    scenes: Annotated[tuple[str, ...] | None, Unique] = None
    widths: Annotated[tuple[Number, ...] | None, Unique] = None
    densities: Annotated[tuple[Number, ...] | None, Unique] = None
    robot_speeds: Annotated[tuple[Number, ...] | None, Unique] = None
    variants: Annotated[tuple[Annotated[int, Field(strict=True)], ...] | None, Unique] = None
    #: explicit episode ids (wins over the filters)
    ids: Annotated[tuple[str, ...] | None, Unique] = None

    @field_validator("scenes")
    @classmethod
    def _known_scenes(cls, v):
        for s in v or ():
            if s not in SCENES:
                raise ValueError(str(UnknownNameError("scene", s, SCENES)))
        return v


class NullDesign(Strict):
    """A null design in place of a part's populations: a kind of
    :data:`popnavshift.populations.identity.NULL_KINDS` (``swap`` permutations of the
    matched pair, ``sized`` random subsets of mixed matched in size to each of the part's
    populations, …) and its number of replicates."""

    kind: str
    replicates: Annotated[int, Field(strict=True, ge=1, le=999)] = 19

    @field_validator("kind")
    @classmethod
    def _declared_kind(cls, v: str) -> str:
        if v not in NULL_KINDS:
            raise ValueError(str(UnknownNameError("null design kind", v, NULL_KINDS)))
        return v


#: What the analysis does with a study part, by role, with its title in the report:
#: ``main`` is the paper's design (Table I, the headline), ``mapping``, ``structure``,
#: ``backend`` and ``respondent`` each give one robustness section
#: (:data:`popnavshift.analysis.study_robustness.ROLE_TABLES`), ``other`` nothing of its
#: own (null replicates, split halves and extra seed sets are found by their populations
#: and episodes wherever they run).
PART_ROLES: dict[str, str] = {
    "main": "The paper's design (Table I and the headline)",
    "mapping": "Mapping sensitivity (paper Table III)",
    "structure": "Profile structure (paper §V-D)",
    "backend": "Pedestrian dynamics: Ped-ORCA vs navground HL (paper §V-E)",
    "respondent": "Respondent robustness: the matched intervention again",
    "other": "Other parts",
}


def role_from_content(part: Part) -> str:
    """The role of a part that declares none and is not named after one: a null design
    or a single profile set and backend is ``other``; two backends, ``backend``; a second
    respondent's set, ``respondent``; a perturbed set, ``structure``; two mappings,
    ``mapping``."""
    if part.null_design is not None:
        return "other"
    sets = [ProfileSet.parse(m) for m in part.mappings]
    if len(part.backends) > 1:
        return "backend"
    if any(s.perturbation == "second_respondent" for s in sets):
        return "respondent"
    if any(s.perturbation != "none" for s in sets):
        return "structure"
    return "mapping" if len(sets) > 1 else "other"


class Part(Strict):
    populations: Names = PAPER_POPULATIONS
    episodes: EpisodeSelection = EpisodeSelection()
    #: controller ids: a registered name, an entry point or ``package.module:Class``;
    #: in YAML also ``{name: HRVO, params: {...}}``, stored as ``HRVO{"...":...}``
    controllers: Names = PAPER_CONTROLLERS
    backends: Names = ("orca",)
    #: profile set(s): a mapping A–D, or a robustness label such as A~shuffle
    mapping: str | Names = "A"
    #: also run every episode × population without a robot
    baseline: Annotated[bool, Field(strict=True)] = True
    #: extra study seeds: the part's episodes are repeated, drawn with each seed
    #: (ids ``<episode>@s<seed>``), so the report can show the spread across seed sets
    seeds: Annotated[tuple[Seed, ...], Unique] = ()
    #: run a null design instead of ``populations`` (which it stands in for): the
    #: populations run are :attr:`planned_populations`
    null_design: NullDesign | None = None
    #: what the analysis does with it (:data:`PART_ROLES`); default: its name when that is
    #: a role, else its content (:func:`role_from_content`) — :meth:`Study.role`
    role: str | None = None

    @model_serializer(mode="wrap")
    def _without_unset_role(self, handler: Any) -> dict[str, Any]:
        """An undeclared role stays out of the stored configuration, so a study's hash
        (and every stamp after it) is the same as before parts had roles."""
        data = handler(self)
        if self.role is None:
            data.pop("role", None)
        return data

    @property
    def mappings(self) -> tuple[str, ...]:
        return (self.mapping,) if isinstance(self.mapping, str) else tuple(self.mapping)

    @property
    def planned_specs(self) -> tuple[PopulationSpec, ...]:
        """The populations this part runs, as identities: its own (conditions or split
        halves, :data:`popnavshift.populations.build.KNOWN`), or its null design's."""
        if self.null_design is None:
            return tuple(known(p) for p in self.populations)
        return null_populations(self.null_design.kind, self.null_design.replicates,
                                self.populations)

    @property
    def planned_populations(self) -> tuple[str, ...]:
        """The names of :attr:`planned_specs`."""
        return tuple(spec.name for spec in self.planned_specs)

    @field_validator("controllers", mode="before")
    @classmethod
    def _controller_ids(cls, v):
        """``{name, params}`` entries → controller ids
        (:func:`popnavshift.sim.controllers.registry.controller_id`), so parameters
        enter the run key and two parameterisations never share a run."""
        if not isinstance(v, list | tuple):
            return v
        return tuple(_controller_entry(c) for c in v)

    @field_validator("role")
    @classmethod
    def _declared_role(cls, v: str | None) -> str | None:
        if v is not None and v not in PART_ROLES:
            raise ValueError(str(UnknownNameError("part role", v, PART_ROLES)))
        return v

    @field_validator("populations")
    @classmethod
    def _known_populations(cls, v):
        for p in v:
            if not is_known(p):
                # a ValueError: pydantic adds where it was (parts.main.populations.0)
                raise ValueError(str(UnknownNameError("population", p,
                                                      POPULATIONS + SPLIT_HALVES))
                                 + " (null replicates are not listed: a part declares "
                                 "them as null_design: {kind, replicates})")
        return v

    @model_validator(mode="after")
    def _runs_something(self) -> Part:
        """A null design planning no population (its kind's ``replicate`` says why when it
        cannot stand in for the part's populations) would plan no run at all."""
        if self.null_design is not None and not self.planned_populations:
            raise ValueError(f"a {self.null_design.kind} null stands in for none of "
                             f"{list(self.populations)}")
        return self

    @model_validator(mode="before")
    @classmethod
    def _null_stands_for_its_own(cls, data: Any) -> Any:
        """A null kind that always stands in for the same populations (a swap null: the
        matched pair) has them as its part's default, and any others are an error."""
        design = data.get("null_design") if isinstance(data, dict) else None
        name = design.get("kind") if isinstance(design, dict) else None
        kind = NULL_KINDS.get(name) if isinstance(name, str) else None
        if kind is None or not kind.stands_for:
            return data
        own = kind.stands_for
        pops = data.get("populations", own)
        if not isinstance(pops, list | tuple) or sorted(map(str, pops)) != sorted(own):
            raise ValueError(f"a {name} null stands in for {' and '.join(own)}: "
                             f"populations {list(own)} (the default), got {pops!r}")
        return {**data, "populations": tuple(own)}


def _controller_entry(entry: Any) -> Any:
    if not isinstance(entry, dict):
        return entry
    params = entry.get("params", {})
    if (
        set(entry) - {"name", "params"}
        or not isinstance(entry.get("name"), str)
        or not (isinstance(params, dict))
    ):
        raise ValueError(
            f"a controller is NAME or {{name: NAME, params: {{KEY: VALUE}}}}, got {entry!r}"
        )
    try:
        return controller_id(entry["name"], params)
    except ConfigError as err:
        raise ValueError(str(err)) from None
