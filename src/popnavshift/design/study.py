"""Studies as data: a YAML file validated by typed models.

A study names its persona source, respondent, populations, scene grid,
controllers, backends, seeds and output folder, and is split into *parts*
(``main``, ``matched``, robustness subsets). Built-in studies (``paper``,
``quick``) live as YAML files in ``popnavshift/studies/``; a user study is any
YAML file of the same shape. Unknown keys are errors, so a typo never silently
falls back to a default.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_serializer,
    model_validator,
)

from ..controller_ids import controller_id
from ..errors import ConfigError, UnknownNameError
from ..hashing import digest
from ..paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from ..populations.build import POPULATIONS, SPLIT_HALVES, is_known, known
from ..populations.identity import MATCHED_PAIR, SIZED_SOURCE, PopulationSpec, index_of
from ..populations.nulls import null_populations
from ..populations.perturb import ProfileSet
from ..strict import Count, Names, Number, Seed, Strict, Unique
from .specs import PersonaSource, RespondentSpec
from .study_yaml import parse_study_yaml

SCENES = ("sidewalk", "head_on", "crossing", "bottleneck", "obstruction")
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
#: a name becomes a folder and a table value: long enough for any study, short enough
#: for any file system (255 bytes a component)
NAME_MAX = 100


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
    """A null design in place of a part's populations (:mod:`popnavshift.populations.nulls`):
    ``swap`` permutations of the matched pair, or ``sized`` random subsets of mixed
    matched in size to each of the part's populations (each kind's populations are
    declared in :data:`popnavshift.populations.identity.NULL_KINDS`)."""

    kind: Literal["swap", "sized"]
    replicates: Annotated[int, Field(strict=True, ge=1, le=999)] = 19


#: What the analysis does with a study part: ``main`` is the paper's design (Table I, the
#: headline), ``mapping``, ``structure``, ``backend`` and ``respondent`` each give one
#: robustness table, ``other`` nothing of its own (null replicates, split halves and extra
#: seed sets are found by their populations and episodes wherever they run).
PartRole = Literal["main", "mapping", "structure", "backend", "respondent", "other"]
PART_ROLES: tuple[str, ...] = PartRole.__args__  # type: ignore[attr-defined]


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
    #: what the analysis does with it (:data:`PartRole`); default: its name when that is a
    #: role, else its content (:func:`role_from_content`) — :meth:`Study.role`
    role: PartRole | None = None

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
        """A sized null of ``mixed`` alone has no population to stand in for: the part
        would plan no run at all."""
        if self.null_design is not None and not self.planned_populations:
            raise ValueError(f"a sized null stands in for populations other than "
                             f"{SIZED_SOURCE!r} (its own size-matched subset), got "
                             f"{list(self.populations)}")
        return self

    @model_validator(mode="before")
    @classmethod
    def _swap_stands_for_matched(cls, data: Any) -> Any:
        """A swap null stands in for the matched pair: that is its populations' default,
        and any other populations are an error."""
        if not (isinstance(data, dict) and isinstance(data.get("null_design"), dict)
                and data["null_design"].get("kind") == "swap"):
            return data
        pops = data.get("populations", MATCHED_PAIR)
        if not isinstance(pops, list | tuple) or sorted(map(str, pops)) != sorted(MATCHED_PAIR):
            raise ValueError(f"a swap null stands in for the matched pair: populations "
                             f"{list(MATCHED_PAIR)} (the default), got {pops!r}")
        return {**data, "populations": tuple(MATCHED_PAIR)}


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


class Study(Strict):
    name: str
    description: str = ""
    seed: Seed = 0
    personas: PersonaSource = PersonaSource()
    respondent: RespondentSpec = RespondentSpec()
    matched_n: Count = 202
    #: mappings whose profiles are built besides A and those the parts name
    #: (:func:`popnavshift.engine.validate.profile_mappings`)
    mappings: Annotated[tuple[str, ...], Unique] = ("A", "B", "C", "D")
    #: a second respondent for the respondent-robustness part (matched pair only)
    respondent2: RespondentSpec | None = None
    parts: dict[str, Part]
    output: str | None = None
    _where: str = PrivateAttr("")

    @property
    def where(self) -> str:
        """Where the study came from, for messages: its file, or ``study <name>``."""
        return self._where or f"study {self.name}"

    def role(self, name: str) -> str:
        """The analysis role of part ``name``: declared, else its name when that is a role
        (as in the built-in studies), else its content (:func:`role_from_content`, which
        never gives ``main``: the main part is declared or named, never found by position)."""
        part = self.parts[name]
        if part.role is not None:
            return part.role
        if name in PART_ROLES:
            return name
        return role_from_content(part)

    def part_with(self, role: str) -> tuple[str, Part] | None:
        """The (name, part) of the part with ``role``, or None."""
        return next(((n, p) for n, p in self.parts.items() if self.role(n) == role), None)

    def main_part(self) -> tuple[str, Part] | None:
        """The (name, part) of the main part (the paper's design: Table I, the headline,
        ``evaluate``'s grid): the part declared ``role: main``, else the part named
        ``main``; None when there is neither."""
        return self.part_with("main")

    def require_main(self) -> tuple[str, Part]:
        """:meth:`main_part`, or a ConfigError saying how to declare one."""
        main = self.main_part()
        if main is None:
            raise ConfigError(f"{self.where} has no main part (parts: {', '.join(self.parts)})",
                              hint="name the part with the study's grid `main`, or declare "
                                   "`role: main` on it")
        return main

    def population_specs(self) -> dict[str, PopulationSpec]:
        """Every population the study's parts run, by name, as declared (a condition or a
        split half it lists, a null replicate of a part's null design): the index readers
        look a population up in, instead of reading its name."""
        return index_of(spec for part in self.parts.values() for spec in part.planned_specs)

    @model_validator(mode="after")
    def _names_are_unique(self) -> Study:
        try:
            self.population_specs()
        except ValueError as err:
            raise ValueError(f"parts: {err}") from None
        return self

    @model_validator(mode="after")
    def _main_is_not_a_null(self) -> Study:
        main = self.main_part()
        if main is not None and main[1].null_design is not None:
            raise ValueError(f"parts.{main[0]}: a part with a null design (its populations "
                             "are null replicates) cannot be the main part; declare "
                             "`role: other` on it, or give the main part another name")
        return self

    @model_validator(mode="after")
    def _one_part_per_role(self) -> Study:
        roles = [self.role(n) for n in self.parts]
        twice = sorted({r for r in roles if r != "other" and roles.count(r) > 1})
        if twice:
            raise ValueError(f"parts: more than one part has role {', '.join(twice)} "
                             "(declare `role: other` on all but one)")
        return self

    @field_validator("name")
    @classmethod
    def _safe_name(cls, v: str) -> str:
        # the name becomes a folder (./study-<name>): no separators, no "..", no dotfile
        if not SAFE_NAME.fullmatch(v) or ".." in v or len(v) > NAME_MAX:
            raise ValueError(f"a study name is up to {NAME_MAX} letters, digits, '.', '_' "
                             "and '-' (it names the default output folder study-<name>)")
        return v

    @field_validator("parts")
    @classmethod
    def _safe_part_names(cls, v: dict[str, Part]) -> dict[str, Part]:
        for name in v:  # a part name is a table value and a report heading
            if not SAFE_NAME.fullmatch(name) or len(name) > NAME_MAX:
                raise ValueError(f"part name {name!r}: up to {NAME_MAX} letters, digits, "
                                 "'.', '_' and '-'")
        return v

    def config_hash(self) -> str:
        """Canonical hash of everything that determines the study's results."""
        return digest(self.model_dump(mode="json", exclude={"output", "description"}))[:16]

    def extended(self, *, replicates: int | None = None,
                 seed_sets: int | None = None) -> Study:
        """This study with more evidence and nothing else changed (``run`` then simulates
        only the new runs, :mod:`popnavshift.engine.run_inputs`): every null design with
        ``replicates`` replicates, and every part that repeats its episodes on extra seed
        sets (a part with ``seeds``) on ``seed_sets`` seed sets in all (the study seed's
        and ``seed_sets − 1`` extra ones: the part's own first, then the next unused
        seeds). None leaves that side as it is; fewer than the study has is an error
        (``run`` would drop finished runs from the tables; shrink the study file instead)."""
        parts = dict(self.parts)
        for name, part in self.parts.items():
            update: dict[str, Any] = {}
            if replicates is not None and part.null_design is not None:
                if replicates < part.null_design.replicates:
                    raise ConfigError(f"{self.where}: part {name} has "
                                      f"{part.null_design.replicates} null replicates; "
                                      f"--replicates {replicates} would drop some")
                update["null_design"] = part.null_design.model_copy(
                    update={"replicates": replicates})
            if seed_sets is not None and part.seeds:
                update["seeds"] = _more_seeds(part.seeds, self.seed, seed_sets,
                                              f"{self.where}: part {name}")
            parts[name] = part.model_copy(update=update) if update else part
        study = self.model_copy(update={"parts": parts})
        study._where = self._where
        return study


def _more_seeds(seeds: tuple[int, ...], study_seed: int, total: int,
                where: str) -> tuple[int, ...]:
    """``seeds`` grown to ``total − 1`` extra seed sets (the study seed's is the first):
    the given ones first, then the smallest unused ones."""
    extra = [s for s in seeds if s != study_seed]
    if total < 1 + len(extra):
        raise ConfigError(f"{where} runs {1 + len(extra)} seed sets; --seed-sets {total} "
                          "would drop some")
    candidate = 1
    while 1 + len(extra) < total:
        if candidate != study_seed and candidate not in extra:
            extra.append(candidate)
        candidate += 1
    return tuple(extra)


def _format_error(err: ValidationError, where: str) -> str:
    first = err.errors()[0]
    loc = ".".join(str(x) for x in first["loc"]) or "(top level)"
    got = first.get("input")
    shown = repr(got) if len(repr(got)) <= 80 else repr(got)[:77] + "…"
    got_txt = "" if isinstance(got, dict) else f"; got {shown}"
    return f"{where}: {loc}: {first['msg'].removeprefix('Value error, ')}{got_txt}"


def study_from_dict(data: Any, where: str = "study") -> Study:
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: a study must be a mapping of keys, got {type(data).__name__}")
    try:
        study = Study.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_error(err, where)) from None
    study._where = where
    return study


def builtin_studies() -> list[str]:
    folder = resources.files("popnavshift").joinpath("studies")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def load_study(name_or_path: str | Path) -> Study:
    """A built-in study by name (``paper``, ``quick``) or a YAML file path."""
    text: str
    where = str(name_or_path)
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise ConfigError(f"study file not found: {path}")
        try:
            text = path.read_text("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = getattr(exc, "strerror", None) or "not UTF-8 text"
            raise ConfigError(f"study file {path}: cannot be read ({reason})") from None
    elif str(name_or_path) in builtin_studies():
        text = (
            resources.files("popnavshift")
            .joinpath("studies", f"{name_or_path}.yaml")
            .read_text("utf-8")
        )
        where = f"built-in study {name_or_path!r}"
    else:
        raise UnknownNameError("study", str(name_or_path), builtin_studies())
    return study_from_dict(parse_study_yaml(text, where), where)
