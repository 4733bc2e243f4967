"""What a learned policy costs as a controller: simulation time per step of an ONNX policy
(``popnavshift.learn.policy``) beside ``robot_orca`` and the built-ins, on the same episodes.

The policy is a tiny one made here with ``onnx.helper`` (a linear map from the 47-value
observation to an action heading for the goal), so the figure is the cost of the
machinery — the Python behaviour, the observation of ``learn.spaces`` and one ONNX Runtime
call per step — not of a large network; a trained 2×64 MLP adds little to one call.

    nice -n 10 python benchmarks/bench_policy.py            # the quick study's 10 episodes
    python benchmarks/bench_policy.py --episodes 4 --repeat 1

Prints the machine and its load, then per controller the runs, steps, seconds and µs per
step (best of ``--repeat``), and the ONNX Runtime call alone.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def goal_policy(path: Path) -> Path:
    """A linear ONNX policy: forward from the goal's bearing cosine, turn from its sine."""
    from onnx import TensorProto, helper, numpy_helper

    from popnavshift.learn.spaces import ACTION_SIZE, OBSERVATION_SIZE, observation_layout

    start = 0
    for name, n in observation_layout():
        if name == "ego_target_direction":
            break
        start += n
    w = np.zeros((OBSERVATION_SIZE, ACTION_SIZE), np.float32)
    w[start, 0], w[start + 1, 1] = 0.8, 1.5
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["observation", "W"], ["action"])], "goal",
        [helper.make_tensor_value_info("observation", TensorProto.FLOAT,
                                       ["batch", OBSERVATION_SIZE])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", ACTION_SIZE])],
        [numpy_helper.from_array(w, "W")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path.write_bytes(model.SerializeToString())
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10,
                    help="episodes of the quick study's main part (it has 10)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many passes")
    args = ap.parse_args(argv)

    from popnavshift.controller_ids import policy_id
    from popnavshift.design.plan import select_episodes
    from popnavshift.design.study import load_study
    from popnavshift.episodes.specs import all_episodes
    from popnavshift.learn.policy import load_predictor
    from popnavshift.sim.controllers import CONTROLLERS
    from popnavshift.sim.run import simulate

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {tuple(round(x, 2) for x in os.getloadavg())}")
    study = load_study("quick")
    every = select_episodes(study.require_main()[1].episodes, all_episodes(study.seed))
    specs = every[:: max(1, len(every) // args.episodes)][: args.episodes]  # across cells
    with tempfile.TemporaryDirectory() as tmp:
        path = goal_policy(Path(tmp) / "goal.onnx")
        policy = policy_id(str(path))
        for name in ("robot_orca", "reactive", policy):
            factory = CONTROLLERS.make(name)
            simulate(specs[0], None, factory)  # warm: imports, numba compilation
            best, steps = float("inf"), 0
            for _ in range(args.repeat):
                started = time.perf_counter()
                steps = sum(simulate(s, None, factory).run["steps"] for s in specs)
                best = min(best, time.perf_counter() - started)
            label = "policy (ONNX)" if name == policy else name
            print(f"{label:>14}: {len(specs)} runs, {steps} steps, {best:.3f} s, "
                  f"{1e6 * best / steps:.1f} us/step")
        predictor = load_predictor(path, _sha(path))
        obs = np.zeros(47, np.float32)
        n = 20_000
        started = time.perf_counter()
        for _ in range(n):
            predictor.predict(obs)
        print(f"ONNX Runtime call alone: {1e6 * (time.perf_counter() - started) / n:.1f} us")
    print(f"load after {tuple(round(x, 2) for x in os.getloadavg())}")
    return 0


def _sha(path: Path) -> str:
    from popnavshift.controller_ids import file_sha256

    return file_sha256(path)


if __name__ == "__main__":
    raise SystemExit(main())
