"""maximise(): dense grid + local refinement."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import models
from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import get, maximise
from mrfpe.targets.base import Target
from mrfpe.targets.maximise import DEFAULT_MAX_POINTS, ascent_from, grid_points, grid_size
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


# ------------------------------------------------------------------------------------------------
# every local method moves where the target rises; the search's cost is bounded; it says so
# ------------------------------------------------------------------------------------------------

METHODS = ["pattern", "nelder-mead", "l-bfgs-b"]


def test_grid_size_is_the_exact_integer_root():
    assert 4096 ** (1 / 3) < 16 and grid_size(4096, 3) == 16  # the float truncates to 15
    for d in range(1, 7):
        for k in range(2, 30):
            assert grid_size(k ** d, d) == k
            assert grid_size(k ** d - 1, d) == k - 1
            assert d == 1 or grid_size(k ** d + 1, d) == k


@pytest.fixture(scope="module")
def gaussian_field():
    m = models.autonormal(4)
    return m, m.simulate([1, 0.2, 2], shape=(16, 16), seed=0)


@pytest.mark.parametrize("estimator", ["exact", "pl", "coding", "block"])
def test_lbfgsb_finds_the_gaussian_models_maximum(gaussian_field, estimator):
    """L-BFGS-B returned its grid start unchanged on every auto-normal target: the first
    trial point left the PD region and a 1e300 stand-in made its line search stop."""
    m, y = gaussian_field
    t = m.target(estimator, y)
    want, lp_want = maximise(t)  # the pattern search
    got, lp, info = maximise(t, method="l-bfgs-b", return_info=True)
    sd = np.sqrt(np.diag(np.linalg.inv(-_hessian(t, want))))
    assert np.all(np.abs(got - want) < 1e-3 * sd), (got, want)
    assert lp >= lp_want - 1e-6 and info["message"] == ""


def _hessian(t, th):
    from mrfpe.models.pl_spread import hessian

    return hessian(t.log_prob, th, 1e-4 * np.maximum(np.abs(th), 1e-2))


def _targets():
    m = models.autonormal(4)
    y = m.simulate([1, 0.2, 2], shape=(12, 12), seed=3)
    i = models.ising()
    x = i.simulate([0.3, 0.1], shape=(8, 8), seed=2, n_sweeps=200)
    p = models.potts(3)
    z = p.simulate([0.5, 0.1, -0.2], shape=(10, 10), seed=1, n_sweeps=200)
    return {"correlated_gaussian": CorrelatedGaussian(), "autonormal_exact": m.target("exact", y),
            "autonormal_pl": m.target("pl", y), "autonormal_coding": m.target("coding", y),
            "ising_exact": i.target("exact", x), "ising_pl": i.target("pl", x),
            "potts_pl": p.target("pl", z)}


@pytest.mark.parametrize("method", METHODS)
def test_every_method_moves_from_a_start_where_the_target_rises(method):
    """Property: from random starts in the support where the target is not flat, every
    local method returns a point of higher log_prob, away from the start."""
    rng = np.random.default_rng(0)
    for name, t in _targets().items():
        b = t.bounds
        tried = 0
        while tried < 3:
            start = b[:, 0] + (b[:, 1] - b[:, 0]) * (0.1 + 0.8 * rng.random(b.shape[0]))
            f0 = float(t.log_prob(start)[0])
            if not np.isfinite(f0) or ascent_from(t, start)[0] <= 1e-9 * (1 + abs(f0)):
                continue
            tried += 1
            theta, lp = maximise(t, grid=start[None], n_starts=1, method=method)
            assert lp > f0 and not np.array_equal(theta, start), (name, method, start)


class _Strip(Target):
    """Finite only on the diagonal x = y, rising along it: no axis move stays finite."""

    param_names = ("x", "y")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])

    def _log_prob(self, theta):
        on = theta[:, 0] == theta[:, 1]
        return np.where(on, -((theta[:, 0] - 0.7) ** 2), -np.inf)


def test_a_point_that_is_no_maximum_is_named(caplog):
    """L-BFGS-B's finite differences see only -inf on the strip: it cannot move, and
    maximise says so (the log and info) instead of returning the start silently."""
    t = _Strip()
    with caplog.at_level("WARNING", logger="mrfpe.targets.maximise"):
        theta, _lp, info = maximise(t, grid=np.array([[0.2, 0.2]]), n_starts=1,
                                    method="l-bfgs-b", return_info=True)
    np.testing.assert_array_equal(theta, [0.2, 0.2])
    assert info["rise"] > 0 and "no local maximum" in info["message"]
    assert "no local maximum" in caplog.text
    # the pattern search follows the diagonal and reaches the maximum
    theta, _lp, info = maximise(t, grid=np.array([[0.2, 0.2]]), n_starts=1, return_info=True)
    np.testing.assert_allclose(theta, [0.7, 0.7], atol=1e-4)


class _Quadratic(Target):
    """``-Σ ((θ - c) / w)²`` in a box of widths ``w`` (any scale): the maximum is ``c``."""

    def __init__(self, d, width):
        self.param_names = tuple(f"p{k}" for k in range(d))
        self.w = np.full(d, float(width))
        self.c = 0.37 * self.w
        self.bounds = np.stack([np.zeros(d), self.w], axis=1)
        self.n_calls = 0
        self.n_points = 0

    def _log_prob(self, theta):
        self.n_calls += 1
        self.n_points += theta.shape[0]
        return -np.sum(((theta - self.c) / self.w) ** 2, axis=1) * 1e4


@pytest.mark.parametrize("width", [1e-3, 1.0, 1e4])
def test_xtol_is_a_fraction_of_each_range(width):
    """Nelder-Mead took xtol as an absolute xatol: in a box 1e-3 wide it stopped a
    thousandth of the range away."""
    t = _Quadratic(2, width)
    for method in METHODS:
        theta, _ = maximise(t, grid=3, method=method, xtol=1e-7)
        assert np.all(np.abs(theta - t.c) < 1e-5 * width), (method, theta, t.c)


def test_the_default_search_is_bounded_and_says_so(caplog):
    """20^5 grid points had not been searched after two minutes; the default search now
    evaluates at most DEFAULT_MAX_POINTS on its grid, a Halton set, and says so."""
    t = _Quadratic(5, 1.0)
    with caplog.at_level("INFO", logger="mrfpe.targets.maximise"):
        theta, _lp, info = maximise(t, return_info=True)
    assert info["grid"] == "halton" and info["grid_points"] == DEFAULT_MAX_POINTS
    assert "Halton" in caplog.text
    assert t.n_points < DEFAULT_MAX_POINTS + 20000
    np.testing.assert_allclose(theta, t.c, atol=1e-4)
    again = maximise(_Quadratic(5, 1.0), return_info=True)
    np.testing.assert_array_equal(again[0], theta)  # the Halton set comes from seed
    small = maximise(_Quadratic(3, 1.0), return_info=True)[2]
    assert small["grid"] == "product" and small["grid_points"] == 20 ** 3
    with pytest.raises(ValueError, match="max_points"):
        maximise(t, max_points=1)
