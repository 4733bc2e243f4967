"""Controller ids: a controller's name and parameters as one string, the ``controller``
column of the run tables.

Controller parameters are part of the controller's identity:
``controller_id("HRVO", {"tau": 0.5})`` is ``'HRVO{"tau":0.5}'``, so two
parameterisations never share a run, and the id is enough to rebuild the controller
(:data:`popnavshift.sim.controllers.CONTROLLERS` parses it). Pure string handling: a
study file is read and planned without the simulator.

A learned policy file is a controller too (:mod:`popnavshift.learn.policy`): its id names
the file by absolute path and content hash (:func:`policy_id`), which only reads the file.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .errors import ConfigError
from .hashing import canonical_json


def controller_id(name: str, params: Mapping[str, Any] | None = None) -> str:
    """The controller column value: ``name``, or ``name`` + canonical JSON of ``params``."""
    if not name or "{" in name:
        raise ConfigError(f"controller name must be non-empty and without '{{', got {name!r}")
    if not params:
        return name
    try:
        json.dumps(dict(params), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"controller {name!r}: parameters must be JSON values: {exc}") from None
    return name + canonical_json(dict(params))


def parse_controller_id(identity: str) -> tuple[str, dict[str, Any]]:
    """Inverse of :func:`controller_id`: ``'HRVO{"tau":0.5}'`` → ``("HRVO", {"tau": 0.5})``."""
    name, brace, rest = identity.partition("{")
    if not brace:
        return identity, {}
    try:
        params = json.loads(brace + rest)
    except json.JSONDecodeError:
        params = None
    if not name or not isinstance(params, dict):
        raise ConfigError(f"controller {identity!r}: expected NAME or NAME{{JSON parameters}}")
    return name, params


#: the controller name of a learned policy file (:mod:`popnavshift.learn.policy`), and the
#: file kinds it runs, by suffix
POLICY = "policy"
POLICY_SUFFIXES: dict[str, str] = {".onnx": "ONNX", ".zip": "Stable-Baselines3"}
#: how many hex digits of the file's sha256 the id keeps (64 bits)
POLICY_HASH_DIGITS = 16


def is_policy_file(spec: str) -> bool:
    """Whether a controller named on the command line is a policy file (``*.onnx``,
    ``*.zip``) rather than a controller name."""
    return "{" not in spec and Path(spec).suffix.lower() in POLICY_SUFFIXES


def file_sha256(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file's bytes, as ``sha256sum`` prints it."""
    h = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def policy_id(spec: str) -> str:
    """The controller id of the policy file ``spec``:
    ``policy{"file":"<absolute path>","sha256":"<first 16 hex digits>"}``. The absolute
    path lets worker processes load the file; the content hash makes a changed file another
    controller (its runs are never taken from the old file's). ConfigError when there is
    no such file."""
    path = Path(spec).expanduser()
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "does not exist"
        raise ConfigError(f"policy file {spec} {what}",
                          hint="give the path of a .onnx file or a Stable-Baselines3 .zip")
    try:
        sha = file_sha256(path)
    except OSError as exc:
        raise ConfigError(f"policy file {spec} cannot be read: {exc.strerror}") from None
    return controller_id(POLICY, {"file": str(path.resolve()),
                                  "sha256": sha[:POLICY_HASH_DIGITS]})


def named_controller(spec: str) -> str:
    """The canonical controller id of a controller as a user names it: a policy file
    (``*.onnx``, ``*.zip``) as :func:`policy_id`, a name with parameters in canonical
    JSON (``HRVO{ "tau": 0.5 }`` → ``HRVO{"tau":0.5}``)."""
    return policy_id(spec) if is_policy_file(spec) else controller_id(
        *parse_controller_id(spec))


def policy_file(identity: str) -> tuple[str, str] | None:
    """(file, sha256 digits) of a policy's id; None when ``identity`` is not a policy's."""
    if not identity.startswith(POLICY + "{"):
        return None
    try:
        name, params = parse_controller_id(identity)
    except ConfigError:
        return None
    file, sha = params.get("file"), params.get("sha256")
    if name != POLICY or not isinstance(file, str) or not isinstance(sha, str):
        return None
    return file, sha


def policy_label(identity: str) -> str | None:
    """How a page names a policy's id: ``policy.onnx (sha256 1a2b3c4d5e6f7a8b)``; None
    when ``identity`` is not a policy's."""
    found = policy_file(identity)
    return None if found is None else f"{Path(found[0]).name} (sha256 {found[1]})"


def display_name(identity: str) -> str:
    """How a page, table or figure names a controller: a policy by its file and hash
    (:func:`policy_label`), never its machine path; any other id as it is."""
    return policy_label(identity) or identity
