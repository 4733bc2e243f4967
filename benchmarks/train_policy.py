"""Train on one population, test on eight: a small learned policy from PopNavShift's
Gymnasium environment (docs/learning.md).

For each training population (default ``homogeneous`` and ``mixed``) this

1. builds the environment (``popnavshift.learn.env.make_env``) on the study's cells
   (``--study``, default ``paper``: its main part's 312 episodes) drawn with another
   episode seed (``--train-seed``, default 1) than the study's own (0): the policy never
   trains on the worlds it is tested on;
2. trains a 2×64 MLP by imitation of a navground controller (``--expert``, default
   ``robot_orca``) with DAgger: round 0 the expert drives, then the policy drives and the
   expert labels every state it visits (``info["navground_action"]``); after each round
   the policy is fitted (mean squared error) on everything gathered so far. The policy
   kept is the one that drove best in training (its success on the training episodes);
   the MLP is a Stable-Baselines3 PPO policy's actor, so it is also an SB3 model zip;
3. saves ``policy_<population>.zip`` (Stable-Baselines3) and ``policy_<population>.onnx``
   (the deterministic actor: input ``observation`` (batch, 47), output ``action``
   (batch, 2), the layout of ``popnavshift.learn.spaces``), and prints its training time;
4. tests both policies and the expert on the study's own episodes (seed 0; ``--test-episodes``
   of them, spread over the cells) under each of the paper's eight populations, in the same
   environment (the ONNX file run by ONNX Runtime), and prints one table: success,
   pedestrian- and world-collision, timeout rates and the mean time of the successes.

Then, with ``--evaluate``, it runs ``popnavshift evaluate policy_<population>.onnx --study
<evaluate-study>`` for each card, timed; ``--evaluate-only`` does only that, on the
policies already in ``--out`` (the cards on the paper study: ``--evaluate-only
--evaluate-study paper --evaluate-dir study --workers 2`` after ``make run``).

Needs ``pip install -e '.[learn]'`` (torch, Stable-Baselines3). Single-threaded torch;
``nice -n 10`` it on a shared machine:

    nice -n 10 python benchmarks/train_policy.py --out learn-example
    python benchmarks/train_policy.py --rounds 2 --episodes 10 --test-episodes 8  # a smoke run

Everything is seeded (``--seed``): the episodes each round draws, the network's
initialisation, the minibatches. Prints the machine's load before and after.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from popnavshift.learn.env import PopNavShiftEnv, make_env
from popnavshift.paper import PAPER_POPULATIONS


def _actor(policy):
    """The deterministic actor of an SB3 ActorCriticPolicy as a torch module:
    observation -> action clipped to [-1, 1] (what is trained, what is exported)."""
    import torch as th

    class Actor(th.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.features = policy.features_extractor
            self.extractor = policy.mlp_extractor
            self.action_net = policy.action_net

        def forward(self, observation: th.Tensor) -> th.Tensor:
            latent = self.extractor.forward_actor(self.features(observation))
            return th.clamp(self.action_net(latent), -1.0, 1.0)

    return Actor()


def _rollouts(env: PopNavShiftEnv, actor, episodes: int, rng: np.random.Generator,
              expert_drives: bool) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """States visited and the expert's action in each, over ``episodes`` episodes driven
    by the expert or by ``actor``; and each episode's outcome."""
    import torch as th

    states, labels, outcomes = [], [], []
    for _ in range(episodes):
        obs, info = env.reset(seed=int(rng.integers(2**31)))
        while True:
            states.append(obs)
            labels.append(info["navground_action"])
            if expert_drives:
                action = None
            else:
                with th.no_grad():
                    action = actor(th.as_tensor(obs[None])).numpy()[0]
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                outcomes.append(info["outcome"])
                break
    return np.array(states, np.float32), np.array(labels, np.float32), outcomes


