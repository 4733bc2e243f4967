"""A Gymnasium environment on a study's worlds: the robot in one of its episodes, the
pedestrians drawn from one of its populations.

``make_env(study, population, folder=...)`` (or ``gymnasium.make("PopNavShift-v0", ...)``)
gives a :class:`PopNavShiftEnv`. Each episode is one run of the study, simulated by the
study's own :func:`popnavshift.sim.run.simulate` — the same world (``sim/world.py``),
pedestrian backend and response layer, the same stepping loop, the same outcome rules
and metrics — with a robot whose command comes from :meth:`PopNavShiftEnv.step`.

* **Episode.** ``reset(seed=s)`` picks one of the study part's episodes (cells × variants)
  with the environment's generator seeded by ``s`` (or ``options={"episode": id}`` names
  it); the episode itself is drawn with the *study's* seed (``get_episode(id,
  seed=study.seed)``; ``episode_seed=k`` draws another seed set of the same cells) and
  its slots are filled from the population's members as the
  study's workers fill them (:func:`popnavshift.engine.rebuild.population_members`,
  :func:`popnavshift.sim.slots.profiles_of_members`). So an episode with the study's id
  is the study's run of that id, pedestrian for pedestrian.
* **Observation / action.** :mod:`.spaces` (47 values in [-1, 1]; 2 values in [-1, 1]).
  ``step(None)`` lets the *expert* act: the navground controller ``expert`` (by default
  ``robot_orca``), computed every step on the same sensed state; ``info["navground_action"]``
  always holds the expert's action for the returned observation (navground-learning's
  key), for imitation.
* **Reward** (:class:`Reward`): metres of progress towards the goal this step, minus a
  small cost per step; on the step that ends the robot's run, a bonus for success and a
  penalty for a collision (the run's outcome as the study records it).
* **End.** ``terminated`` when the robot's run ends (success or a collision: the study's
  outcome rules), ``truncated`` at the study's 45 s limit (outcome ``timeout``). The last
  ``info["run"]`` is the run's row (the columns of ``runs.parquet`` that ``simulate``
  writes: outcome, robot time, path, minimum distance, …) and ``info["pedestrians"]`` its
  pedestrians' columns, computed once the pedestrians have left, as in the study.

How it runs: ``simulate`` runs in a worker thread; the robot's behaviour
(:class:`GymBehavior`, a navground ``Behavior`` wrapping the expert's) hands each
observation to :meth:`PopNavShiftEnv.step` and waits for its action, so exactly one of
the two threads runs at a time and an episode is as deterministic as the study's runs.
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from navground import core

from ..design.plan import select_episodes
from ..design.study import Study, load_study
from ..engine.rebuild import member_arrays, population_members
from ..episodes.specs import EpisodeSpec, all_episodes, get_episode
from ..errors import ConfigError, InputError
from ..sim.constants import ROBOT_GOAL_TOLERANCE, ROBOT_RADIUS, WHEEL_AXIS
from ..sim.run import SimResult, resolve_controller, simulate
from ..sim.slots import profiles_of_members
from .spaces import PolicySpaces

ENV_ID = "PopNavShift-v0"


@dataclass(frozen=True)
class Reward:
    """The reward of one step: ``progress`` × metres of progress towards the goal
    (distance at the previous decision minus now; on the success step, the rest of the
    way into the goal disc), plus ``step`` (a cost per 0.1 s), plus, on the step that
    ends the robot's run, ``success`` or ``pedestrian_collision`` / ``world_collision``.
    A timeout adds nothing (the episode is truncated)."""

    progress: float = 1.0
    step: float = -0.01
    success: float = 10.0
    pedestrian_collision: float = -10.0
    world_collision: float = -5.0

    def outcome(self, outcome: str) -> float:
        return float(getattr(self, outcome, 0.0)) if outcome != "step" else 0.0


class _Aborted(Exception):
    """The environment abandoned the episode (reset or close): end its simulation."""


class _Episode:
    """One run of :func:`simulate` in a worker thread, stepped by the environment.

    Messages to the environment: ``("obs", observation, expert action, distance to the
    goal)`` before each robot decision, then ``("end", SimResult)`` or ``("error", exc)``.
    """

    def __init__(self, spec: EpisodeSpec, slots, expert, backend: str, record: bool) -> None:
        self.actions: queue.Queue = queue.Queue(maxsize=1)
        self.events: queue.Queue = queue.Queue(maxsize=1)
        self.factory = _GymController(expert, self)
        self.thread = threading.Thread(target=self._simulate, args=(spec, slots, backend, record),
                                       name="popnavshift-env", daemon=True)
        self.thread.start()

    def _simulate(self, spec: EpisodeSpec, slots, backend: str, record: bool) -> None:
        try:
            result = simulate(spec, slots, self.factory, backend, record=record, stretches=False)
        except BaseException as exc:  # handed to the environment's thread
            self.events.put(("error", exc))
            return
        self.events.put(("end", result))

    def decide(self, obs: np.ndarray, expert: np.ndarray, distance: float) -> Any:
        """In the simulation thread: hand over the observation, wait for the action."""
        self.events.put(("obs", obs, expert, distance))
        action = self.actions.get()
        if action is _ABORT:
            raise _Aborted
        return action

    def abort(self) -> None:
        """End the simulation (it raises in the robot's behaviour) and wait for it."""
        while self.thread.is_alive():
            with contextlib.suppress(queue.Full):
                self.actions.put_nowait(_ABORT)
            with contextlib.suppress(queue.Empty):
                self.events.get(timeout=0.05)
        self.thread.join()


_ABORT = object()


class GymBehavior(core.Behavior):
    """The robot's behaviour in the environment: it wraps the expert controller's
    behaviour (``inner``, which shares its sensed state), and each step computes the
    expert's command, hands the observation to the environment and actuates its action
    (or the expert's command for ``None``). After the robot's run has ended (the stepping
    loop set a Stop target: arrived or stopped by a collision) it no longer asks. Not
    registered as a navground type (a listing of navground's behaviours, as the
    leaderboard's, must not offer it: it runs only inside the environment)."""

    def __init__(self, kinematics: core.Kinematics | None = None, radius: float = 0.0) -> None:
        core.Behavior.__init__(self, kinematics, radius)
        self.inner: core.Behavior | None = None
        self.inner_target: core.Target | None = None
        self.episode: _Episode | None = None
        self.spaces: PolicySpaces | None = None
        self.goal = np.zeros(2)
        self.over = False

    def get_environment_state(self) -> core.EnvironmentState:
        assert self.inner is not None
        return self.inner.environment_state

    def compute_cmd_internal(self, time_step: SupportsFloat) -> core.Twist2:
        inner, episode, spaces = self.inner, self.episode, self.spaces
        assert inner is not None and episode is not None and spaces is not None
        inner.set_state_from(self)
        if self.over or self.target.position is None:  # the loop's Stop: stop as the expert
            self.over = True
            return inner.compute_cmd(float(time_step))
        inner.target = self.inner_target or self.target  # the expert's own (symmetry-broken)
        cmd = inner.compute_cmd(float(time_step))
        state = inner.environment_state
        assert isinstance(state, core.GeometricState)
        obs = spaces.observe(self, state)
        distance = math.dist(self.position, self.goal) - ROBOT_GOAL_TOLERANCE
        action = episode.decide(obs, spaces.action(cmd, self), distance)
        if action is None:
            return cmd
        return spaces.command(action, self, float(time_step))


class _GymController:
    """The controller factory of the environment's robot (the study's contract:
    ``build`` / ``after_placement``): a :class:`GymBehavior` around the expert's."""

    sensing = True

    def __init__(self, expert, episode: _Episode) -> None:
        self.expert, self.name = resolve_controller(expert)
        self.name = f"gym:{self.name}"
        self.episode = episode

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        inner = self.expert.build(kinematics, radius, speed)
        behavior = GymBehavior(kinematics, radius)
        behavior.set_state_from(inner)  # the expert's speeds, horizon, margin, heading
        behavior.inner = inner
        behavior.episode = self.episode
        return behavior

    def after_placement(self, behavior: GymBehavior, dt: float) -> None:
        inner = behavior.inner
        assert inner is not None
        inner.set_state_from(behavior)
        self.expert.after_placement(inner, dt)
        behavior.inner_target = inner.target
        behavior.goal = np.array(behavior.target.position, dtype=float)
        behavior.spaces = PolicySpaces(behavior)

    def describe(self) -> dict[str, Any]:
        return {"expert": self.expert.describe() if hasattr(self.expert, "describe") else {}}


def _unit_spaces() -> PolicySpaces:
    """The spaces of a robot at 1 m/s (the bounds are the same at every speed)."""
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0,
                                                              wheel_axis=WHEEL_AXIS)
    return PolicySpaces(core.Behavior(kin, ROBOT_RADIUS))


