"""No upward import: the table declarations import no stage package, and the analysis
never imports the report or the CLI (every import, at module level or in a function)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "popnavshift"


def imported(source: str, module: str) -> set[str]:
    """Dotted names of the popnavshift modules the ``source`` of ``module`` imports."""
    package = module.rsplit(".", 1)[0]
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                names.add(f"{base}.{node.module}" if node.module else base)
            else:
                names.add(node.module or "")
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return {n for n in names if n.startswith("popnavshift")}


def imported_by(path: Path) -> set[str]:
    module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return imported(path.read_text("utf-8"), module)


def test_imports_are_found_in_functions_and_resolved_from_relative_names():
    source = "import numpy\nfrom .delay import x\n\ndef f():\n    from ..report import page\n"
    assert imported(source, "popnavshift.analysis.study") == {
        "popnavshift.analysis.delay", "popnavshift.report"}


def test_the_table_layer_imports_no_stage_package():
    assert imported_by(PACKAGE / "tables.py") == {"popnavshift.errors"}


@pytest.mark.parametrize("path", sorted((PACKAGE / "analysis").glob("*.py")), ids=lambda p: p.name)
def test_the_analysis_never_imports_the_report_or_the_cli(path):
    upward = {n for n in imported_by(path)
              if n.startswith(("popnavshift.report", "popnavshift.cli"))}
    assert not upward, f"{path.name} imports {sorted(upward)}"
