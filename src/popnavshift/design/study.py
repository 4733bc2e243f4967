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
from typing import Annotated, Any

from pydantic import PrivateAttr, ValidationError, field_validator, model_validator

from ..errors import ConfigError, UnknownNameError
from ..hashing import digest
from ..populations.identity import PopulationSpec, index_of
from ..strict import Count, Seed, Strict, Unique
from .part import PART_ROLES, Part, role_from_content
from .specs import PersonaSource, RespondentSpec
from .study_yaml import parse_study_yaml

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
#: a name becomes a folder and a table value: long enough for any study, short enough
#: for any file system (255 bytes a component)
NAME_MAX = 100


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
    except ConfigError as err:  # raised by a validator itself (a profile set's label): where
        if err.message.startswith(f"{where}:"):
            raise
        raise ConfigError(f"{where}: {err.message}", hint=err.hint) from None
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
