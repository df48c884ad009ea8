"""The architecture rules of mrfpe (docs/architecture.md), checked on the source tree.

Imports: the graph comes from grimp (the import-linter project's graph builder),
which reads every import statement, including those inside functions and those
under ``if TYPE_CHECKING:`` (a type-only import is still a dependency of the
design, and an import-graph tool counts it). The generic core imports nothing
from the BRDF wing (``mrfpe.brdf``); no circles between modules, nor between
packages at any depth; leaves stay leaves; nothing imports the package root; no
private name crosses a subpackage boundary.

Size and state: no module over 450 lines, no function over 80 lines (numba
kernels excepted: their loops are written out for the compiler), no
``object.__setattr__`` (frozen means frozen) and no ``global`` statement (no
process-wide mutable switch).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

grimp = pytest.importorskip("grimp")

#: The layers of docs/architecture.md, top to bottom, as first-level modules of ``mrfpe``:
#: a module imports only from layers below its own (and, where ``independent=False``,
#: from its own layer's other modules). The leaves import no mrfpe module at all.
LAYERS = (
    ("applications", ("__main__", "cli", "demo", "warmup", "experiments")),
    ("BRDF wing", ("brdf",)),
    ("studies", ("study",)),
    ("conformance", ("testing",)),
    ("samplers", ("samplers", "classify")),
    ("distances", ("distances",)),
    ("models", ("models",)),
    ("targets", ("targets",)),
    ("posteriors", ("posterior", "mixture", "_arviz")),
    ("registries, files and fast math", ("_plugins", "_factories", "netcdf", "fastmath")),
    ("leaves", ("validation", "resampling", "threads", "budget", "checksum", "_caller",
                "_terminal", "_version", "_moved")),
)
#: The application wings: over the generic core, under the applications.
WINGS = ("mrfpe.brdf",)
#: Modules that may import a wing: the applications (the package root too, for its
#: deprecated ``mrfpe.Scene``).
WING_USERS = ("mrfpe.__main__", "mrfpe.cli", "mrfpe.demo", "mrfpe.warmup", "mrfpe.experiments")


def _grimp_layers(layers=LAYERS):
    return [grimp.Layer(*tails, independent=name == "leaves") for name, tails in layers]


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("mrfpe", include_external_packages=False,
                             exclude_type_checking_imports=False)


def _edges(graph, module: str) -> set[str]:
    # importing a submodule imports its parent package: that is not a dependency edge
    return {t for t in graph.find_modules_directly_imported_by(module)
            if not module.startswith(t + ".")}


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    edges = {m: _edges(graph, m) for m in graph.modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(edges)))

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    try:
        for m in sorted(edges):
            if m not in index:
                visit(m)
    finally:
        sys.setrecursionlimit(limit)
    return found


def test_no_import_cycles(graph):
    assert _cycles(graph) == []


def test_cycle_finder_sees_a_cycle():
    """The checker itself: a two-module circle is found (an independent toy graph)."""
    g = grimp.ImportGraph()
    for m in ("pkg", "pkg.a", "pkg.b", "pkg.c"):
        g.add_module(m)
    g.add_import(importer="pkg.a", imported="pkg.b")
    g.add_import(importer="pkg.b", imported="pkg.a")
    g.add_import(importer="pkg.c", imported="pkg.a")
    assert _cycles(g) == [["pkg.a", "pkg.b"]]


def _layer_violations(graph, layers=LAYERS) -> list[str]:
    found = graph.find_illegal_dependencies_for_layers(layers=_grimp_layers(layers),
                                                       containers={"mrfpe"})
    return sorted(f"{d.importer} -> {d.imported}" for d in found)


def test_imports_go_down_the_layers(graph):
    assert _layer_violations(graph) == []


def test_every_module_has_a_layer(graph):
    placed = {f"mrfpe.{tail}" for _, tails in LAYERS for tail in tails}
    assert graph.find_children("mrfpe") - placed == set(), "add it to LAYERS and the docs"


def test_layer_checker_sees_an_upward_import(graph):
    """The checker itself: swapping two layers turns their real imports into violations."""
    swapped = list(LAYERS)
    i = [name for name, _ in LAYERS].index("targets")
    swapped[i - 1], swapped[i] = swapped[i], swapped[i - 1]
    assert any(v.startswith("mrfpe.") for v in _layer_violations(graph, tuple(swapped)))


def _in(module: str, packages: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def _wing_violations(graph) -> list[str]:
    """Imports of a wing from outside it (the applications and the root excepted)."""
    return sorted(f"{m} -> {t}" for m in graph.modules
                  if not _in(m, WINGS) and not _in(m, WING_USERS) and m != "mrfpe"
                  for t in _edges(graph, m) if _in(t, WINGS))


def test_the_core_imports_nothing_from_the_wing(graph):
    assert _wing_violations(graph) == []


def test_wing_checker_sees_an_arrow_into_the_wing():
    """The checker itself, on a toy graph with a core module reaching into the wing."""
    g = grimp.ImportGraph()
    for m in ("mrfpe", "mrfpe.models", "mrfpe.brdf", "mrfpe.brdf.scene", "mrfpe.cli"):
        g.add_module(m)
    g.add_import(importer="mrfpe.models", imported="mrfpe.brdf.scene")
    g.add_import(importer="mrfpe.cli", imported="mrfpe.brdf.scene")
    g.add_import(importer="mrfpe.brdf.scene", imported="mrfpe.models")
    assert _wing_violations(g) == ["mrfpe.models -> mrfpe.brdf.scene"]


def test_type_only_imports_are_counted(graph):
    """The graph holds ``if TYPE_CHECKING:`` imports: one known to exist is an edge."""
    assert "mrfpe.models.gaussian.structure" in _edges(graph, "mrfpe.models.gaussian.base")


def _package_cycles(graph, depth: int) -> list[list[str]]:
    """Circles between the packages and modules ``depth`` levels below ``mrfpe`` (a module
    deeper down counts as its ancestor at that depth; a package and what it holds are one
    thing, not a circle)."""
    def at(m: str) -> str:
        return ".".join(m.split(".")[: depth + 1])

    g = grimp.ImportGraph()
    nodes = {at(m) for m in graph.modules}
    for n in nodes:
        g.add_module(n)
    for m in graph.modules:
        for t in _edges(graph, m):
            a, b = at(m), at(t)
            if a != b and not b.startswith(a + ".") and not a.startswith(b + "."):
                g.add_import(importer=a, imported=b)
    return _cycles(g)


@pytest.mark.parametrize("depth", [1, 2, 3])
def test_no_circles_between_packages_at_any_depth(graph, depth):
    assert _package_cycles(graph, depth) == []


def test_package_circle_finder_sees_a_circle_through_submodules():
    """Two subpackages whose modules import each other's form a circle at depth 1."""
    g = grimp.ImportGraph()
    for m in ("mrfpe", "mrfpe.a", "mrfpe.a.x", "mrfpe.b", "mrfpe.b.y"):
        g.add_module(m)
    g.add_import(importer="mrfpe.a.x", imported="mrfpe.b.y")
    g.add_import(importer="mrfpe.b.y", imported="mrfpe.a")
    assert _package_cycles(g, 1) == [["mrfpe.a", "mrfpe.b"]]
    assert _package_cycles(g, 2) == []


