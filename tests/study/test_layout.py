"""The study machinery's import graph: no circle (type-checking imports included), the
settings-value module knows no study, and the machinery never imports the experiments."""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp")


@pytest.fixture(scope="module")
def graph():
    # type-checking imports included: a circle hidden under TYPE_CHECKING is still a circle
    return grimp.build_graph("mrfpe", include_external_packages=False,
                             exclude_type_checking_imports=False)


def _machinery(graph) -> set[str]:
    return {m for m in graph.modules if m == "mrfpe.study" or m.startswith("mrfpe.study.")}


def _imports(graph, module: str) -> set[str]:
    return {m for m in graph.find_modules_directly_imported_by(module)
            if not module.startswith(m + ".")}


def test_the_machinery_never_imports_the_experiments(graph):
    for module in _machinery(graph):
        assert not {m for m in _imports(graph, module) if m.startswith("mrfpe.experiments")}, \
            module


def test_setting_values_know_no_study(graph):
    assert {m for m in _imports(graph, "mrfpe.study.config") if m.startswith("mrfpe")} == set()


def test_no_circle_in_the_machinery(graph):
    inner = {m for m in _machinery(graph) if m != "mrfpe.study"}
    for module in inner:
        for other in _imports(graph, module) & inner:
            assert not graph.chain_exists(importer=other, imported=module), \
                f"{module} and {other} import each other"
