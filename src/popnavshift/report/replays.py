"""Replays of illustrative runs: re-simulated from the stored tables and checked bit for bit.

The strongest mean-delay reversals and the largest single delays of an
:class:`~popnavshift.analysis.study.Analysis` are re-simulated from the episode id, the
population table and the study seed, drawn as animated pages, and each re-simulated
run is compared with its stored rows.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..analysis.delay import episode_cells
from ..analysis.study import Analysis
from ..errors import PopNavShiftError
from ..read.folder import StudyFolder, stored_pedestrians
from ..tables import NO_ROBOT, RUN_KEY
from ..viz.replay import write_replay

REPLAY_METRICS = ("outcome", "robot_time", "robot_path_length", "robot_stop_time",
                  "robot_min_clearance", "ped_collisions", "world_collisions", "n_peds",
                  "peds_arrived")


def slug(text: str) -> str:
    """A file-name-safe version of ``text`` (letters, digits, ``._-``)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "x"


@dataclass(frozen=True)
class Case:
    """An illustrative case: what it shows and the runs (keys as dicts) that show it."""

    kind: str  # "reversal" or "delay"
    index: int
    text: str
    runs: tuple[dict[str, str], ...]


def _run_mean_delay(paired: pd.DataFrame) -> pd.Series:
    return paired.groupby(["episode", "population", "controller"])["delay"].mean()


def reversal_cases(a: Analysis, runs: pd.DataFrame, n: int) -> list[Case]:
    """The ``n`` strongest mean-delay reversals (distinct cells): both orderings' smaller |Δ|.

    Each case replays the two controllers under the two populations in the
    variant where the per-run mean delays reverse most strongly (else the first).
    """
    if a.comps is None or a.paired is None or n <= 0:
        return []
    c = a.comps[(a.comps["metric"] == "mean_delay") & a.comps["reversal"]]
    c = c.assign(strength=np.minimum(c["diff_a"].abs(), c["diff_b"].abs()))
    c = c.sort_values("strength", ascending=False, kind="stable").drop_duplicates("cell").head(n)
    md = _run_mean_delay(a.paired)
    eps = episode_cells(runs)
    cases = []
    for i, r in enumerate(c.itertuples(index=False), start=1):
        def gap(ep: str, pop: str, r=r) -> float:
            return float(md.get((ep, pop, r.ctrl_1), np.nan) - md.get((ep, pop, r.ctrl_2), np.nan))

        options = sorted(eps.loc[eps["cell"] == r.cell, "episode"])
        score = [min(abs(gap(e, r.pop_a)), abs(gap(e, r.pop_b)))
                 if gap(e, r.pop_a) * gap(e, r.pop_b) < 0 else -1.0 for e in options]
        ep = options[int(np.argmax(score))]
        text = (f"Cell {r.cell}: under {r.pop_a}, {r.ctrl_1} minus {r.ctrl_2} mean delay is "
                f"{r.diff_a:+.2f} s; under {r.pop_b} it is {r.diff_b:+.2f} s, so the order "
                f"flips. Replayed episode: {ep}.")
        keys = tuple({"episode": ep, "population": p, "controller": ctrl, "backend": r.backend,
                      "mapping": r.mapping} for p in (r.pop_a, r.pop_b)
                     for ctrl in (r.ctrl_1, r.ctrl_2))
        cases.append(Case("reversal", i, text, keys))
    return cases


def delay_cases(a: Analysis, n: int) -> list[Case]:
    """The ``n`` robot runs with the largest single paired delay, each with its baseline run."""
    if a.paired is None or a.paired.empty or n <= 0:
        return []
    p = a.paired.sort_values("delay", ascending=False, kind="stable")
    p = p.drop_duplicates(list(RUN_KEY)).head(n)
    cases = []
    for i, r in enumerate(p.itertuples(index=False), start=1):
        key = {k: str(getattr(r, k)) for k in RUN_KEY}
        text = (f"Persona {r.persona_id} (slot {r.slot}) took {r.delay:.1f} s longer with "
                f"{r.controller} than without a robot in {r.episode} under {r.population}.")
        cases.append(Case("delay", i, text, (key, {**key, "controller": NO_ROBOT})))
    return cases


