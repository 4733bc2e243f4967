"""Follow a recipe of docs/architecture.md ("Where to add") literally: a copy of the
package with the recipe's edits, imported by a fresh interpreter.

A recipe test proves the recipe is complete: the edits it lists are the only ones made,
and what they add reaches the tables or the report. Each edit names an anchor that must
occur exactly once, so a recipe whose anchor moved fails loudly instead of going stale.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
SRC = TESTS.parent / "src"

Edits = dict[str, list[tuple[str, str]]]  # module path under popnavshift/ → (anchor, text)


def package_with(tmp: Path, edits: Edits) -> Path:
    """A copy of ``src/popnavshift`` under ``tmp/src`` with each anchor replaced by its
    text (the anchor kept when the text starts with it). Returns ``tmp/src``."""
    root = tmp / "src"
    shutil.copytree(SRC / "popnavshift", root / "popnavshift",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for module, changes in edits.items():
        path = root / "popnavshift" / module
        text = path.read_text(encoding="utf-8") if path.exists() else ""
        for anchor, new in changes:
            if anchor:
                assert text.count(anchor) == 1, f"{module}: anchor {anchor!r} not there once"
                text = text.replace(anchor, new)
            else:
                text += new
        path.write_text(text, encoding="utf-8")
    with_numba_caches(root)
    return root


def with_numba_caches(root: Path) -> None:
    """Seed the copy under ``root`` with the source tree's numba caches, so that its study
    does not compile the simulator's kernels again (~30 s): numba checks each kernel's
    source file stamp, which the copy keeps, so a module a recipe edits is compiled anew."""
    for cached in SRC.rglob("__pycache__/*.nb[ic]"):
        target = root / cached.relative_to(SRC)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, target)


def run_with(root: Path, code: str, cwd: Path | None = None) -> str:
    """Run ``code`` in a fresh interpreter that imports the package under ``root`` (and
    the test helpers); its stdout. Fails with its stderr when it fails."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(TESTS)])}
    check = f"import popnavshift; assert popnavshift.__file__.startswith({str(root)!r})\n"
    out = subprocess.run([sys.executable, "-c", check + code], env=env, cwd=cwd,
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-4000:]
    return out.stdout
