"""Learned policies: the observation and action of a PopNavShift policy (:mod:`.spaces`)
and a Gymnasium environment on a study's worlds and populations (:mod:`.env`).

Needs the learning dependencies (navground-learning, Gymnasium; ONNX Runtime to run an
exported policy): ``pip install -e '.[learn]'`` (``make install-dev`` installs the light
ones; torch and Stable-Baselines3 only come with ``[learn]``). See docs/learning.md.
"""
