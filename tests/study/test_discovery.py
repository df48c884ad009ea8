"""Where studies come from: the ``mrfpe.studies`` entry points, read without importing them."""

from __future__ import annotations

import ast
import dataclasses
import os
import textwrap
from pathlib import Path

import pytest

import mrfpe.experiments
from mrfpe import study as S
from mrfpe.study import discovery

from .. import _processes as procs

EXPERIMENTS = Path(mrfpe.experiments.__file__).parent


def _run(code: str, **env: str) -> str:
    return procs.python(textwrap.dedent(code), env={**os.environ, **env}).stdout.strip()


def _defines_study(path: Path) -> bool:
    tree = ast.parse(path.read_text())
    return any(isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "STUDY"
                                                    for t in node.targets)
               for node in tree.body)


def test_every_experiment_is_registered_and_nothing_else():
    """pyproject.toml's entry points and the modules defining STUDY are the same set."""
    import importlib.metadata as md

    modules = {p.stem for p in EXPERIMENTS.glob("*.py") if _defines_study(p)}
    eps = {ep.name: ep.value for ep in md.entry_points(group=discovery.GROUP)
           if ep.value.startswith("mrfpe.")}
    assert eps == {m: f"mrfpe.experiments.{m}:STUDY" for m in modules}


def test_listing_imports_no_study_and_get_imports_one():
    out = _run("""
        import sys
        from mrfpe.study import discovery
        names = discovery._names()
        before = sorted(m for m in sys.modules if m.startswith("mrfpe.experiments"))
        study = discovery.get("importance_sampling")
        after = sorted(m for m in sys.modules if m.startswith("mrfpe.experiments."))
        print(len(names), before, after, study.source)
    """)
    assert out == ("8 [] ['mrfpe.experiments.importance_sampling', "
                   "'mrfpe.experiments.writeup'] mrfpe.experiments.importance_sampling")


def test_discovery_leaves_the_module_s_study_alone():
    from mrfpe.experiments import importance_sampling

    found = S.get("importance_sampling")
    assert found.source == "mrfpe.experiments.importance_sampling"
    assert importance_sampling.STUDY.source == ""  # a changed copy, not a mutated original
    assert found == importance_sampling.STUDY  # source does not enter equality
    with pytest.raises(dataclasses.FrozenInstanceError):
        found.source = "elsewhere"


THIRD_PARTY = '''
"""A study shipped by another distribution.

Full run: instant.
"""
import xarray as xr
from mrfpe.study import Study

STUDY = Study(name="{name}", doc=__doc__, trial=lambda c, r, s: xr.Dataset(),
              summarise=lambda results, config, out: "", config={{"n_trials": 1, "seed": 0}})
'''


@pytest.fixture
def third_party(tmp_path):
    """A distribution on a path of its own registering two studies, one misnamed."""
    pkg = tmp_path / "site"
    (pkg / "othermod").mkdir(parents=True)
    (pkg / "othermod" / "__init__.py").write_text("")
    (pkg / "othermod" / "theirs.py").write_text(THIRD_PARTY.format(name="theirs"))
    (pkg / "othermod" / "misnamed.py").write_text(THIRD_PARTY.format(name="something_else"))
    info = pkg / "otherdist-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: otherdist\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[mrfpe.studies]\ntheirs = othermod.theirs:STUDY\n"
        "misnamed = othermod.misnamed:STUDY\n")
    return pkg


def test_another_distribution_ships_studies(third_party):
    out = _run("""
        import warnings
        from mrfpe import study as S
        study = S.get("theirs")
        broken = {}
        names = sorted(S.available(broken))
        print(study.name, study.source)
        print("theirs" in names, "classification" in names)
        print(broken)
        try:
            S.get("misnamed")
        except ValueError as exc:
            print(exc)
    """, PYTHONPATH=str(third_party))
    lines = out.splitlines()
    assert lines[0] == "theirs othermod.theirs"
    assert lines[1] == "True True"
    assert "misnamed" in lines[2] and "'something_else'" in lines[2]
    assert "the two names must agree" in lines[3]
