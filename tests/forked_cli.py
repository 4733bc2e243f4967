"""Run ``popnavshift`` in a forked child of the test process: a real process (its own exit
code, stdout and stderr, what a user sees) without Python's start-up and imports, so a
fuzz test can afford hundreds of command lines. Where ``fork`` does not exist the command
runs as a fresh subprocess instead."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import popnavshift.cli  # noqa: F401  (imported once, before any fork)
import popnavshift.design.plan  # noqa: F401
import popnavshift.design.study  # noqa: F401
import popnavshift.engine.validate  # noqa: F401
from popnavshift.episodes.specs import all_episodes

all_episodes(0)  # drawn once (cached): every child's plan reads it


def run_cli(*args: str, cwd: Path | None = None,
            timeout: float = 120) -> subprocess.CompletedProcess:
    """``popnavshift *args`` in a child process; a hang past ``timeout`` s is killed and
    reported as exit code -9."""
    if not hasattr(os, "fork"):  # pragma: no cover - Windows
        return subprocess.run([sys.executable, "-m", "popnavshift", *args], cwd=cwd,
                              capture_output=True, text=True, timeout=timeout)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child: never returns
            _child(args, cwd, out.fileno(), err.fileno())
        code = _wait(pid, timeout)
        out.seek(0)
        err.seek(0)
        return subprocess.CompletedProcess(
            ["popnavshift", *args], code, out.read().decode("utf-8", "replace"),
            err.read().decode("utf-8", "replace"))


def _child(args: tuple[str, ...], cwd: Path | None, out: int,
           err: int) -> None:  # pragma: no cover
    code = 1
    try:
        os.dup2(out, 1)
        os.dup2(err, 2)
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), "utf-8",
                                      line_buffering=True)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), "utf-8",
                                      line_buffering=True)
        if cwd is not None:
            os.chdir(cwd)
        sys.argv = ["popnavshift", *args]
        from popnavshift.cli import main

        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # what Python itself would do: a traceback and exit 1
        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _wait(pid: int, timeout: float) -> int:
    deadline = time.monotonic() + timeout
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            return -9
        time.sleep(0.01)