def test_library_never_imports_the_cli(graph):
    users = {m for m in graph.modules if "mrfpe.cli" in _edges(graph, m)}
    assert users <= {"mrfpe.__main__"}


# -- source-level rules ----------------------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]
#: Library sources the rules hold for: the package and the plugins shipped beside it.
SOURCES = sorted([*(ROOT / "mrfpe").rglob("*.py"), *(ROOT / "plugins").glob("*/*/*.py")])
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 80
#: Decorators that mark a compiled kernel (exempt from the function-length rule).
KERNEL_DECORATORS = ("njit", "jit", "vectorize", "guvectorize", "stencil")


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _module_name(path: Path) -> str:
    """Dotted module name of a source file (plugins: relative to their project folder)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[0] == "plugins":
        parts = parts[2:]
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _is_kernel(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    for deco in fn.decorator_list:
        target = deco.func if isinstance(deco, ast.Call) else deco
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in KERNEL_DECORATORS:
            return True
    return False


def long_functions(tree: ast.Module) -> list[tuple[str, int]]:
    """(name, lines) of every function or method over the limit that is not a kernel."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not _is_kernel(node):
            lines = node.end_lineno - node.lineno + 1
            if lines > MAX_FUNCTION_LINES:
                found.append((node.name, lines))
    return found