def _fit(actor, states: np.ndarray, labels: np.ndarray, epochs: int,
         rng: np.random.Generator) -> float:
    """Mean squared error of ``actor`` on (states, labels), minimised by Adam; returns the
    last epoch's loss."""
    import torch as th

    opt = th.optim.Adam(actor.parameters(), lr=1e-3)
    x, y = th.as_tensor(states), th.as_tensor(labels)
    loss = th.zeros(())
    for _ in range(epochs):
        order = th.as_tensor(rng.permutation(len(x)))
        for i in range(0, len(x), 256):
            batch = order[i:i + 256]
            loss = th.mean((actor(x[batch]) - y[batch]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
    return float(loss.item())


def train(population: str, args: argparse.Namespace, folder: Path, out: Path) -> dict:
    """DAgger on ``population``; writes the zip and the ONNX file; returns the record."""
    import torch as th
    from stable_baselines3 import PPO

    th.manual_seed(args.seed)
    rng = np.random.default_rng([args.seed, sum(map(ord, population))])
    start = time.perf_counter()
    env = make_env(args.study, population, folder=folder, expert=args.expert,
                   episode_seed=args.train_seed)
    model = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [64, 64]}, device="cpu",
                seed=args.seed)
    actor = _actor(model.policy)
    states = np.zeros((0, env.observation_space.shape[0]), np.float32)
    labels = np.zeros((0, 2), np.float32)
    rounds = []
    fitted: list[dict] = []  # the weights fitted after each round
    for k in range(args.rounds + 1):
        s, a, outcomes = _rollouts(env, actor, args.episodes, rng, expert_drives=k == 0)
        states, labels = np.concatenate([states, s]), np.concatenate([labels, a])
        success = outcomes.count("success") / len(outcomes)
        loss = _fit(actor, states, labels, args.epochs, rng)
        fitted.append(copy.deepcopy(actor.state_dict()))
        rounds.append({"round": k, "driver": "expert" if k == 0 else "policy",
                       "success": success, "samples": len(states), "loss": loss})
        print(f"  {population} round {k} ({rounds[-1]['driver']} drives): success "
              f"{success:.0%}; fitted on {len(states)} samples, loss {loss:.4f}", flush=True)
    # keep the policy that drove best in training (the weights fitted before that round;
    # the last fit has not driven yet: it is kept only if no policy round did better than 0)
    best = max(range(1, args.rounds + 1), key=lambda k: (rounds[k]["success"], k),
               default=None)
    if best is not None:
        actor.load_state_dict(fitted[best - 1])
        print(f"  {population}: kept the policy of round {best} "
              f"({rounds[best]['success']:.0%} success in training)", flush=True)
    seconds = time.perf_counter() - start
    env.close()
    zip_path, onnx_path = out / f"policy_{population}.zip", out / f"policy_{population}.onnx"
    model.save(zip_path)
    with warnings.catch_warnings():  # the TorchScript exporter: no onnxscript needed
        warnings.simplefilter("ignore", DeprecationWarning)
        th.onnx.export(actor, (th.zeros(1, states.shape[1]),), str(onnx_path), dynamo=False,
                       input_names=["observation"], output_names=["action"],
                       dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}},
                       opset_version=17)
    print(f"{population}: trained in {seconds:.1f} s -> {onnx_path}, {zip_path}", flush=True)
    return {"population": population, "seconds": seconds, "rounds": rounds, "kept": best,
            "onnx": str(onnx_path), "zip": str(zip_path)}


def _test_episodes(env: PopNavShiftEnv, n: int) -> list[str]:
    """``n`` of the environment's episodes, evenly spread over its (cell-ordered) list."""
    ids = env.episode_ids
    picks = np.linspace(0, len(ids) - 1, min(n, len(ids))).round().astype(int)
    return [ids[i] for i in dict.fromkeys(picks.tolist())]


def test(policies: dict[str, Path], args: argparse.Namespace, folder: Path) -> list[dict]:
    """Each policy (ONNX Runtime) and the expert on the study's own episodes under each
    of the paper's populations: one row per (driver, population)."""
    from navground.learning.onnx.policy import OnnxPolicy

    drivers: dict[str, OnnxPolicy | None] = {f"expert {args.expert}": None}
    drivers.update({f"policy[{p}]": OnnxPolicy(path) for p, path in policies.items()})
    rows = []
    for population in PAPER_POPULATIONS:
        env = make_env(args.study, population, folder=folder, expert=args.expert)
        episodes = _test_episodes(env, args.test_episodes)
        for name, policy in drivers.items():
            outcomes, times = [], []
            for episode in episodes:
                obs, info = env.reset(options={"episode": episode})
                while True:
                    action = None if policy is None else policy.predict(obs)[0].reshape(-1)
                    obs, _, terminated, truncated, info = env.step(action)
                    if terminated or truncated:
                        break
                outcomes.append(info["outcome"])
                if info["outcome"] == "success":
                    times.append(info["run"]["robot_time"])
            rows.append({"driver": name, "population": population, "episodes": len(episodes),
                         **{o: outcomes.count(o) / len(outcomes) for o in
                            ("success", "pedestrian_collision", "world_collision", "timeout")},
                         "mean_success_time": float(np.mean(times)) if times else float("nan")})
        env.close()
    return rows


