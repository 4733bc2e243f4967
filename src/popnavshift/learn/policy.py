"""Learned policies as controllers: an ONNX file or a Stable-Baselines3 model zip, run as a
navground behaviour (issue #36).

``popnavshift evaluate policy.onnx`` (and ``compare``, ``leaderboard``) names a policy by
its file; the command line turns it into a controller id
(:func:`popnavshift.controller_ids.policy_id`),
``policy{"file":"<absolute path>","sha256":"<16 hex digits>"}``, and the controller
registry makes that id with :class:`PolicyController` (registered as ``policy`` in
:mod:`popnavshift.sim.controllers.builtin`). So a policy is a controller like any other:
the same contract check (:func:`popnavshift.sim.check.check_controller`), the same runs,
cards and cache; worker processes and Ray workers load the file by its absolute path; a
changed file has another hash, so another id and its own runs, and an id whose file has
changed since is refused rather than run with the new file.

The robot runs :class:`PolicyBehavior`, a navground behaviour that observes and acts
exactly as the environment trains (:class:`popnavshift.learn.spaces.PolicySpaces`: the
bounded sensing every controller gets, the observation of 47 values, the action as
fractions of the cell's caps) and asks the policy — a navground-learning
``PolicyPredictor`` — for its action. Inference is deterministic: ONNX Runtime on one
thread, sequential execution, the CPU provider; a Stable-Baselines3 policy with
``deterministic=True`` on one torch thread. Every problem with a file (missing, not a
model, the wrong observation or action shape, a zip without torch installed) is one
:class:`ConfigError` line, raised when the controller is made: before anything runs.
"""

from __future__ import annotations

import inspect
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, SupportsFloat

import numpy as np
from navground import core

from ..controller_ids import POLICY, POLICY_SUFFIXES, controller_id, file_sha256
from ..errors import ConfigError
from ..hashing import digest

LEARN_HINT = "pip install -e '.[learn]'"
try:
    from .spaces import ACTION_SIZE, OBSERVATION_SIZE, PolicySpaces
except ImportError as _exc:  # the learn extra is not installed
    raise ConfigError(f"learned policies need navground-learning ({_exc.name} is not "
                      "installed)", hint=LEARN_HINT) from None

Shape = tuple[int, ...]


class Predictor(Protocol):
    """navground-learning's ``PolicyPredictor``: an observation → (action, state)."""

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]: ...


class PolicyBehavior(core.Behavior):
    """The robot's navground behaviour under a learned policy: at each step the observation
    of :class:`.spaces.PolicySpaces` from its bounded sensing (a ``GeometricState``, which
    the world fills as for every controller), the policy's deterministic action, and the
    feasible command of that action. Not registered as a navground type: it needs its
    policy (:class:`PolicyController` builds it)."""

    def __init__(self, kinematics: core.Kinematics | None = None, radius: float = 0.0,
                 policy: Predictor | None = None) -> None:
        super().__init__(kinematics, radius)
        self._state = core.GeometricState()
        self._policy = policy
        self._spaces: PolicySpaces | None = None  # made on the first command: the caps

    def get_environment_state(self) -> core.EnvironmentState:
        return self._state

    def compute_cmd_internal(self, time_step: SupportsFloat) -> core.Twist2:
        if self._policy is None:
            raise ConfigError("PolicyBehavior has no policy")
        if self._spaces is None:
            self._spaces = PolicySpaces(self)
        observation = self._spaces.observe(self, self._state)
        action, _ = self._policy.predict(observation, deterministic=True)
        return self._spaces.command(action, self, float(time_step))


def policy_shapes() -> tuple[Shape, Shape]:
    """The (observation, action) shapes of a PopNavShift policy (:mod:`.spaces`)."""
    return (OBSERVATION_SIZE,), (ACTION_SIZE,)


