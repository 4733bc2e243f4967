"""File layer for the population pipeline: each stage reads and writes the study folder.

Stage functions (pure, in their modules) know nothing of files; this module
reads inputs, calls them, writes outputs atomically and returns what it wrote.
Study folder layout::

    personas.parquet, personas.json (provenance)
    responses.parquet, responses_invalid.parquet, responses.json (stats)
    profiles.parquet (all mappings), populations.parquet (all mappings)
    figures/fig3a_profiles.{png,svg}, figures/fig3b_matched_shift.{png,svg}
    cache/llm.sqlite (network respondents)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from .design.specs import PersonaSource, RespondentSpec
from .errors import InputError, RespondentError
from .io import write_json, write_parquet
from .personas.load import load_personas
from .personas.variants import MATCHED_N_DEFAULT, matched_ids
from .populations.build import POPULATIONS, SPLIT_HALVES, attach_profiles, membership
from .populations.figures import write_profile_figures
from .populations.identity import MATCHED_PAIR, PopulationSpec
from .populations.perturb import STRUCTURE, Sources, label
from .profiles.mappings import build_profiles
from .progress import progress_bar
from .responses.collect import collect_responses
from .responses.probes import PROBE_SET_HASH
from .responses.respondent import RESPONDENTS, Respondent
from .responses.samples import AGGREGATION, aggregate_samples


@dataclass(frozen=True)
class PopulationSettings:
    """Everything that determines the population pipeline's outputs: the study's persona
    source and respondents as the study holds them, and what its parts need built."""

    personas: PersonaSource = field(default_factory=PersonaSource)
    seed: int = 0
    respondent: RespondentSpec = field(default_factory=RespondentSpec)
    matched_n: int = MATCHED_N_DEFAULT
    mappings: tuple[str, ...] = ("A", "B", "C", "D")
    #: second respondent for the respondent-robustness study (matched pair only)
    respondent2: RespondentSpec | None = None
    #: also build the profile sets of the structure study (reassign, shuffle, blocks)
    structure: bool = False
    #: null populations the study runs (:mod:`popnavshift.populations.nulls`), and the
    #: profile sets they are run with (their members get only those profiles)
    nulls: tuple[PopulationSpec, ...] = ()
    null_mappings: tuple[str, ...] = ()
    #: the populations the study runs: one of them empty is an error, any other empty
    #: one is left out (None: every population is required). Not in the stage's stamp:
    #: membership does not depend on it, and the runner checks it on every run.
    required: tuple[str, ...] | None = None

    @property
    def respondent2_label(self) -> str | None:
        """Profile-set label of the second respondent, e.g. ``A~rule-2`` (None without one)."""
        return label("second_respondent", self.respondent2.name) if self.respondent2 else None


def read_table(path: Path, stage: str) -> pd.DataFrame:
    """Read a stage table written by an earlier step, with a clear error if absent."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{stage} table not found: {path}", hint="run the earlier stage first")
    try:
        return pd.read_parquet(path)
    except Exception as exc:
        raise InputError(f"{path}: not a readable Parquet file ({exc})") from None


def read_responses(path: Path) -> pd.DataFrame:
    """A responses table as profiles and populations read it: one answer per persona and
    variant, the aggregate of its samples (:func:`aggregate_samples`)."""
    return aggregate_samples(read_table(path, "responses"))


def run_personas(folder: Path, s: PopulationSettings, target: Path | None = None) -> pd.DataFrame:

    p = s.personas
    personas, provenance = load_personas(
        p.source,
        n=p.n,
        seed=s.seed,
        missing=p.missing,
        codebook=p.codebook,
        sources=p.sources,
        verify_checksums=p.verify_checksums,
    )
    target = target or folder / "personas.parquet"
    write_parquet(personas, target)
    write_json(provenance, target.with_suffix(".json"))
    return personas


#: the response cache of respondents that declare ``uses_cache``, in the study folder
RESPONSE_CACHE = Path("cache") / "llm.sqlite"


def respondent_from(name: str, options: dict[str, Any], folder: Path) -> Respondent:
    """The respondent ``name`` with ``options``; one that declares ``uses_cache`` gets
    the folder's response cache unless ``options`` name a ``cache_path``."""
    opts = dict(options)
    if RESPONDENTS.resolve(name).uses_cache:
        opts.setdefault("cache_path", folder / RESPONSE_CACHE)
    respondent = RESPONDENTS.make(name, **opts)
    validate = getattr(respondent, "validate", None)
    if callable(validate):  # a bad option is named before any table is read or call made
        validate()
    return respondent


