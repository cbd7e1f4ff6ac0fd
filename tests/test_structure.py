"""The package reads as its data flow: imports run down the stages, with no circles (not
even through imports inside functions or for type checkers), no underscored names taken
from another module, and no side effects at import time."""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fabplan"

# top of the flow first: a stage may import the stages after it, never one before it
STAGES = ["cli", "edit", "study", "fabricate", "layout", "design", "solve", "net", "report", "io", "errors"]

# the products of the fabricate stage, each a room of its own: a product imports the shared
# modules of fabricate/ (`limits`) and the stages below, never another product
PRODUCTS = ["molds", "strips", "milling", "arcs"]
#: the longest module of fabricate/ (lines): a longer one is split where it has a seam
MAX_FABRICATE_LINES = 900


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@functools.cache
def _tree(path: Path) -> ast.Module:
    """The parsed file (parsed once: several tests read every module)."""
    return ast.parse(path.read_text(encoding="utf-8"))


def _statements(body: list, typing_only: bool = False):
    """(statement, whether it sits in an ``if TYPE_CHECKING:`` block) for every statement
    in `body` and the blocks within it: imports are statements, so the expressions (most
    of a file's nodes) need no walk."""
    for node in body:
        yield node, typing_only
        checking = isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            for child in getattr(node, field, None) or []:
                inner = child.body if isinstance(child, (ast.ExceptHandler, ast.match_case)) else [child]
                yield from _statements(inner, typing_only or checking)


