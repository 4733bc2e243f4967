"""The package's layering (docs/architecture.md), checked on the source: no import
cycle between modules and no import from a lower layer into a higher one, lazy
imports (inside functions) included."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "src" / "popnavshift"

#: bottom to top: a module may import its own layer's modules and lower layers only
LAYERS: tuple[frozenset[str], ...] = (
    frozenset({"errors", "version", "hashing", "redact", "registry", "progress", "io", "strict",
               "outputs"}),
    frozenset({"table_spec"}),
    frozenset({"tables", "paper", "controller_ids", "result_tables"}),
    frozenset({"personas", "episodes", "viz", "dictionary"}),
    frozenset({"responses", "profiles"}),
    frozenset({"populations"}),
    frozenset({"design"}),
    frozenset({"pipeline"}),
    frozenset({"read"}),
    frozenset({"analysis"}),
    # the simulator and the engine sit above the read side: reading and analysing a
    # finished study folder never imports them (nor navground)
    frozenset({"sim"}),
    frozenset({"engine"}),
    frozenset({"report", "evaluate", "learn"}),
    frozenset({"cli"}),
    frozenset({"__main__", ""}),  # "" = the package's __init__
)


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _imports(module: str) -> set[str]:
    """The package modules ``module`` imports, anywhere in its source."""
    path = MODULES[module]
    return _imported(path.read_text(encoding="utf-8"), module, path.name == "__init__.py")


def _imported(source: str, module: str, is_package: bool = False) -> set[str]:
    """The package modules ``source`` (the text of ``module``) imports, at module level
    or inside functions, relative names resolved."""
    package = module if is_package else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if not (node.module or "").startswith("popnavshift"):
                    continue
                base = node.module.removeprefix("popnavshift").lstrip(".")
            else:
                parts = package.split(".") if package else []
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join(parts + ([node.module] if node.module else []))
            for alias in node.names:
                name = f"{base}.{alias.name}" if base else alias.name
                found.add(name if name in MODULES else base)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("popnavshift"):
                    found.add(alias.name.removeprefix("popnavshift").lstrip("."))
    return {m for m in found if m in MODULES and m != module}


GRAPH = {m: _imports(m) for m in MODULES}


def _layer(module: str) -> int:
    top = module.partition(".")[0]
    for i, members in enumerate(LAYERS):
        if top in members:
            return i
    raise AssertionError(f"popnavshift.{top} belongs to no layer: add it to LAYERS")


def test_every_module_has_a_layer():
    for module in MODULES:
        _layer(module)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_imports_from_a_higher_layer(module):
    upward = sorted(t for t in GRAPH[module] if _layer(t) > _layer(module))
    assert not upward, f"popnavshift.{module} imports from a higher layer: {upward}"


def test_no_import_cycle():
    """Tarjan's strongly connected components of the module graph: all singletons."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in GRAPH:
        if module not in index:
            visit(module)
    assert not cycles, f"import cycles: {cycles}"


def test_the_checker_sees_relative_and_lazy_imports():
    source = ("import numpy\nfrom .delay import x\nfrom ..tables import PARAMS\n"
              "def f():\n    from ..report import page\n    import popnavshift.cli.app\n")
    assert _imported(source, "analysis.study") == {"analysis.delay", "tables", "report.page",
                                                   "cli.app"}
    assert _imported("from . import builtin", "sim.controllers", is_package=True) == {
        "sim.controllers.builtin"}


#: STYLE.md habit 9: modules under ~400 lines. A module may exceed it only when listed
#: here with the reason; the list is short on purpose.
MAX_LINES = 400
OVERSIZE: dict[str, str] = {}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_modules_stay_under_the_size_limit(module):
    lines = len(MODULES[module].read_text(encoding="utf-8").splitlines())
    limit = MAX_LINES if module not in OVERSIZE else float("inf")
    assert lines <= limit, (f"popnavshift.{module} has {lines} lines (limit {MAX_LINES}): "
                            "split it by concern, or list it in OVERSIZE with the reason")


def test_the_size_allow_list_names_only_oversize_modules():
    """An entry whose module shrank below the limit is stale: remove it."""
    stale = [m for m in OVERSIZE
             if m not in MODULES or len(MODULES[m].read_text("utf-8").splitlines()) <= MAX_LINES]
    assert not stale, f"OVERSIZE lists modules within the limit: {stale}"


def test_no_test_module_imports_another():
    """Shared fixtures and helpers live in plain helper modules (docs/architecture.md,
    Tests), so running one test module never runs, or depends on, another."""
    tests = Path(__file__).resolve().parent
    found = []
    for path in sorted(tests.glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{path.name}: {n}" for n in names if n.startswith("test_")]
    assert found == []
