"""Tiny learned policies made in the tests (no download, no torch): an ONNX graph built
with ``onnx.helper`` that maps the observation of :mod:`popnavshift.learn.spaces` linearly
to an action heading for the goal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper


def observation_layout() -> tuple[int, int, dict[str, slice]]:
    """(observation size, action size, the flat observation's slice of each field), from
    :mod:`popnavshift.learn.spaces`."""
    from popnavshift.learn.spaces import ACTION_SIZE, OBSERVATION_SIZE
    from popnavshift.learn.spaces import observation_layout as fields

    layout, start = {}, 0
    for key, n in fields():
        layout[key] = slice(start, start + n)
        start += n
    assert start == OBSERVATION_SIZE
    return start, ACTION_SIZE, layout


def goal_weights(forward: float = 0.8, turn: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """(W, b) of ``action = observation @ W + b``: forward speed and turn from the goal's
    direction in the robot's frame (cos, sin) — it heads for the goal, ignoring people."""
    n_obs, n_act, layout = observation_layout()
    direction = layout["ego_target_direction"]
    w = np.zeros((n_obs, n_act), dtype=np.float32)
    w[direction.start, 0] = forward  # cos of the goal's bearing: ahead → forward
    w[direction.start + 1, 1] = turn  # sin of the goal's bearing: turn towards it
    return w, np.zeros(n_act, dtype=np.float32)


def linear_onnx(path: Path, w: np.ndarray, b: np.ndarray, *, input_name: str = "observation",
                n_inputs: int | None = None) -> Path:
    """Write an ONNX model ``clip(x @ w + b, -1, 1)`` with input (batch, n_inputs or
    w's rows) to ``path``."""
    n_in = w.shape[0] if n_inputs is None else n_inputs
    graph = helper.make_graph(
        [helper.make_node("MatMul", [input_name, "W"], ["xw"]),
         helper.make_node("Add", ["xw", "B"], ["raw"]),
         helper.make_node("Clip", ["raw", "LO", "HI"], ["action"])],
        "linear_policy",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, ["batch", n_in])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", w.shape[1]])],
        [numpy_helper.from_array(w, "W"), numpy_helper.from_array(b, "B"),
         numpy_helper.from_array(np.array(-1, np.float32), "LO"),
         numpy_helper.from_array(np.array(1, np.float32), "HI")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    path.write_bytes(model.SerializeToString())
    return path


def goal_policy(path: Path, **weights: float) -> Path:
    """The goal-seeking linear policy (:func:`goal_weights`) as an ONNX file."""
    return linear_onnx(path, *goal_weights(**weights))