@functools.cache
def _imports(path: Path, typing_too: bool = False) -> list[tuple[str, list[str], int]]:
    """(module, names, line) of every fabplan import in a file, lazy ones included, those
    only for type checkers left out (unless `typing_too`)."""
    tree = _tree(path)
    package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rsplit(".", 1)[0]
    found = []
    for node, typing_only in _statements(tree.body):
        if typing_only and not typing_too:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module.split(".")[0] == "fabplan":
                found.append((module, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            found += [(a.name, [], node.lineno) for a in node.names if a.name.split(".")[0] == "fabplan"]
    return found


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _target(module: str, name: str) -> str:
    """The module an imported name refers to (a submodule, or the module itself)."""
    return f"{module}.{name}" if f"{module}.{name}" in MODULES else module


@functools.cache
def _graph(typing_too: bool = False) -> dict[str, set[str]]:
    """module -> the fabplan modules it imports, at its top, inside its functions and
    (with `typing_too`) for type checkers."""
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for module, path in MODULES.items():
        for target, names, _ in _imports(path, typing_too):
            for t in {_target(target, n) for n in names} or {target}:
                if t in MODULES and t != module:
                    graph[module].add(t)
    return graph


def _lazy_packages() -> set[str]:
    """The packages that re-export their submodules' names lazily (a module-level
    ``__getattr__`` in their ``__init__``): `fabplan`, the product rooms of fabricate/..."""
    return {m for m, p in MODULES.items() if p.name == "__init__.py"
            and any(isinstance(node, ast.FunctionDef) and node.name == "__getattr__"
                    for node in _tree(p).body)}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of `graph`: one path ``a -> ... -> a`` per strongly connected
    group of modules (Tarjan), found in a stable order."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups: list[set[str]] = []

    def visit(m: str) -> None:
        index[m] = low[m] = len(index)
        stack.append(m)
        for t in sorted(graph[m]):
            if t not in index:
                visit(t)
                low[m] = min(low[m], low[t])
            elif t in stack:
                low[m] = min(low[m], index[t])
        if low[m] == index[m]:
            group = set()
            while m not in group:
                group.add(stack.pop())
            if len(group) > 1:
                groups.append(group)

    for m in sorted(graph):
        if m not in index:
            visit(m)
    cycles = []
    for group in groups:
        # the shortest circle through the group's first module
        start = min(group)
        paths = {start: [start]}
        queue = [start]
        for here in queue:   # breadth first, the queue growing as it is read
            if start in graph[here]:
                cycles.append(paths[here] + [start])
                break
            for t in sorted(graph[here] & group - paths.keys()):
                paths[t] = paths[here] + [t]
                queue.append(t)
    return cycles


def _stage(module: str) -> str:
    return module.split(".")[1] if "." in module else "fabplan"


def test_no_import_cycle():
    """No two fabplan modules import each other, by any path: imports at the top, inside
    functions and for type checkers only all count (a circle of annotations is a circle
    of concepts all the same). Left out: the packages that re-export lazily through a
    module ``__getattr__`` (`fabplan`, `fabplan.edit`, `fabplan.fabricate.molds`, ...),
    by design: their names are imported from the submodule only when first used."""
    lazy = _lazy_packages()
    assert "fabplan" in lazy and "fabplan.fabricate.molds" in lazy
    graph = {m: targets - lazy for m, targets in _graph(typing_too=True).items() if m not in lazy}
    cycles = _cycles(graph)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_cycles_are_found():
    """The circle finder itself: a circle of three, a pair, and none in a chain."""
    found = _cycles({"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": {"e"}, "e": {"d"}, "f": {"a"}})
    assert sorted(found) == [["a", "b", "c", "a"], ["d", "e", "d"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_underscored_name_from_another_module():
    taken = [f"{_module_name(p)}:{line} takes {n} from {module}"
             for p in MODULES.values() for module, names, line in _imports(p)
             for n in names if n.startswith("_") and not n.endswith("__") and module != _module_name(p)]
    assert not taken, "\n".join(taken)


def test_imports_run_down_the_stages():
    upward = []
    for module, targets in _graph().items():
        if module == "fabplan":
            continue
        here = STAGES.index(_stage(module))
        for t in targets:
            if t != "fabplan" and STAGES.index(_stage(t)) < here:
                upward.append(f"{module} imports {t}")
    assert not upward, "\n".join(sorted(upward))


def test_every_stage_is_a_folder_with_its_rules():
    for stage in STAGES:
        folder = PACKAGE / stage
        if folder.is_dir():
            doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
            assert doc and ("May import" in doc or stage == "io"), \
                f"{stage}/__init__.py says what it may import"
    loose = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert loose == ["__init__.py", "errors.py"]


#: the command line's modules and functions stay readable: one module per command, and a
#: long run split into named steps
CLI_MODULE_LINES = 900
CLI_FUNCTION_LINES = 80


def test_the_command_line_has_short_modules_and_functions():
    long = []
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        if len(text.splitlines()) > CLI_MODULE_LINES:
            long.append(f"{path.name}: {len(text.splitlines())} lines")
        long += [f"{path.name}:{node.lineno} {node.name}: {node.end_lineno - node.lineno + 1} lines"
                 for node in ast.walk(ast.parse(text))
                 if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                 and node.end_lineno - node.lineno + 1 > CLI_FUNCTION_LINES]
    assert not long, "\n".join(long)


def _product(module: str) -> str | None:
    """The product of fabricate/ a module belongs to (`molds` for
    ``fabplan.fabricate.molds.panels``), None outside them."""
    parts = module.split(".")
    if len(parts) > 2 and parts[1] == "fabricate" and parts[2] in PRODUCTS:
        return parts[2]
    return None


def test_products_of_fabricate_never_import_one_another():
    """molds, strips, milling and arcs share only what lives in fabricate/ itself (and the
    stages below); type-checking imports count too."""
    sideways = []
    for module, path in MODULES.items():
        here = _product(module)
        if here is None:
            continue
        for target, names, line in _imports(path, typing_too=True):
            for t in {_target(target, n) for n in names} or {target}:
                there = _product(t)
                if there is not None and there != here:
                    sideways.append(f"{module}:{line} imports {t}")
    assert not sideways, "\n".join(sorted(sideways))


def test_every_product_is_a_room_with_its_rules():
    """Each product subpackage says what it owns and what it may import, and re-exports
    the names of the module it replaced."""
    import importlib

    for product in PRODUCTS:
        folder = PACKAGE / "fabricate" / product
        if not folder.is_dir():
            assert (PACKAGE / "fabricate" / f"{product}.py").is_file(), product
            continue
        doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
        assert doc and "Owns" in doc and "May import" in doc, f"fabricate/{product}/__init__.py"
        package = importlib.import_module(f"fabplan.fabricate.{product}")
        assert set(package.__all__) <= set(package._EXPORTS)
        for name, owner in package._EXPORTS.items():
            assert owner.startswith(f"fabplan.fabricate.{product}.")
            value = getattr(package, name)
            assert value is getattr(importlib.import_module(owner), name)
            assert value is not None


def test_no_module_of_fabricate_is_too_long():
    long = [f"{_module_name(p)}: {n} lines" for p in (PACKAGE / "fabricate").rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_FABRICATE_LINES]
    assert not long, f"over {MAX_FABRICATE_LINES} lines: " + ", ".join(long)



#: the longest function (lines, docstring included): a longer one is split where it has a
#: seam with a name, or listed in `LONG_FUNCTIONS` with the reason it stays whole
MAX_FUNCTION_LINES = 80
#: functions allowed over `MAX_FUNCTION_LINES` (fabplan/cli is checked on its own), each
#: with why it stays one function; the list only shrinks
LONG_FUNCTIONS = {
    "fabplan.solve.optimize:optimize": "a 72-line docstring of its options; the body "
                                       "is the one solve, each step a call",
    "fabplan.edit.server:EditServer.app": "the route table of the edit server: its handlers are "
                                          "closures over the session and the starlette classes "
                                          "it imports when first served",
    "fabplan.solve.pattern:normal_pattern": "one computation in four numbered steps "
                                            "sharing their index arrays",
    "fabplan.fabricate.arcs:_edge_tangents": "one computation in four numbered steps sharing "
                                             "the tangent, normal and decided arrays; step 3 is "
                                             "one front loop over them",
    "fabplan.fabricate.strips.unrolling:unroll_polylines": "a 30-line docstring with its doctest; "
                                                           "one vectorized unrolling, each line "
                                                           "an array of all nodes",
    "fabplan.fabricate.molds.panel_classes:cone_fits": "one Levenberg-Marquardt fit, its "
                                                       "parameter steps and costs local "
                                                       "functions of the same arrays",
    "fabplan.layout.extraction:fill_boundary_cells": "a 24-line docstring; one loop of passes "
                                                     "over the boundary cells, each predicting, "
                                                     "snapping and accepting corners on key "
                                                     "tables it rebuilds",
    "fabplan.layout.view:net_numbers": "one table of a record's numbers, row by row",
    "fabplan.layout.starts:glide_fairest": "a 28-line docstring; one loop over the starts, "
                                           "each laid out, glided and judged in turn",
}


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualified name, node) of every function in `tree`, methods as ``Class.name``."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node
            yield from _functions(node, prefix + node.name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


def test_no_function_is_too_long():
    """Functions outside fabplan/cli stay within `MAX_FUNCTION_LINES`, apart from those
    listed with their reason; a listed one that got shorter leaves the list."""
    long = {f"{module}:{name}": node.end_lineno - node.lineno + 1
            for module, path in MODULES.items() if not module.startswith("fabplan.cli")
            for name, node in _functions(_tree(path))
            if node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES}
    unlisted = sorted(f"{k} ({n} lines)" for k, n in long.items() if k not in LONG_FUNCTIONS)
    assert not unlisted, f"over {MAX_FUNCTION_LINES} lines: " + ", ".join(unlisted)
    stale = sorted(set(LONG_FUNCTIONS) - set(long))
    assert not stale, "listed but no longer long (take them off LONG_FUNCTIONS): " + ", ".join(stale)

@pytest.mark.parametrize("statement", ["import fabplan", "import fabplan.cli",
                                       "import fabplan.study.report", "import fabplan.layout.picture"])
def test_import_has_no_side_effects(statement):
    """No backend switching, no umask change, no pyplot: a Jupyter or Rhino host keeps its own."""
    code = ("import os, sys\nmask = os.umask(0o027)\n"
            f"{statement}\n"
            "assert os.umask(0o027) == 0o027, 'umask changed'\n"
            "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot imported'\n"
            "assert 'ezdxf' not in sys.modules or '" + statement + "' != 'import fabplan'\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_import_fabplan_stays_light():
    """``import fabplan`` loads none of the heavy libraries; they come with their stage."""
    code = ("import sys, fabplan\n"
            "heavy = [m for m in ('ezdxf', 'igl', 'shapely', 'trimesh', 'matplotlib', 'scipy') "
            "if m in sys.modules]\n"
            "assert not heavy, heavy\n"
            "assert fabplan.QuadMesh.__module__ == 'fabplan.net.mesh'\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_figures_leave_pyplot_alone(tmp_path):
    """Drawing a report picture neither imports pyplot nor changes the backend."""
    code = ("import sys\n"
            "from fabplan.report import figures\n"
            "fig = figures.new_figure((2, 2)); ax = fig.subplots(); ax.plot([0, 1], [0, 1])\n"
            "uri = figures.figure_to_data_uri(fig)\n"
            "assert uri.startswith('data:image/png;base64,') and len(uri) > 200\n"
            "assert 'matplotlib.pyplot' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    switching = [f"{_module_name(p)}:{node.lineno}" for p in MODULES.values()
                 for node in ast.walk(_tree(p))
                 if (isinstance(node, ast.Call) and ast.unparse(node.func) in ("matplotlib.use", "os.umask"))
                 or (isinstance(node, (ast.Import, ast.ImportFrom))
                     and "pyplot" in ast.unparse(node))]
    assert not switching, "backend, umask or pyplot in the library: " + ", ".join(switching)


def test_every_public_name_resolves():
    import fabplan

    lazy = set(fabplan.__all__) - {"FabplanError", "InputError", "SolverError", "data_path"}
    assert lazy == set(fabplan._EXPORTS)
    for name in fabplan.__all__:
        assert getattr(fabplan, name) is not None


def test_designs_and_reference_surfaces_travel_to_other_processes():
    """Studies send a design (with its closest-point tree) to worker processes."""
    import numpy as np

    pickle = pytest.importorskip("cloudpickle")   # what Dask sends functions with

    import fabplan

    design = fabplan.load_design("hyperbolic-paraboloid:width=4,depth=4,rise=1.2", triangles=2000)
    reference = design.reference
    copy = pickle.loads(pickle.dumps(design))
    points = np.array([[0.3, -0.2, 1.0], [1.0, 1.0, -2.0]])
    assert np.array_equal(copy.reference.closest_points(points)[0],
                          reference.closest_points(points)[0])


def test_every_package_is_installed():
    """`pip install .` installs the packages pyproject.toml lists: a package missing there
    works from a checkout and breaks on a user's machine."""
    import tomllib

    root = Path(__file__).resolve().parent.parent
    listed = set(tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(root).parts) for p in (root / "fabplan").rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)