class PopNavShiftEnv(gym.Env):
    """See the module's documentation; made by :func:`make_env`."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, study: Study, members: tuple[np.ndarray, list[str]],
                 episodes: list[str], *, population: str, expert: str = "robot_orca",
                 backend: str = "orca", reward: Reward | None = None,
                 record: bool = False, episode_seed: int | None = None) -> None:
        self.study, self.members, self.episode_ids = study, members, list(episodes)
        self.population, self.expert, self.backend = population, expert, backend
        self.reward_spec = reward or Reward()
        self.record = record
        #: the seed the episodes are drawn with: the study's (its runs), or another
        #: seed set of the same cells (e.g. to train on other worlds than a study tests on)
        self.episode_seed = study.seed if episode_seed is None else int(episode_seed)
        resolve_controller(expert)  # an unknown expert fails here
        spaces = _unit_spaces()
        self.observation_space = spaces.observation_space
        self.action_space = spaces.action_space
        self._episode: _Episode | None = None
        self._distance = 0.0
        self._spec: EpisodeSpec | None = None

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._abandon()
        episode = (options or {}).get("episode")
        if episode is None:
            episode = self.episode_ids[int(self.np_random.integers(len(self.episode_ids)))]
        spec = get_episode(str(episode), seed=self.episode_seed)
        slots = profiles_of_members(spec, *self.members)
        self._spec = spec
        self._episode = _Episode(spec, slots, self.expert, self.backend, self.record)
        msg = self._episode.events.get()
        if msg[0] != "obs":  # the run ended before the robot's first decision
            self._episode = None
            self._raise(msg)
            raise RuntimeError(f"episode {spec.id}: the robot never had to decide")
        _, obs, expert, self._distance = msg
        return obs, self._info(expert)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._episode is None:
            raise gym.error.ResetNeeded("call reset() before step(): the episode is over")
        if action is not None:
            action = np.asarray(action, dtype=np.float32).reshape(-1)
            if action.shape != (2,) or not np.all(np.isfinite(action)):
                raise ValueError(f"action must be 2 finite numbers, got {action!r}")
        self._episode.actions.put(action)
        msg = self._episode.events.get()
        rw = self.reward_spec
        if msg[0] == "obs":
            _, obs, expert, distance = msg
            reward = rw.progress * (self._distance - distance) + rw.step
            self._distance = distance
            return obs, reward, False, False, self._info(expert)
        self._episode.thread.join()
        self._episode = None
        self._raise(msg)
        result: SimResult = msg[1]
        outcome = str(result.run["outcome"])
        reward = rw.step + rw.outcome(outcome)
        if outcome == "success":
            reward += rw.progress * self._distance
        info = {**self._info(np.zeros(2, np.float32)), "run": result.run, "outcome": outcome,
                "is_success": outcome == "success", "pedestrians": result.ped_columns}
        if result.trajectory is not None:
            info["trajectory"] = result.trajectory
        obs = np.zeros(self.observation_space.shape, np.float32)
        return obs, reward, outcome != "timeout", outcome == "timeout", info

    def _info(self, expert: np.ndarray) -> dict[str, Any]:
        assert self._spec is not None
        return {"episode": self._spec.id, "population": self.population,
                "navground_action": expert}

    @staticmethod
    def _raise(msg: tuple) -> None:
        if msg[0] == "error":
            raise msg[1]

    def _abandon(self) -> None:
        if self._episode is not None:
            self._episode.abort()
            self._episode = None

    def close(self) -> None:
        self._abandon()
        super().close()


def make_env(study: str | Path | Study = "quick", population: str = "homogeneous", *,
             folder: str | Path, mapping: str = "A", part: str | None = None,
             episodes: list[str] | None = None, **kwargs: Any) -> PopNavShiftEnv:
    """The environment on ``study``'s ``part`` (its main part by default) under
    ``population`` (profile set ``mapping``), its members read from ``folder``'s
    populations table — built there with the study's settings if it is missing, as
    ``popnavshift simulate`` does. ``episodes`` narrows the episode ids (default: every
    episode of the part). Other keywords: :class:`PopNavShiftEnv` (``expert``,
    ``backend``, ``reward``, ``record``, ``episode_seed``: draw the same cells and
    variants with another seed than the study's)."""
    st = study if isinstance(study, Study) else load_study(study)
    if part is None:
        part = st.require_main()[0]
    if part not in st.parts:
        raise ConfigError(f"study {st.name!r} has no part {part!r}",
                          hint=f"parts: {', '.join(st.parts)}")
    ids = [e.id for e in select_episodes(st.parts[part].episodes, all_episodes(st.seed))]
    if episodes is not None:
        unknown = sorted(set(episodes) - set(ids))
        if unknown:
            raise ConfigError(f"episode {unknown[0]!r} is not in part {part!r} of {st.name!r}")
        ids = list(episodes)
    if not ids:
        raise ConfigError(f"part {part!r} of study {st.name!r} has no episodes")
    pops = _populations(st, Path(folder))
    try:
        members = member_arrays(population_members(pops, mapping, population))
    except InputError:
        raise ConfigError(f"{folder}/populations.parquet has no population {population!r} "
                          f"for profile set {mapping!r}") from None
    return PopNavShiftEnv(st, members, ids, population=population, **kwargs)


def _populations(study: Study, folder: Path):
    """``folder``'s populations table, its stages run first with ``study``'s settings
    when the table is missing."""
    from ..engine.lock import study_lock
    from ..engine.runner import population_settings, run_stages
    from ..pipeline import read_table

    if not (folder / "populations.parquet").exists():
        folder.mkdir(parents=True, exist_ok=True)
        with study_lock(folder):
            run_stages(folder, population_settings(study), False)
    return read_table(folder / "populations.parquet", "populations")


if ENV_ID not in gym.registry:
    gym.register(ENV_ID, entry_point="popnavshift.learn.env:make_env")
