"""The power model's hold-out (docs/analysis.md §8a): how well each candidate model of the
excess and the null SD, fitted on a study's first seed sets, predicts the t at more.

Two steps. ``rates`` computes, for one comparison design of a finished study folder (the
matched pair and its swap null by default), the raw reversal rate of the observed pairs
and of each of the first P null replicates on every subset of the seed sets (sizes given
by ``--sizes``); raw rates use a fixed tie tolerance, so no bootstrap is involved.
``evaluate`` then builds every nested *path* (an order of seed sets, as a study's curve
nests them), fits each (excess form × SD form) of :mod:`popnavshift.analysis.power` on
the first ``--fit`` seed sets with the package's own :func:`fit_curve`, predicts the t at
the held-out ``--target`` and compares it with the t measured on that path:

    python benchmarks/power_holdout.py rates STUDY_FOLDER rates.csv --sizes 1 2 3 4 8
    python benchmarks/power_holdout.py evaluate rates.csv --fit 2 --target 4 --fit 4 --target 8

prints per model the mean absolute error, bias (mean of actual − predicted) and SD of the
errors, per hold-out and averaged; with ``--model root constant --bias B --sd S`` also
the share of held-out t inside the model's 10–90 % interval (the module's ``Spread``).
"""

from __future__ import annotations

import argparse
import time
from itertools import combinations, permutations
from pathlib import Path

import numpy as np
import pandas as pd

from popnavshift.analysis.power import EXCESS_FORMS, SD_FORMS, Spread, fit_curve, t_interval


def rates(folder: Path, out: Path, label: str, max_nulls: int, sizes: list[int] | None) -> None:
    from popnavshift.analysis.delay import cell_metrics, paired_delays
    from popnavshift.analysis.evidence import complete_design
    from popnavshift.analysis.nulls import design_populations, headline_designs
    from popnavshift.analysis.ranked import RANKED_NAMES
    from popnavshift.analysis.replicates import seed_sets
    from popnavshift.analysis.resample import build_design, episode_weights, resampled_metrics
    from popnavshift.analysis.significance import orderings, pair_counts
    from popnavshift.populations.identity import spec_of
    from popnavshift.read.folder import open_study

    t0 = time.time()
    study = open_study(folder)
    _, part = study.main_part()
    keep = study.runs["backend"].isin(part.backends) & study.runs["mapping"].isin(part.mappings)
    runs = study.runs[keep]
    peds = study.pedestrians[study.pedestrians["backend"].isin(part.backends)
                             & study.pedestrians["mapping"].isin(part.mappings)]
    present = [spec_of(study.population_specs, x) for x in runs["population"].unique()]
    conditions = {s.name for s in present if s.role == "observed"}
    observed = [x for x in part.populations if x in conditions]
    d = headline_designs(present, observed)[label]
    d = d._replace(nulls=d.nulls[:max_nulls])
    r, p = complete_design(runs, peds, design_populations(d))
    rs, ps = seed_sets(r).to_numpy(), seed_sets(p).to_numpy()
    sets = sorted(set(rs))
    rows = []
    for k in sizes or range(1, len(sets) + 1):
        for sub in combinations(sets, k):
            rr, pp = r[np.isin(rs, sub)], p[np.isin(ps, sub)]
            paired = paired_delays(pp)
            cells, design = cell_metrics(rr, paired), build_design(rr, paired)
            w = episode_weights(design, 2, np.random.default_rng(0))
            for m in RANKED_NAMES:
                o = orderings(cells, design, resampled_metrics(design, w, (m,)), m)
                for j, pairs in enumerate([d.observed, *d.nulls]):
                    rows.append({"sets": "-".join(map(str, sub)), "S": len(sub), "metric": m,
                                 "k": j, "raw": pair_counts(o, pairs).rate("raw")})
            print(f"{sub} {time.time() - t0:.0f} s", flush=True)
    pd.DataFrame(rows).to_csv(out, index=False)


def points(table: pd.DataFrame, nulls: int) -> dict:
    """(metric, sets key) → (excess, null SD) with the first ``nulls`` replicates."""
    out = {}
    t = table[table["k"] <= nulls]
    for (metric, sets), g in t.groupby(["metric", "sets"], sort=False):
        obs = g.loc[g["k"] == 0, "raw"].to_numpy(float)[0]
        null = g.loc[g["k"] > 0, "raw"].to_numpy(float)
        out[(metric, sets)] = (obs - null.mean(), null.std(ddof=1))
    return out


