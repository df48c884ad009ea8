"""The import graph of mrfpe: no circles, and the leaf modules stay leaves (issue 11).

The graph comes from grimp (the import-linter project's graph builder), which
reads every import statement, including those inside functions; imports under
``if TYPE_CHECKING:`` are left out (they never run).
"""

from __future__ import annotations

import sys

import pytest

grimp = pytest.importorskip("grimp")

#: Modules every layer may use; they import no other mrfpe module. (``mrfpe.mixture``
#: is not one: its numba kernel uses the vectorised exp/log of ``mrfpe.targets.kernels``.)
LEAVES = ("mrfpe.validation", "mrfpe.resampling", "mrfpe.threads", "mrfpe.checksum")
#: Modules that import leaves only (the netCDF reader verifies checksums).
NEAR_LEAVES = ("mrfpe.netcdf",)


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("mrfpe", include_external_packages=False,
                             exclude_type_checking_imports=True)


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


@pytest.mark.parametrize("leaf", LEAVES)
def test_leaf_modules_import_no_mrfpe_module(graph, leaf):
    assert {m for m in _edges(graph, leaf) if m.startswith("mrfpe")} == set()


@pytest.mark.parametrize("module", NEAR_LEAVES)
def test_near_leaves_import_leaves_only(graph, module):
    assert {m for m in _edges(graph, module) if m.startswith("mrfpe")} <= set(LEAVES)


def test_library_never_imports_the_cli(graph):
    users = {m for m in graph.modules if "mrfpe.cli" in _edges(graph, m)}
    assert users <= {"mrfpe.__main__"}