class OnnxPredictor:
    """An ONNX Runtime session as navground-learning's ``PolicyPredictor``: one observation
    (batched as 1) → one action. One thread, sequential: the same action in every
    process for the same observation."""

    def __init__(self, path: Path) -> None:
        try:
            import onnxruntime as ort  # type: ignore[import-untyped]
        except ImportError:
            raise ConfigError(f"policy file {path}: running an ONNX policy needs onnxruntime",
                              hint=LEARN_HINT) from None
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 3  # errors only: they are ours to word
        try:
            self.session = ort.InferenceSession(str(path), options,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime's own InvalidProtobuf, Fail, InvalidGraph…
            raise ConfigError(f"policy file {path} is not an ONNX model onnxruntime can run: "
                              f"{_first_line(exc)}") from None
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            raise ConfigError(f"policy file {path} has {len(inputs)} inputs "
                              f"({', '.join(x.name for x in inputs)}); a policy takes one, "
                              "the observation")
        self.input = inputs[0].name
        self.input_shape = list(inputs[0].shape)
        dtype = {"tensor(float)": np.float32, "tensor(double)": np.float64}.get(inputs[0].type)
        if dtype is None:
            raise ConfigError(f"policy file {path}: its input {self.input!r} is "
                              f"{inputs[0].type}; a policy observes floats")
        self.dtype = dtype
        self.output = self.session.get_outputs()[0].name

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        x = np.asarray(observation, dtype=self.dtype)[np.newaxis]
        y = np.asarray(self.session.run([self.output], {self.input: x})[0])
        return (y[0] if y.ndim > 1 and y.shape[0] == 1 else y).astype(np.float32), None

    def check(self, path: Path, obs: Shape, act: Shape) -> None:
        """ConfigError unless the model takes a (batch, *obs) input and gives a (batch,
        *act) output: its declared shape, then a trial on a zero observation."""
        declared = self.input_shape[1:]
        fixed_batch = isinstance(self.input_shape[0], int) and self.input_shape[0] != 1 if \
            self.input_shape else True
        if fixed_batch or len(declared) != len(obs) or any(
                isinstance(d, int) and d != n for d, n in zip(declared, obs, strict=True)):
            raise ConfigError(
                f"policy file {path}: its input {self.input!r} has shape "
                f"{_shape(self.input_shape)}; a PopNavShift policy observes {_shape(obs)} "
                "values per step, as (batch, values)", hint=SPACES_HINT)
        try:
            action, _ = self.predict(np.zeros(obs))
        except Exception as exc:
            raise ConfigError(f"policy file {path}: onnxruntime failed on an observation of "
                              f"shape {_shape(obs)}: {_first_line(exc)}") from None
        if action.shape != act:
            raise ConfigError(f"policy file {path} outputs {_shape(action.shape)} values per "
                              f"step; a PopNavShift action is {_shape(act)}", hint=SPACES_HINT)


SPACES_HINT = ("train it on popnavshift.learn's environment, whose observation and action "
               "are popnavshift.learn.spaces' (docs/learning.md)")
class SB3Predictor:
    """The policy of a Stable-Baselines3 model zip (``model.save``, any algorithm) as a
    ``PolicyPredictor``: deterministic actions, on one torch thread. Only the policy is
    rebuilt (its class, spaces and keyword arguments as the zip records them, and its
    weights), not the algorithm."""

    def __init__(self, path: Path) -> None:
        try:
            import torch
            from stable_baselines3.common.save_util import load_from_zip_file
        except ImportError as exc:
            raise ConfigError(f"policy file {path} is a Stable-Baselines3 model zip: running "
                              f"it needs torch and stable-baselines3 ({exc.name} is not "
                              "installed)", hint=LEARN_HINT) from None
        if not zipfile.is_zipfile(path):
            raise ConfigError(f"policy file {path} is not a Stable-Baselines3 model zip (not "
                              "a zip archive)", hint="save the model with model.save(path)")
        torch.set_num_threads(1)
        try:
            data, params, _ = load_from_zip_file(path, device="cpu", print_system_info=False)
            if data is None:
                raise ValueError("no 'data' record")
            cls = data["policy_class"]
            kwargs = dict(data.get("policy_kwargs") or {})
            if "use_sde" in data and "use_sde" in inspect.signature(cls).parameters:
                kwargs.setdefault("use_sde", data["use_sde"])
            self.policy = cls(data["observation_space"], data["action_space"],
                              lambda _: 0.0, **kwargs)
            self.policy.load_state_dict(params["policy"])
        except Exception as exc:  # a zip model.save did not write, or of another version
            raise ConfigError(f"policy file {path} is not a Stable-Baselines3 model zip it can "
                              f"load: {type(exc).__name__}: {_first_line(exc)}",
                              hint="save the model with model.save(path)") from None
        self.policy.set_training_mode(False)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        action, _ = self.policy.predict(np.asarray(observation, dtype=np.float32),
                                        deterministic=True)
        return np.asarray(action, dtype=np.float32), None

    def check(self, path: Path, obs: Shape, act: Shape) -> None:
        got = (self.policy.observation_space.shape, self.policy.action_space.shape)
        if got != (obs, act):
            raise ConfigError(f"policy file {path} observes {_shape(got[0])} values and acts "
                              f"{_shape(got[1])}; a PopNavShift policy observes {_shape(obs)} "
                              f"and acts {_shape(act)}", hint=SPACES_HINT)


#: the predictors loaded in this process, by file and content hash: a study makes the
#: controller once per run
_LOADED: dict[tuple[str, str], OnnxPredictor | SB3Predictor] = {}
_KINDS: dict[str, Callable[[Path], OnnxPredictor | SB3Predictor]] = {
    "ONNX": OnnxPredictor, "Stable-Baselines3": SB3Predictor}


def load_predictor(path: Path, sha256: str) -> OnnxPredictor | SB3Predictor:
    """The checked predictor of the policy file ``path`` whose hex sha256 is ``sha256``."""
    key = (str(path), sha256)
    if key not in _LOADED:
        predictor = _KINDS[POLICY_SUFFIXES[path.suffix.lower()]](path)
        predictor.check(path, *policy_shapes())
        _LOADED[key] = predictor
    return _LOADED[key]


def spaces_stamp() -> str:
    """A digest of :mod:`.spaces`' source: the observation and action a policy runs under
    are part of its description, so editing them reruns a policy's runs (the code stamp
    covers only this module's source)."""
    from . import spaces

    return digest(inspect.getsource(spaces))[:16]


class PolicyController:
    """Controller factory of a policy file (module doc); ``file`` an absolute path,
    ``sha256`` the first hex digits of its sha256 (its id's parameters)."""

    def __init__(self, file: str = "", sha256: str = "") -> None:
        if not file or not sha256:
            raise ConfigError("controller 'policy' needs its file and hash",
                              hint="name a policy by its file: popnavshift evaluate "
                                   "policy.onnx")
        path = Path(file)
        kind = POLICY_SUFFIXES.get(path.suffix.lower())
        if kind is None:
            raise ConfigError(f"policy file {file} is neither .onnx nor .zip")
        if not path.is_file():
            raise ConfigError(f"policy file {file} does not exist",
                              hint="a policy's id names its file by absolute path: evaluate "
                                   "the file where it is now")
        actual = file_sha256(path)
        if len(sha256) < 8 or not actual.startswith(sha256.lower()):
            raise ConfigError(f"policy file {file} has changed: its sha256 begins "
                              f"{actual[:16]}, the controller id says {sha256}",
                              hint=f"evaluate the new file as a new controller: popnavshift "
                                   f"evaluate {file}")
        self.name = controller_id(POLICY, {"file": file, "sha256": sha256})
        self.file, self.kind, self.sha256 = path, kind, actual
        self.predictor = load_predictor(path, actual)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        behavior = PolicyBehavior(kinematics, radius, self.predictor)
        behavior.optimal_speed = speed
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        """Nothing: the behaviour configures itself on its first command."""

    def describe(self) -> dict[str, Any]:
        return {"controller": POLICY, "file": self.file.name, "path": str(self.file),
                "sha256": self.sha256, "format": self.kind, "spaces": spaces_stamp()}


def _shape(shape: Any) -> str:
    """``35`` for one axis, ``(batch, 35)`` for several."""
    dims = ["batch" if not isinstance(d, int) else str(d) for d in shape]
    return dims[0] if len(dims) == 1 else "(" + ", ".join(dims) + ")"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0][:300]