def frozen_escapes(tree: ast.Module) -> list[int]:
    """Line numbers of ``object.__setattr__`` calls and ``global`` statements."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            found.append(node.lineno)
        elif (isinstance(node, ast.Attribute) and node.attr == "__setattr__"
              and isinstance(node.value, ast.Name) and node.value.id == "object"):
            found.append(node.lineno)
    return found


def _subpackage(module: str) -> str:
    """First-level subpackage of a module (``mrfpe.targets.base`` -> ``mrfpe.targets``),
    one level deeper inside a wing (``mrfpe.brdf.engine.lean`` -> ``mrfpe.brdf.engine``);
    top-level modules (``mrfpe.fastmath``) belong to ``mrfpe``, a plugin to itself."""
    parts = module.split(".")
    if parts[0] != "mrfpe" or len(parts) < 2 or not (ROOT / "mrfpe" / parts[1]).is_dir():
        return parts[0]
    if ".".join(parts[:2]) in WINGS and len(parts) > 2 \
            and (ROOT / "mrfpe" / parts[1] / parts[2]).is_dir():
        return ".".join(parts[:3])
    return ".".join(parts[:2])


def private_imports(tree: ast.Module, module: str, is_package: bool) -> list[str]:
    """``from X import _name`` where X is an mrfpe module of another subpackage."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = module.split(".")[: len(module.split(".")) - node.level + is_package]
            source = ".".join(base + ([node.module] if node.module else []))
        else:
            source = node.module or ""
        if not source.startswith("mrfpe"):
            continue
        for alias in node.names:
            private = alias.name.startswith("_") and not alias.name.startswith("__")
            if private and _subpackage(source) != _subpackage(module):
                found.append(f"{source}.{alias.name}")
    return found


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_module_is_short(path):
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_MODULE_LINES, f"{_rel(path)} has {lines} lines: split it by idea"


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_functions_are_short(path):
    assert long_functions(_tree(path)) == [], f"{_rel(path)}: split these into steps"


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_no_frozen_escape_or_global_state(path):
    assert frozen_escapes(_tree(path)) == [], f"{_rel(path)}: object.__setattr__ or global"


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_no_private_name_crosses_a_subpackage(path):
    module = _module_name(path)
    assert private_imports(_tree(path), module, path.name == "__init__.py") == []


#: Applications built on the library: they may use the package root's front door
#: (``mrfpe.sample``, ``mrfpe.distance``); the library's layers never import it.
APPLICATIONS = ("mrfpe.__main__", "mrfpe.cli", "mrfpe.demo", "mrfpe.experiments")


def test_only_applications_import_the_package_root(graph):
    users = {m for m in graph.modules if "mrfpe" in graph.find_modules_directly_imported_by(m)}
    assert {m for m in users if not m.startswith(APPLICATIONS)} == set()


def test_source_rules_see_violations():
    """The checkers themselves, on a small source with one of each violation."""
    src = ast.parse(
        "from mrfpe.targets.kernels import _FM\n"
        "from .lean import _inner\n"
        "import numba\n"
        "def long():\n" + "    x = 1\n" * 85 +
        "@numba.njit(cache=True)\ndef kernel():\n" + "    x = 1\n" * 85 +
        "def sneaky(self):\n    global STATE\n    object.__setattr__(self, 'a', 1)\n")
    assert long_functions(src) == [("long", 86)]
    assert frozen_escapes(src) == [src.body[-1].body[0].lineno, src.body[-1].body[1].lineno]
    assert private_imports(src, "mrfpe.mixture", False) == ["mrfpe.targets.kernels._FM"]
    assert private_imports(src, "mrfpe.targets.jacobian", False) == []
    # inside a wing, its subpackages are subpackages too
    wing = ast.parse("from mrfpe.brdf.engine.lean import _inner\n"
                     "from mrfpe.brdf.targets.energy import _table\n")
    assert private_imports(wing, "mrfpe.brdf.targets.brdf_target", False) == [
        "mrfpe.brdf.engine.lean._inner"]
