"""Learning: PopNavShift's worlds as a Gymnasium environment and learned policies
(ONNX, Stable-Baselines3) as controllers (issue #36). Needs the ``learn`` extra's
packages; nothing here is imported until used."""
