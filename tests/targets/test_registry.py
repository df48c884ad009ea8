"""The ``mrfpe.targets`` entry-point registry and what it accepts."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.targets import Target, get, names, target_class
from mrfpe.targets.options import Option, number_check
from mrfpe.targets.registry import registry, validate_target_class


class _Flat(Target):
    """A flat density on [0, 1] (data: anything)."""

    data_kind = "anything"
    option_specs = (Option("width", float, 1.0, number_check(0.0, low_open=True), "box width"),)
    param_names = ("a",)

    def __init__(self, data, width: float = 1.0) -> None:
        self.bounds = np.array([[0.0, width]])

    def log_prob(self, theta):
        theta = np.atleast_2d(theta)
        return np.where(self.in_bounds(theta), 0.0, -np.inf)


def test_a_registered_target_is_built_by_name():
    registry.register("flat_test", _Flat)
    try:
        assert "flat_test" in names()
        t = get("flat_test", None, width=2.0)
        assert t.bounds.tolist() == [[0.0, 2.0]]
        with pytest.raises(ValueError, match="width"):
            get("flat_test", None, widht=2.0)
    finally:
        registry.unregister("flat_test")
    assert "flat_test" not in names()


@pytest.mark.parametrize("bad, match", [
    (42, "Target subclass"),
    (dict, "Target subclass"),
    (type("NoKind", (Target,), {"data_kind": 3}), "data_kind"),
    (type("BadOptions", (Target,), {"option_specs": (1, 2)}), "option_specs"),
])
def test_validate_target_class_refuses(bad, match):
    with pytest.raises(TypeError, match=match):
        validate_target_class(bad)


def test_unknown_name_lists_the_names_nearest_first():
    with pytest.raises(ValueError, match=r"did you mean 'pls'"):
        target_class("plss")


def test_the_wrong_data_is_refused_by_the_target_class():
    with pytest.raises(ValueError, match="Scene for target 'pl'"):
        get("pl", np.zeros((4, 4), dtype=int))