def _same(x: Any, y: Any) -> bool:
    if isinstance(x, (float, np.floating)) or isinstance(y, (float, np.floating)):
        return bool(np.array_equal(np.float64(x), np.float64(y), equal_nan=True))
    return bool(x == y)


def run_differences(stored_run: pd.Series, stored_peds: pd.DataFrame, result) -> list[str]:
    """Columns where a re-simulated run (:class:`SimResult`) differs from the stored rows."""
    bad = [k for k, v in result.run.items() if k in stored_run and not _same(stored_run[k], v)]
    new = result.pedestrians.sort_values("slot").reset_index(drop=True)
    old = stored_peds.sort_values("slot").reset_index(drop=True)
    if len(new) != len(old):
        return [*bad, f"pedestrians ({len(old)} stored rows, {len(new)} re-simulated)"]
    for col in new.columns.intersection(old.columns):
        if not all(_same(x, y) for x, y in zip(old[col], new[col], strict=True)):
            bad.append(f"pedestrians.{col}")
    return bad


def resimulate(key: dict[str, str], populations: pd.DataFrame, seed: int, *, record: bool = True):
    """Simulate one stored run again from the episode id, the population table and the seed.
    The simulator is imported here, not with the report: a finished folder is analysed and
    reported without it (:func:`simulator_missing`)."""
    from ..engine.rebuild import rebuild_run

    return rebuild_run(key, populations, seed, record=record)


def simulator_missing() -> str | None:
    """Why the replays cannot be re-simulated here (navground does not import), or None."""
    try:
        import navground.sim  # noqa: F401
    except ImportError as exc:
        return (f"the replays re-simulate runs, which needs navground ({exc}); the rest of "
                "the report does not: install navground to add them")
    return None


def _row(df: pd.DataFrame, key: dict[str, str]) -> pd.DataFrame:
    m = np.ones(len(df), dtype=bool)
    for k, v in key.items():
        m &= (df[k] == v).to_numpy()
    return df[m]


def write_replays(study: StudyFolder, a: Analysis, runs: pd.DataFrame,
                  out: Path, n: int) -> pd.DataFrame | None:
    """Re-simulate the illustrative cases, write ``out/<name>.html`` (+ .svg) and check each run.

    Returns one row per replayed run: case, run keys, ``file`` (relative to the
    report), ``reproduced`` (every stored column equal, bit for bit) and
    ``differences``; None with ``a.missing["replays"]`` set when impossible.
    """
    seed = study.seed
    if n <= 0:
        return None
    if study.populations is None or seed is None:
        a.missing["replays"] = "the folder lacks populations.parquet or the study seed"
        return None
    cases = reversal_cases(a, runs, n) + delay_cases(a, n)
    missing = simulator_missing() if cases else None
    if missing:
        a.missing["replays"] = missing
        return None
    if not cases:
        a.missing["replays"] = "no reversal and no paired delay to illustrate"
        return None
    rows = []
    for case in cases:
        for key in case.runs:
            stored = _row(runs, key)
            if stored.empty:
                continue
            try:
                result = resimulate(key, study.populations, seed)
            except PopNavShiftError as exc:  # e.g. a run stored as controller_error
                rows.append({"case": case.kind, "index": case.index, "text": case.text, **key,
                             "file": "", "reproduced": False,
                             "differences": f"could not re-simulate: {exc}"})
                continue
            diff = run_differences(stored.iloc[0], stored_pedestrians(study, key), result)
            name = slug(f"{case.kind}{case.index}-{key['controller']}-{key['population']}")
            metrics = {"illustrates": case.text,
                       **{k: stored.iloc[0][k] for k in REPLAY_METRICS if k in stored},
                       "reproduces the stored run": "yes, bit for bit" if not diff
                       else "NO, differs in " + ", ".join(diff)}
            title = f"{key['episode']} · {key['population']} · {key['controller']}"
            write_replay(result.trajectory, metrics, out / f"{name}.html", title)
            rows.append({"case": case.kind, "index": case.index, "text": case.text, **key,
                         "file": f"replays/{name}.html", "reproduced": not diff,
                         "differences": ", ".join(diff)})
    return pd.DataFrame(rows)
