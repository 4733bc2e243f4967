"""The simulation benchmark: a fixed stratified sample and sane numbers (no timing assertions)."""

import numpy as np
import pytest
from navground import sim

from popnavshift.episodes import SCENES
from popnavshift.errors import ConfigError
from popnavshift.sim.bench import (
    CONDITIONS,
    bare_world,
    bench_sample,
    format_bench,
    run_bench,
    synthetic_population,
)


def test_sample_is_fixed_stratified_and_varied():
    sample = bench_sample(3)
    assert [s.id for s in sample] == [s.id for s in bench_sample(3)]
    assert [s.scene for s in sample] == [scene for scene in SCENES for _ in range(3)]
    assert len({s.id for s in sample}) == len(sample)
    sidewalk = sample[:3]  # consecutive picks differ in every factor
    for attr in ("width", "density", "variant"):
        assert len({getattr(s, attr) for s in sidewalk}) == 3
    assert [s.robot_speed for s in sidewalk] == [0.6, 1.0, 0.6]
    with pytest.raises(ConfigError, match="n_per_scene"):
        bench_sample(0)


def test_every_episode_of_a_scene_once():
    head_on = [s.id for s in bench_sample(24, scenes=("head_on",))]  # 8 cells x 3 variants
    assert len(set(head_on)) == 24
    sidewalk = [s.id for s in bench_sample(72, scenes=("sidewalk",))]  # 24 cells x 3 variants
    assert len(set(sidewalk)) == 72


def test_bare_world_follows_routes_without_python():
    spec = next(s for s in bench_sample(1) if s.scene == "sidewalk")
    world = bare_world(spec, np.full(spec.n_peds, 1.2), "orca", robot=True)
    assert len(world.agents) == spec.n_peds + 1
    start = np.array([a.position for a in world.agents])
    world.run(50, 0.1)
    moved = np.linalg.norm(np.array([a.position for a in world.agents]) - start, axis=1)
    assert np.all(moved > 1.0)  # 5 s at >= 0.6 m/s: everybody walks, the C++ robot too


def test_run_bench_on_a_few_episodes():
    result = run_bench(1, conditions=("none", "robot_orca"), backends=("orca",),
                       profile=True, scenes=("head_on", "sidewalk"))
    table = result.table
    assert list(table.columns) == ["condition", "backend", "episodes", "steps", "full_ms",
                                   "bare_ms", "full_eps", "bare_eps", "ratio"]
    assert table["condition"].tolist() == ["none", "robot_orca"]
    assert table["episodes"].tolist() == [2, 2]
    assert (table["steps"] > 0).all() and (table["steps"] <= 450).all()
    assert (table["full_ms"] > 0).all() and (table["bare_ms"] > 0).all()
    assert np.allclose(table["ratio"], table["full_ms"] / table["bare_ms"])
    assert np.allclose(table["full_eps"], 1e3 / table["full_ms"])
    s = result.summary
    assert s["episodes"] == 4 and s["ratio"] > 0 and s["within_target"] == (
        s["ratio"] <= 1.3 and s["worst_part"]["ratio"] <= 2.0)
    cats = s["profile"]["categories"]
    expected = {"navground update (C++)", "response layer kernel", "world build", "metrics"}
    assert expected <= set(cats)
    assert sum(cats.values()) == pytest.approx(s["profile"]["profiled_ms"], rel=1e-6)
    assert "update" not in vars(sim.World)  # the profiler's wrapper is gone again
    text = format_bench(result)
    assert "robot_orca" in text and "overall" in text and "profile" in text


def test_bad_arguments_name_the_parameter():
    with pytest.raises(ConfigError, match="repeats"):
        run_bench(1, repeats=0)
    with pytest.raises(ConfigError, match="unknown"):
        run_bench(1, conditions=("dwa",))
    assert set(CONDITIONS) == {"none", "reactive", "early_yield", "robot_orca"}


def test_synthetic_population_depends_on_seed():
    a, b = synthetic_population(0), synthetic_population(1)
    assert a.equals(synthetic_population(0)) and not a.equals(b)


def test_every_profile_rule_names_a_function_that_exists():
    """A module split must move its profile rules along (a stale rule silently files a
    function's time under its caller's category)."""
    import ast
    from pathlib import Path

    from popnavshift.sim.bench_profile import CATEGORY_RULES

    package = Path(__file__).resolve().parents[1] / "src" / "popnavshift"
    for category, suffix, names in CATEGORY_RULES:
        if suffix in ("", "~"):  # built-ins
            continue
        path = package / suffix
        assert path.exists(), (category, suffix)
        if path.is_dir():
            continue
        defined = {n.name for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                   if isinstance(n, ast.FunctionDef)}
        assert names <= defined, (category, suffix, sorted(names - defined))
