"""maximise(): dense grid + local refinement."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import get, maximise
from mrfpe.targets.maximise import grid_points
from mrfpe.testing import CorrelatedGaussian


def test_grid_points():
    g = grid_points([[0, 1], [-1, 1]], 3)
    assert g.shape == (9, 2)
    np.testing.assert_allclose(sorted(set(g[:, 1])), [-1, 0, 1])


@pytest.mark.parametrize("method", ["pattern", "nelder-mead", "l-bfgs-b"])
def test_finds_gaussian_mode(method):
    t = CorrelatedGaussian()
    theta, lp = maximise(t, grid=6, method=method, n_starts=2, xtol=1e-7)
    np.testing.assert_allclose(theta, t.mean, atol=1e-4)
    assert lp == pytest.approx(float(t.log_prob(theta)[0]))
    assert lp >= t.log_prob(t.mean)[0] - 1e-6


def test_random_starts_reproducible():
    t = CorrelatedGaussian()
    a = maximise(t, grid=3, n_random=3, seed=4, max_iter=5)
    b = maximise(t, grid=3, n_random=3, seed=4, max_iter=5)
    np.testing.assert_array_equal(a[0], b[0])


def test_explicit_grid_and_bad_input():
    t = CorrelatedGaussian()
    theta, _ = maximise(t, grid=np.random.default_rng(0).random((50, 3)))
    np.testing.assert_allclose(theta, t.mean, atol=1e-4)
    with pytest.raises(ValueError, match="method"):
        maximise(t, method="newton")
    with pytest.raises(ValueError, match="grid"):
        maximise(t, grid=1)
    with pytest.raises(ValueError, match="grid"):
        maximise(t, grid=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="n_starts"):
        maximise(t, n_starts=0)


def test_noise_free_ward_maximiser_near_truth():
    """Thesis-style check: over a 20^3 grid (+ refinement) the PL_s maximum is within 0.1."""
    u = np.array([0.7, 0.4, 0.45])
    s = make_scene(brdf="ward", theta=[0.7, 0.4, 0.225], shape=(24, 24), n_labels=10, seed=0)
    t = get("pls", s)
    theta, lp = maximise(t, grid=20)
    assert np.linalg.norm(theta - u) < 0.1
    assert lp >= t.log_prob(u)[0] - 1e-8  # 1e-10 relative: the polish stops at xtol 1e-6


def test_bad_arguments_are_named():
    from mrfpe.testing import TwoModes

    with pytest.raises(ValueError, match="grid must be"):
        maximise(TwoModes(), grid="x")
    with pytest.raises(ValueError, match="seed must be"):
        maximise(TwoModes(), seed="x")
    with pytest.raises(ValueError, match="theta must be"):
        TwoModes().log_prob("abc")
