"""Parametric bootstrap of the MPLE: the posterior schema, refits on the box's face, and
what it refuses."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import models
from mrfpe.brdf.synthetic import make_scene
from mrfpe.models.bootstrap import parametric_bootstrap


def test_parametric_bootstrap_schema_and_spread():
    m = models.ising()
    x = m.simulate([0.3, 0.05], shape=(8, 8), seed=1, n_sweeps=300)
    boot = parametric_bootstrap(m, x, n_boot=30, seed=0)
    assert boot.attrs["kind"] == "optima" and boot["theta"].shape == (30, 2)
    spread = boot["theta"].values.std(0)
    assert np.all(spread > 0) and np.all(spread < 1.0)
    assert not boot["on_face"].values.any() and "bias" not in boot.attrs


def test_parametric_bootstrap_flags_refits_on_the_box_face():
    """Near the critical coupling on a 6 x 6 lattice many simulated lattices are uniform:
    their MPLE is the bound, which must be marked, not silently mixed into the quantiles."""
    m = models.ising()
    x = m.simulate([0.44, 0.0], shape=(6, 6), seed=0, n_sweeps=300)
    boot = parametric_bootstrap(m, x, n_boot=20, seed=0)
    th, b = boot["theta"].values, np.array(m.target("pl", x).bounds)
    by_hand = ((np.isclose(th, b[:, 0]) | np.isclose(th, b[:, 1])).any(axis=1))
    assert by_hand.any()
    np.testing.assert_array_equal(boot["on_face"].values, by_hand)
    assert f"{by_hand.sum()} of 20 refits lie on the box's face" in boot.attrs["bias"]
    assert not boot.attrs["diag_reliable"]


def test_parametric_bootstrap_refuses_what_it_cannot_refit_before_fitting():
    m = models.ising()
    x = m.simulate([0.3, 0.05], shape=(8, 8), seed=1, n_sweeps=300)
    for bad in (0, -2, 2.5, True):
        with pytest.raises(ValueError, match=r"n_boot must be an integer >= 1"):
            parametric_bootstrap(m, x, n_boot=bad)
    scene = make_scene(brdf="phong", theta=[0.5, 0.4, 8.0], shape=(6, 7), n_labels=5, seed=3)
    with pytest.raises(ValueError, match=r"simulates the labels of a fixed scene"):
        parametric_bootstrap(models.get("brdf"), scene, n_boot=5)
