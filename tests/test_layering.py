"""The layering of DESIGN.md, read from the source: core/ is pure numerics and the project's
modules import each other one way only (no cycle)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "tasks", "flows")
# what core/ may import besides the standard library and itself: array numerics and the
# kernel libraries made for this field that take and return NumPy arrays
CORE_ALLOWED = {"numpy", "scipy", "cv2", "numba"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (REPO / pkg).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Every module ``name`` imports, anywhere in the file (function-level imports included)."""
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = name.split(".")
                parent = parent if is_pkg else parent[:-1]
                parent = parent[: len(parent) - (node.level - 1)]
                base = ".".join(parent + ([base] if base else []))
            for a in node.names:  # "from pkg import module" imports the module
                found.add(f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base)
    return found


GRAPH = {name: {m for m in _imports(name, path) if m in MODULES} for name, path in MODULES.items()}


def test_the_module_list_is_complete():
    assert {"core.geodesy", "core.sensors.pushbroom", "tasks.simulate.scene", "flows.cli"} <= set(MODULES)


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n.split(".")[0] == "core"))
def test_core_imports_no_io_no_orchestration_and_nothing_above_it(name: str):
    bad = sorted(
        m for m in _imports(name, MODULES[name])
        if m.split(".")[0] not in sys.stdlib_module_names | CORE_ALLOWED | {"core", "__future__"}
    )
    assert not bad, f"{name} imports {bad}: core/ is NumPy/SciPy numerics (no I/O, no Dask, " \
        "no Prefect, nothing from tasks/ or flows/)"


def test_tasks_do_not_import_flows():
    bad = {n: sorted(m for m in deps if m.startswith("flows")) for n, deps in GRAPH.items()
           if n.startswith("tasks")}
    assert not any(bad.values()), bad


def test_no_import_cycle():
    """Tarjan's strongly connected components: every component must be a single module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(GRAPH[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(GRAPH)))
    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_the_checker_sees_a_cycle_and_a_forbidden_import(tmp_path: Path):
    """The rules above can fail: a planted cycle and a planted rasterio import are caught."""
    global GRAPH
    saved = GRAPH
    try:
        GRAPH = dict(saved, **{"core.geodesy": saved["core.geodesy"] | {"core.dem"}})
        with pytest.raises(AssertionError, match="import cycles"):
            test_no_import_cycle()
    finally:
        GRAPH = saved
    bad = tmp_path / "bad.py"
    bad.write_text("import numpy\nfrom rasterio import open as ropen\n")
    assert "rasterio" in _imports("core.bad", bad)


# ------------------------------------------------------------------ the layout (issue 18)
#: the longest a module may grow: past it, split it where it holds two subjects
MAX_LINES = {"core": 600, "tasks": 500, "flows": 500}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_stay_small(name: str):
    n = len(MODULES[name].read_text().splitlines())
    limit = MAX_LINES[name.split(".")[0]]
    assert n <= limit, f"{name} has {n} lines (> {limit}): split it where it has two subjects"


#: modules every step uses that are neither I/O nor a step: where tile work is scheduled
TASKS_SHARED = {"__init__.py", "scheduling.py"}


def test_tasks_are_grouped_by_step():
    """tasks/ holds packages (io/ and one per step of the chain), no loose module but the
    scheduler every step uses."""
    loose = sorted(p.name for p in (REPO / "tasks").glob("*.py") if p.name not in TASKS_SHARED)
    assert not loose, f"modules directly in tasks/: {loose}; put each in tasks/io/ or its step"


def _decorated(path: Path, decorator: str) -> list[tuple[str, bool]]:
    """The functions of a file carrying ``@decorator`` (or ``@decorator(...)``): (name, whether
    defined at module level)."""
    tree = ast.parse(path.read_text(), str(path))
    top = {id(n) for n in tree.body}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for d in node.decorator_list:
                target = d.func if isinstance(d, ast.Call) else d
                if isinstance(target, ast.Name) and target.id == decorator:
                    out.append((node.name, id(node) in top))
    return out


def test_tasks_live_in_tasks_and_flows_in_flows():
    """``@task`` only under tasks/, ``@flow`` only under flows/ (that flows are built at module
    level is held by ``tests/flows/test_layout.py``)."""
    misplaced = {name: f for name, path in MODULES.items()
                 for f, _ in _decorated(path, "task") if not name.startswith("tasks")}
    assert not misplaced, f"@task outside tasks/: {misplaced}"
    outside = {name: f for name, path in MODULES.items()
               for f, _ in _decorated(path, "flow") if not name.startswith("flows")}
    assert not outside, f"@flow outside flows/: {outside}"


#: the one strict JSON writer and reader (:mod:`core.jsonio`); files through tasks.io.rasters
JSON_HOME = {"core.jsonio"}


def test_json_is_written_and_parsed_in_one_place():
    """No ``json.dumps``/``json.loads`` (nor ``dump``/``load``) outside :mod:`core.jsonio`:
    every product is written by the strict writer (NaN as null) and read by ``parse_json``."""
    found = {}
    for name, path in MODULES.items():
        if name in JSON_HOME:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "json"
                    and node.func.attr in {"dumps", "loads", "dump", "load"}):
                found.setdefault(name, []).append(f"json.{node.func.attr} line {node.lineno}")
    assert not found, f"JSON handled outside core.jsonio: {found}"
