"""A study folder's respondent tables, read for the respondent audit.

The audit (:mod:`popnavshift.analysis.audit_verdict`) reads the answers of each
respondent a study asked — ``responses.parquet`` and, when the study has a second
respondent, ``responses_alt.parquet`` — with the personas they answered for and the
motion profiles mapped from them: the study's main mapping for the first respondent, the
second respondent's profile set (``A~<respondent>-2``) for the second.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ..errors import InputError
from ..pipeline import read_table
from ..populations.perturb import ProfileSet
from ..responses.samples import with_samples
from ..tables import check_table
from .folder import StudyFolder

#: The profile set of the first respondent when the manifest names no study part.
MAIN_MAPPING = "A"


@dataclass(frozen=True)
class RespondentTables:
    """One respondent's answers and profiles: ``role`` is ``first`` (responses.parquet)
    or ``second`` (responses_alt.parquet); ``profiles`` has one profile set (``mapping``)."""

    role: str
    responses: pd.DataFrame
    profiles: pd.DataFrame
    #: the respondent's settings as responses.json records them (temperature, samples, …)
    meta: dict[str, Any] = field(default_factory=dict)


def _profile_set(profiles: pd.DataFrame, second: bool, main: str) -> pd.DataFrame:
    sets = {m: ProfileSet.parse(m) for m in profiles["mapping"].unique()}
    if second:
        names = [m for m, s in sets.items() if s.perturbation == "second_respondent"]
    else:
        names = [main] if main in sets else [m for m, s in sets.items()
                                             if s.perturbation == "none"][:1]
    return profiles[profiles["mapping"].isin(names[:1])].reset_index(drop=True)


def main_mapping(folder: Path) -> str:
    """The first profile set of the study's main part (:meth:`.folder.StudyFolder.main_part`);
    :data:`MAIN_MAPPING` when the folder has no study or it has no main part."""
    main = StudyFolder(folder).main_part()
    return MAIN_MAPPING if main is None else main[1].mappings[0]


def read_respondent_tables(folder: Path) -> tuple[pd.DataFrame, list[RespondentTables]]:
    """(personas, one :class:`RespondentTables` per respondent) of a study folder.

    Raises InputError when the folder lacks ``personas.parquet`` or ``responses.parquet``
    (the probe stage has not run); a missing ``profiles.parquet`` leaves the profiles
    empty (the audit then covers the answers only).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"study folder {folder} does not exist",
                         hint="give a folder written by `popnavshift run` or `popnavshift probe`")
    for name in ("personas", "responses"):
        if not (folder / f"{name}.parquet").exists():
            raise InputError(f"study folder {folder}: {name}.parquet not found",
                             hint="run the probe stage first (`popnavshift run` or "
                             "`popnavshift personas` then `popnavshift probe`)")
    personas = check_table(read_table(folder / "personas.parquet", "personas"), "personas")
    main = main_mapping(folder)
    has_profiles = (folder / "profiles.parquet").exists()
    profiles = (check_table(read_table(folder / "profiles.parquet", "profiles"), "profiles")
                if has_profiles else None)
    meta_path = folder / "responses.json"
    meta = json.loads(meta_path.read_text("utf-8")) if meta_path.exists() else {}
    metas = {"first": meta, "second": meta.get("second") or {}}
    out = []
    for role, file in (("first", "responses"), ("second", "responses_alt")):
        if not (folder / f"{file}.parquet").exists():
            continue
        responses = check_table(with_samples(read_table(folder / f"{file}.parquet",
                                                        "responses")), "responses")
        if not (responses["variant"] == "baseline").any():
            raise InputError(f"{folder / file}.parquet has no baseline answer to audit",
                             hint="run the probe stage again")
        sets = (_profile_set(profiles, role == "second", main) if profiles is not None
                else pd.DataFrame(columns=["persona_id", "variant", "mapping"]))
        out.append(RespondentTables(role, responses, sets, metas[role]))
    return personas, out