def run_responses(folder: Path, s: PopulationSettings, show_progress: bool = True) -> pd.DataFrame:
    respondent = respondent_from(s.respondent.name, s.respondent.options, folder)  # fail fast
    personas = read_table(folder / "personas.parquet", "personas")
    matched = matched_ids(personas, s.matched_n, s.seed)
    total = len(personas) + len(matched)
    with progress_bar(f"probing ({respondent.name})", total * s.respondent.samples, show_progress,
                      note=getattr(respondent, "progress_note", None)) as advance:
        responses, invalid, stats = collect_responses(personas, respondent, matched, advance,
                                                      s.respondent.samples)
    write_parquet(invalid, folder / "responses_invalid.parquet")
    _require_valid(responses, invalid, respondent, folder / "responses_invalid.parquet")
    write_parquet(responses, folder / "responses.parquet")
    meta = {**stats, **respondent.describe(), "probe_set": PROBE_SET_HASH, "matched_n": s.matched_n,
            "aggregation": AGGREGATION}
    if s.respondent2 is not None:  # the matched pair again, with the second respondent
        second = respondent_from(s.respondent2.name, s.respondent2.options, folder)
        pair = personas[personas["persona_id"].isin(matched)]
        with progress_bar(f"probing ({second.name}, 2nd)", 2 * len(pair) * s.respondent2.samples,
                          show_progress, note=getattr(second, "progress_note", None)) as adv:
            alt, alt_invalid, alt_stats = collect_responses(pair, second, matched, adv,
                                                            s.respondent2.samples)
        write_parquet(alt_invalid, folder / "responses_alt_invalid.parquet")
        _require_valid(alt, alt_invalid, second, folder / "responses_alt_invalid.parquet")
        write_parquet(alt, folder / "responses_alt.parquet")
        meta["second"] = {**alt_stats, **second.describe(), "label": s.respondent2_label}
    write_json(meta, folder / "responses.json")
    return responses


def _require_valid(responses: pd.DataFrame, invalid: pd.DataFrame, respondent,
                   listed_in: Path) -> None:
    """RespondentError when every record is invalid: nothing downstream can use the run,
    and a zero exit would hide a dead server or a broken model."""
    if len(responses) or not len(invalid):
        return
    raise RespondentError(
        f"{respondent.name} {respondent.model}: no valid response in {len(invalid)} records; "
        f"first error: {invalid['error'].iloc[0]}",
        hint=f"every record is listed in {listed_in}; -v shows retries and re-asks",
    )


def run_profiles(folder: Path, s: PopulationSettings) -> pd.DataFrame:

    personas = read_table(folder / "personas.parquet", "personas")
    responses = read_responses(folder / "responses.parquet")
    sets = [build_profiles(responses, personas, m) for m in s.mappings]
    if s.structure:  # the structure sets built from Mapping A's profiles
        sources = Sources(sets[s.mappings.index("A")], responses, personas, s.seed)
        sets += [kind.profiles(sources, arg) for kind in STRUCTURE.values()
                 if kind.profiles is not None for arg in kind.args]
    if s.respondent2 is not None:
        alt = read_responses(folder / "responses_alt.parquet")
        sets.append(build_profiles(alt, personas, "A").assign(mapping=s.respondent2_label))
    profiles = pd.concat(sets, ignore_index=True)
    write_parquet(profiles, folder / "profiles.parquet")
    return profiles


def run_populations(folder: Path, s: PopulationSettings) -> pd.DataFrame:
    """The populations stage: :func:`build_populations` from the folder's tables, written
    with its profile figures."""
    table = build_populations(folder, s)
    write_parquet(table, folder / "populations.parquet")
    write_profile_figures(table[table["mapping"] == "A"], folder / "figures")
    return table


def build_populations(folder: Path, s: PopulationSettings) -> pd.DataFrame:
    """The ``populations`` table under settings ``s`` from the folder's personas, responses
    and profiles, written nowhere (``plan`` counts the runs a changed null design adds)."""
    personas = read_table(folder / "personas.parquet", "personas")
    responses = read_responses(folder / "responses.parquet")
    profiles = read_table(folder / "profiles.parquet", "profiles")
    matched = matched_ids(personas, s.matched_n, s.seed)
    members = membership(
        personas, responses, profiles[profiles["mapping"] == "A"], matched,
        populations=[*POPULATIONS, *SPLIT_HALVES, *s.nulls], seed=s.seed,
        required=s.required,
    )
    is_null = members["population"].isin([spec.name for spec in s.nulls])
    tables = []
    for set_label in profiles["mapping"].unique():
        these = profiles[profiles["mapping"] == set_label]
        these_members = members[~is_null | (set_label in s.null_mappings)]
        if set_label == s.respondent2_label:
            # a second respondent answered only the matched pair: those populations only
            have = set(these.loc[these["variant"] == "deadline", "persona_id"])
            pair = these_members["population"].isin(MATCHED_PAIR)
            these_members = these_members[pair & these_members["persona_id"].isin(have)]
        tables.append(attach_profiles(these_members, these))
    if s.structure:  # the structure sets built from Mapping A's populations
        base_a = next(t for t in tables if t["mapping"].iloc[0] == "A")
        tables += [kind.populations(base_a, arg, s.seed) for kind in STRUCTURE.values()
                   if kind.populations is not None for arg in kind.args]
    return pd.concat(tables, ignore_index=True)


