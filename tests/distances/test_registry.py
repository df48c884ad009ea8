"""The mrfpe.distances registry, its validator, listing and front doors."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

import mrfpe
import mrfpe.distances as distances
from mrfpe._plugins import Registry
from mrfpe.classify import similarity_matrix
from mrfpe.distances import registry, validate_distance
from mrfpe.distances.gaussian import Chernoff

from ._helpers import random_post


class DuckDistance:
    """A plugin that does not derive from mrfpe's base class: |mean difference|."""

    kind = "distance"
    symmetric = True
    params: ClassVar[dict] = {"scale": 1.0}

    def __call__(self, a, b, scale=1.0):
        return float(scale * np.abs(a["theta"].values.mean(0) - b["theta"].values.mean(0)).sum())


class DuckSimilarity(DuckDistance):
    """A similarity plugin."""

    kind = "similarity"
    symmetric = False

    def similarity(self, a, b):
        return -self(a, b)

    def log_similarity(self, a, b):
        raise ValueError("no log")


@pytest.fixture
def local_plugins():
    registry.register("duck", DuckDistance)
    registry.register("duck_sim", DuckSimilarity)
    try:
        yield
    finally:
        registry.unregister("duck")
        registry.unregister("duck_sim")


def test_registry_shares_the_plugin_code():
    assert isinstance(registry, Registry)
    assert registry.group == "mrfpe.distances"


def test_get_returns_the_class_and_rejects_unknown_names():
    assert distances.get("chernoff") is Chernoff
    with pytest.raises(ValueError, match=r"unknown distance 'nope'.*bhattacharyya"):
        distances.get("nope")
    with pytest.raises(ValueError, match="string"):
        distances.get(3)


def test_front_doors_agree():
    rng = np.random.default_rng(0)
    a, b = random_post(rng), random_post(rng, loc=0.5)
    v = Chernoff()(a, b, alpha=0.6)
    assert mrfpe.distance("chernoff", a, b, alpha=0.6) == v
    assert distances.distance("chernoff", a, b, alpha=0.6) == v


def test_table_shows_kind_symmetry_and_parameters(capsys):
    text = distances.table()
    assert registry.table() == text
    lines: dict[str, str] = {}  # name -> its row with the wrapped continuation lines
    for line in text.splitlines()[2:]:
        if line[:1].strip():
            name = line.split()[0]
            lines[name] = line
        else:
            lines[name] += " " + line.strip()
    assert set(distances.available()) <= set(lines)
    assert "[distance, asymmetric] alpha=0.7 eps=1e-09 min_var=1e-12" in lines["chernoff"]
    assert "[similarity, symmetric] sigma=0.005 form='weighted'" in lines["agmmp"]
    assert "[similarity, symmetric] (no parameters)" in lines["correlation"]
    assert "[distance, symmetric] (no parameters)" in lines["map_euclidean"]
    from mrfpe.cli import main

    assert main(["distances"]) == 0
    assert "sliced_wasserstein" in capsys.readouterr().out


def test_local_plugins_work_everywhere(local_plugins):
    assert {"duck", "duck_sim"} <= set(distances.available())
    rng = np.random.default_rng(1)
    sets = [random_post(rng, loc=0.3 * k) for k in range(3)]
    assert mrfpe.distance("duck", sets[0], sets[1], scale=2.0) == pytest.approx(
        2 * DuckDistance()(sets[0], sets[1]))
    S = similarity_matrix(sets, "duck", n_jobs=2)
    expect = -np.array([[DuckDistance()(x, y) for y in sets] for x in sets])
    np.testing.assert_allclose(S, expect)
    assert "[similarity, asymmetric] scale=1.0" in " ".join(distances.table().split())


class NoKind:
    symmetric = True
    params: ClassVar[dict] = {}

    def __call__(self, a, b):
        return 0.0


class BadKind(NoKind):
    kind = "metric"


class BadSymmetric(NoKind):
    kind = "distance"
    symmetric = "yes"


class BadParams(NoKind):
    kind = "distance"
    params = ("alpha",)


class NeedsArgs(NoKind):
    kind = "distance"

    def __init__(self, thing):
        self.thing = thing


class NotCallable:
    kind = "distance"
    symmetric = True
    params: ClassVar[dict] = {}


class OneArgument(NoKind):
    kind = "distance"

    def __call__(self, a):
        return 0.0


class SimilarityWithoutLog(NoKind):
    kind = "similarity"

    def similarity(self, a, b):
        return 1.0


@pytest.mark.parametrize(("obj", "message"), [
    (DuckDistance(), "must be a class"), (NoKind, "kind"), (BadKind, "kind"),
    (BadSymmetric, "symmetric"), (BadParams, "params"), (NeedsArgs, "no arguments"),
    (NotCallable, "__call__"), (OneArgument, "two posteriors"),
    (SimilarityWithoutLog, "log_similarity"),
])
def test_validator_rejects_broken_plugins(obj, message):
    with pytest.raises(TypeError, match=message):
        validate_distance(obj)
    with pytest.raises(TypeError, match=message):
        registry.register("broken_one", obj)
    assert "broken_one" not in distances.available()


def test_validator_accepts_every_built_in_and_a_duck():
    for name in distances.available():
        validate_distance(distances.get(name))
    validate_distance(DuckDistance)
    validate_distance(DuckSimilarity)


def test_a_broken_entry_point_is_listed_not_raised():
    import importlib.metadata as md

    ep = md.EntryPoint(name="ghost", value="mrfpe.distances.no_such_module:Ghost",
                       group="mrfpe.distances")
    info = registry._load(ep)
    assert not info.ok and "ModuleNotFoundError" in info.error


def test_cli_compare_passes_parameters(tmp_path, capsys):
    from mrfpe.cli import main
    from mrfpe.posterior import save

    rng = np.random.default_rng(2)
    a, b = random_post(rng), random_post(rng, loc=0.5)
    save(a, tmp_path / "a.nc")
    save(b, tmp_path / "b.nc")
    assert main(["compare", str(tmp_path / "a.nc"), str(tmp_path / "b.nc"),
                 "--distance", "chernoff", "--param", "alpha=0.4"]) == 0
    assert float(capsys.readouterr().out.split(": ")[-1].split()[0]) == pytest.approx(
        mrfpe.distance("chernoff", a, b, alpha=0.4), rel=1e-12)
    assert main(["compare", str(tmp_path / "a.nc"), str(tmp_path / "b.nc"),
                 "--distance", "chernoff", "--param", "alpha=4"]) == 2
    assert "alpha must lie in" in capsys.readouterr().err