def _table(rows: list[dict]) -> str:
    head = (f"{'driver':<22} {'population':<19} {'n':>3} {'success':>7} {'ped.col':>7} "
            f"{'wall.col':>8} {'timeout':>7} {'time[s]':>7}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['driver']:<22} {r['population']:<19} {r['episodes']:>3} "
                     f"{r['success']:>7.0%} {r['pedestrian_collision']:>7.0%} "
                     f"{r['world_collision']:>8.0%} {r['timeout']:>7.0%} "
                     f"{r['mean_success_time']:>7.1f}")
    return "\n".join(lines)


def _evaluate(onnx: str, args: argparse.Namespace, out: Path) -> None:
    """``popnavshift evaluate <onnx>`` on ``--evaluate-study`` in ``--evaluate-dir`` (default
    a folder beside the policies), timed, with the machine's load before and after."""
    folder = args.evaluate_dir or out / f"study-{Path(args.evaluate_study).stem}"
    cmd = [sys.executable, "-m", "popnavshift", "evaluate", onnx, "--study",
           args.evaluate_study, "-w", str(args.workers), "-d", str(folder)]
    print("$", " ".join(cmd), f"(load {os.getloadavg()})", flush=True)
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    print(proc.stdout[-3000:], proc.stderr[-2000:], sep="\n", flush=True)
    print(f"evaluate [{Path(onnx).name}]: {time.perf_counter() - start:.0f} s, exit "
          f"{proc.returncode}; load {os.getloadavg()}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("learn-example"))
    ap.add_argument("--study", default="paper", help="study whose cells the policy sees")
    ap.add_argument("--populations", nargs="+", default=["homogeneous", "mixed"],
                    help="training populations (one policy each)")
    ap.add_argument("--expert", default="robot_orca", help="the controller imitated")
    ap.add_argument("--rounds", type=int, default=8, help="DAgger rounds after round 0")
    ap.add_argument("--episodes", type=int, default=50, help="episodes per round")
    ap.add_argument("--epochs", type=int, default=20, help="epochs per fit")
    ap.add_argument("--train-seed", type=int, default=1, help="episode seed of training")
    ap.add_argument("--test-episodes", type=int, default=40,
                    help="study episodes (seed 0) each driver is tested on per population")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--evaluate", action="store_true",
                    help="then run `popnavshift evaluate` on each ONNX file")
    ap.add_argument("--evaluate-study", default="quick")
    ap.add_argument("--evaluate-dir", type=Path, default=None,
                    help="the study folder to evaluate in (e.g. `make run`'s ./study with "
                         "--evaluate-study paper: its runs are reused)")
    ap.add_argument("--evaluate-only", action="store_true",
                    help="no training: evaluate the policy_<population>.onnx files in --out")
    ap.add_argument("--workers", type=int, default=1, help="evaluate's worker processes")
    args = ap.parse_args(argv)
    if args.evaluate_only:
        for population in args.populations:
            _evaluate(str((args.out / f"policy_{population}.onnx").resolve()), args, args.out)
        return 0

    import torch as th

    th.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)
    folder = args.out / f"study-{Path(args.study).stem}"  # its populations table
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()}; torch {th.__version__}", flush=True)
    start = time.perf_counter()
    trained = [train(p, args, folder, args.out) for p in args.populations]
    rows = test({t["population"]: Path(t["onnx"]) for t in trained}, args, folder)
    total = time.perf_counter() - start
    print(_table(rows))
    for t in trained:
        print(f"training time [{t['population']}]: {t['seconds']:.1f} s")
    print(f"total (training and test): {total:.1f} s; load {os.getloadavg()}")
    record = {"args": {k: str(v) for k, v in vars(args).items()}, "trained": trained,
              "test": rows, "total_seconds": total, "load_after": os.getloadavg()}
    (args.out / "train_policy.json").write_text(json.dumps(record, indent=1))
    if args.evaluate:
        for t in trained:
            _evaluate(t["onnx"], args, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