def paths(sets: list[int], fit: int, target: int) -> list[tuple[list[str], str]]:
    """Every nested path: the keys of its first 1 … ``fit`` seed sets and of the held-out
    first ``target`` (every order of the fitted sets, every completion to ``target``)."""
    key = lambda s: "-".join(map(str, sorted(s)))  # noqa: E731
    out = []
    for head in permutations(sets, fit):
        rest = [s for s in sets if s not in head]
        for more in combinations(rest, target - fit):
            out.append(([key(head[:i]) for i in range(1, fit + 1)], key(head + more)))
    return out


def evaluate(table: pd.DataFrame, holdouts: list[tuple[int, int]], nulls: int,
             models: list[tuple[str, str]], spread: Spread | None) -> pd.DataFrame:
    pts = points(table, nulls)
    sets = sorted({int(x) for key in table["sets"].unique() for x in str(key).split("-")})
    rows = []
    for fit, target in holdouts:
        for head, tkey in paths(sets, fit, target):
            for metric in table["metric"].unique():
                e = np.array([pts[(metric, h)][0] for h in head])
                v = np.array([pts[(metric, h)][1] for h in head])
                ae, av = pts[(metric, tkey)]
                actual = ae / (av * np.sqrt(1 + 1 / nulls))
                for model in models:
                    f = fit_curve(np.arange(1, fit + 1), e, v, model)
                    pred = f.t(target, nulls)
                    row = {"fit": fit, "target": target, "metric": metric,
                           "model": "+".join(model), "predicted": pred, "actual": actual,
                           "error": actual - pred}
                    if spread is not None:
                        _, low, high = t_interval(f, target, nulls, fit, spread)
                        row["covered"] = low <= actual <= high
                    rows.append(row)
    return pd.DataFrame(rows)


def summary(errors: pd.DataFrame) -> pd.DataFrame:
    agg = {"mae": ("error", lambda x: float(np.abs(x).mean())),
           "bias": ("error", "mean"), "sd": ("error", "std"), "n": ("error", "size")}
    if "covered" in errors:
        agg["covered"] = ("covered", "mean")
    by = errors.groupby(["model", "fit", "target"]).agg(**agg).reset_index()
    return by


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a1 = sub.add_parser("rates")
    a1.add_argument("folder", type=Path)
    a1.add_argument("out", type=Path)
    a1.add_argument("--label", default="matched")
    a1.add_argument("--nulls", type=int, default=9)
    a1.add_argument("--sizes", type=int, nargs="+", default=None)
    a2 = sub.add_parser("evaluate")
    a2.add_argument("rates", type=Path)
    a2.add_argument("--fit", type=int, action="append", required=True)
    a2.add_argument("--target", type=int, action="append", required=True)
    a2.add_argument("--nulls", type=int, default=9)
    a2.add_argument("--model", nargs=2, default=None, help="one model, e.g. root constant")
    a2.add_argument("--bias", type=float, default=None)
    a2.add_argument("--sd", type=float, default=None)
    a2.add_argument("--errors", type=Path, default=None, help="write every error here")
    a2.add_argument("--metrics", nargs="+",
                    default=["robot_time", "mean_delay", "worst_decile", "cvar90"],
                    help="the metrics evaluated (§8a: the four ranked ones)")
    a = ap.parse_args()
    if a.cmd == "rates":
        rates(a.folder, a.out, a.label, a.nulls, a.sizes)
        return
    table = pd.read_csv(a.rates, dtype={"sets": str})
    table = table[table["metric"].isin(a.metrics)]
    models = ([tuple(a.model)] if a.model else
              [(e, v) for e in EXCESS_FORMS for v in SD_FORMS])
    spread = Spread(a.bias, a.sd) if a.bias is not None and a.sd is not None else None
    errors = evaluate(table, list(zip(a.fit, a.target, strict=True)), a.nulls, models, spread)
    if a.errors:
        errors.to_csv(a.errors, index=False)
    pd.set_option("display.width", 200)
    s = summary(errors)
    print(s.round(3).to_string(index=False))
    mean = s.groupby("model")[["mae", "bias", "sd"]].mean().sort_values("mae")
    print("\nmean over the hold-outs:\n" + mean.round(3).to_string())
    print("\nby metric:\n" + errors.groupby(["model", "metric"])["error"].agg(
        mae=lambda x: float(np.abs(x).mean()), bias="mean").unstack().round(2).to_string())


if __name__ == "__main__":
    main()
