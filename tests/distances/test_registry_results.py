"""What a distance plugin returns or raises: refused or named, never printed as a number."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mrfpe
import mrfpe.distances as distances
from mrfpe._plugins import PluginError
from mrfpe.cli import main
from mrfpe.distances.base import Distance
from mrfpe.posterior import save

from .._dists import make_dist, on_sys_path, unique
from ._helpers import random_post

PLUGINS = """
    import math


    class _Duck:
        kind = "distance"
        symmetric = True
        params = {}
        VALUE = 0.0

        def __call__(self, a, b):
            return self.VALUE


    class Nan(_Duck):
        VALUE = math.nan


    class Negative(_Duck):
        VALUE = -0.5


    class MayBeNegative(_Duck):
        VALUE = -0.5
        nonnegative = False


    class Rounding(_Duck):
        VALUE = -1e-12


    class Text(_Duck):
        VALUE = "far"


    class Boom(_Duck):
        def __call__(self, a, b):
            raise RuntimeError("kaboom\\nsecond line")


    class Exits(_Duck):
        def __call__(self, a, b):
            raise SystemExit(4)


    class Refuses(_Duck):
        def __call__(self, a, b):
            raise ValueError("these posteriors are not on my grid")
"""
NAMES = ("Nan", "Negative", "MayBeNegative", "Rounding", "Text", "Boom", "Exits", "Refuses")


@pytest.fixture
def site(tmp_path, monkeypatch):
    yield from on_sys_path(tmp_path, monkeypatch)


@pytest.fixture
def plugin_module(site, request):
    mod = unique(request, "distance_plugins")
    make_dist(site, "dplugins", {mod: PLUGINS},
              {"mrfpe.distances": {n.lower(): f"{mod}:{n}" for n in NAMES}})
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # every one of them loads
        distances.registry.entries(refresh=True)
    return mod


@pytest.fixture
def pair():
    rng = np.random.default_rng(3)
    return random_post(rng), random_post(rng, loc=0.5)


def _label(mod: str, name: str) -> str:
    return f"distance plugin {name.lower()!r} ({mod}:{name}, package dplugins 1.0)"


@pytest.mark.parametrize(("name", "tail"), [
    ("Nan", " returned NaN: the distance means nothing for these posteriors"),
    ("Negative", " returned -0.5, a negative distance, though it declares nonnegative"),
    ("Text", " returned str 'far', not a number"),
    ("Refuses", ": these posteriors are not on my grid"),
])
def test_a_meaningless_value_is_refused_naming_the_plugin(plugin_module, pair, name, tail):
    with pytest.raises(ValueError) as err:
        mrfpe.distance(name.lower(), *pair)
    assert str(err.value).startswith(_label(plugin_module, name) + tail)


@pytest.mark.parametrize(("name", "reason"), [
    ("Boom", "RuntimeError: kaboom second line"), ("Exits", "SystemExit: 4")])
def test_a_plugin_that_raises_is_named(plugin_module, pair, name, reason):
    with pytest.raises(PluginError) as err:
        distances.distance(name.lower(), *pair)
    assert str(err.value) == f"{_label(plugin_module, name)} failed: {reason}"


def test_values_allowed_by_the_declaration_or_rounding_pass(plugin_module, pair):
    assert mrfpe.distance("maybenegative", *pair) == -0.5
    assert mrfpe.distance("rounding", *pair) == -1e-12


class _NegativeSubclass(Distance):
    def compare(self, fa, fb, p):
        return -0.25


def test_the_base_class_refuses_a_negative_distance_it_declares_nonnegative(pair):
    with pytest.raises(ValueError, match=r"_NegativeSubclass: the distance is -0\.25, "
                                         r"negative, though _NegativeSubclass\.nonnegative"):
        _NegativeSubclass()(*pair)
    _NegativeSubclass.nonnegative = False
    try:
        assert _NegativeSubclass()(*pair) == -0.25
        assert mrfpe.distance(_NegativeSubclass, *pair) == -0.25
    finally:
        del _NegativeSubclass.nonnegative


@pytest.mark.parametrize(("name", "status", "message"), [
    ("Nan", 2, " returned NaN"),
    ("Negative", 2, " returned -0.5, a negative distance"),
    ("Boom", 1, " failed: RuntimeError: kaboom second line"),
    ("Exits", 1, " failed: SystemExit: 4"),
])
def test_cli_compare_refuses_or_names_the_plugin(plugin_module, pair, tmp_path, capsys, name,
                                                 status, message):
    for post, path in zip(pair, ("a.nc", "b.nc"), strict=True):
        save(post, tmp_path / path)
    rc = main(["compare", str(tmp_path / "a.nc"), str(tmp_path / "b.nc"), "--distance",
               name.lower()])
    out, err = capsys.readouterr()
    assert (rc, out) == (status, "")
    assert err.startswith(f"mrfpe compare: error: {_label(plugin_module, name)}{message}")
    assert err.count("\n") == 1  # one line, and not "internal error"
