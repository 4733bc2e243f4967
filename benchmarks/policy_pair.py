"""Two controllers on the same runs: the paired difference in outcome shares over a study's
main part (same episodes, same populations, one run each), with an exact McNemar test per
outcome, a sign-flip test by episode (an episode's runs under the eight populations share
its world, so the episode is the unit that was drawn at random), and the success share per
population. For docs/learning.md's question "does the
training population matter?": run after ``popnavshift evaluate`` of both policies.

    .venv/bin/python benchmarks/policy_pair.py study/evaluate/policy-A… study/evaluate/policy-B…

Each argument is a card folder (its ``runs.parquet`` holds the controller's own runs).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

KEY = ["episode", "population"]
OUTCOMES = ("success", "world_collision", "pedestrian_collision", "timeout")


def _sign_flip(d: np.ndarray, draws: int = 20_000, seed: int = 0) -> float:
    """Two-sided p of the mean of ``d`` (one value per episode) under random sign flips."""
    rng = np.random.default_rng(seed)
    signs = rng.choice((-1, 1), size=(draws, len(d)))
    null = np.abs((signs * d).mean(axis=1))
    return float((1 + np.sum(null >= abs(d.mean()) - 1e-12)) / (draws + 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("first", type=Path, help="card folder of the first controller")
    ap.add_argument("second", type=Path, help="card folder of the second controller")
    a = ap.parse_args()
    runs = [pd.read_parquet(f / "runs.parquet") for f in (a.first, a.second)]
    main_runs = [r.loc[r["part"] == "main", [*KEY, "outcome"]] for r in runs]
    both = main_runs[0].merge(main_runs[1], on=KEY, suffixes=("_1", "_2"), validate="1:1")
    print(f"{len(both)} paired runs (main part): 1 = {a.first.name}, 2 = {a.second.name}")
    for o in OUTCOMES:
        x, y = both["outcome_1"] == o, both["outcome_2"] == o
        only1, only2 = int((x & ~y).sum()), int((~x & y).sum())
        p = stats.binomtest(only1, only1 + only2, 0.5).pvalue if only1 + only2 else 1.0
        by_episode = (y.astype(int) - x.astype(int)).groupby(both["episode"]).sum().to_numpy()
        print(f"{o:21s} 1: {100 * x.mean():5.1f}%  2: {100 * y.mean():5.1f}%  "
              f"discordant 1 only {only1}, 2 only {only2}; exact McNemar p {p:.2g}; "
              f"sign-flip by episode p {_sign_flip(by_episode):.2g}")
    per = both.groupby("population").agg(
        first=("outcome_1", lambda s: 100 * (s == "success").mean()),
        second=("outcome_2", lambda s: 100 * (s == "success").mean()))
    print("success by population [%]:")
    print(per.round(1).to_string())


if __name__ == "__main__":
    main()
