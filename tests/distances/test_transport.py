"""EMD and sliced Wasserstein against independent routes (scipy, a linear program, closed forms)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize, stats

import mrfpe
from mrfpe.distances import get

from ._helpers import post, random_post


def normalised(lw):
    w = np.exp(lw - np.max(lw))
    return w / w.sum()


def test_emd_1d_equals_scipy_wasserstein():
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(30), rng.standard_normal(17) + 0.4
    lwx, lwy = rng.standard_normal(30), rng.standard_normal(17)
    expect = stats.wasserstein_distance(x, y, normalised(lwx), normalised(lwy))
    assert mrfpe.distance("emd", post(x, lwx), post(y, lwy)) == pytest.approx(expect, rel=1e-9)


def test_emd_2d_equals_the_transport_linear_program():
    rng = np.random.default_rng(1)
    x, y = rng.random((6, 2)), rng.random((5, 2))
    lwx, lwy = rng.standard_normal(6), rng.standard_normal(5)
    wx, wy = normalised(lwx), normalised(lwy)
    cost = np.linalg.norm(x[:, None] - y[None], axis=-1).ravel()
    rows = np.kron(np.eye(6), np.ones(5))  # Σ_j T_ij = wx_i
    cols = np.kron(np.ones(6), np.eye(5))  # Σ_i T_ij = wy_j
    lp = optimize.linprog(cost, A_eq=np.vstack([rows, cols]), b_eq=np.r_[wx, wy],
                          bounds=(0, None), method="highs")
    assert lp.status == 0
    assert mrfpe.distance("emd", post(x, lwx), post(y, lwy)) == pytest.approx(lp.fun, rel=1e-7)


@pytest.mark.parametrize("scale", [1.0, 1e-6])
def test_emd_of_a_translated_set_is_the_shift(scale):
    """W₁(μ, μ + t) = |t| -- also when the whole set spans 1e-6 (no cancellation in the cost)."""
    rng = np.random.default_rng(2)
    x = 0.5 + scale * rng.random((40, 3))
    lw = rng.standard_normal(40)
    t = scale * np.array([0.3, -0.1, 0.2])
    assert mrfpe.distance("emd", post(x, lw), post(x + t, lw)) == pytest.approx(
        np.linalg.norm(t), rel=1e-7)


def test_emd_ground_cost_matches_pot():
    import ot
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(3)
    x, y = rng.random((20, 3)), rng.random((15, 3))
    np.testing.assert_allclose(cdist(x, y), ot.dist(x, y, metric="euclidean"), atol=1e-7)


def test_emd_zero_weight_samples_carry_no_mass():
    rng = np.random.default_rng(4)
    a, b = random_post(rng), random_post(rng, loc=1.0)
    a0 = post(np.vstack([a["theta"].values, [[50.0, 50.0]]]),
              np.append(a["log_weight"].values, -np.inf))
    assert mrfpe.distance("emd", a0, b) == pytest.approx(mrfpe.distance("emd", a, b), rel=1e-9)


def test_emd_warns_when_the_solver_stops_early():
    rng = np.random.default_rng(5)
    a, b = random_post(rng, S=30), random_post(rng, S=30, loc=1.0)
    with pytest.warns(UserWarning, match="numItermax"):
        mrfpe.distance("emd", a, b, num_iter_max=2)


def quantile_wp(x, wx, y, wy, p):
    """Exact 1-D p-Wasserstein from the two quantile functions (an independent route)."""
    ox, oy = np.argsort(x), np.argsort(y)
    x, wx, y, wy = x[ox], wx[ox], y[oy], wy[oy]
    cx, cy = np.cumsum(wx), np.cumsum(wy)
    u = np.unique(np.r_[0.0, cx, cy].clip(0, 1))
    mid = 0.5 * (u[1:] + u[:-1])
    qx = x[np.minimum(np.searchsorted(cx, mid), x.size - 1)]
    qy = y[np.minimum(np.searchsorted(cy, mid), y.size - 1)]
    return float(np.sum(np.diff(u) * np.abs(qx - qy) ** p) ** (1 / p))


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_sliced_in_1d_is_the_exact_wasserstein(p):
    rng = np.random.default_rng(6)
    x, y = rng.standard_normal(25), 0.5 + 2 * rng.standard_normal(19)
    lwx, lwy = rng.standard_normal(25), rng.standard_normal(19)
    expect = quantile_wp(x, normalised(lwx), y, normalised(lwy), p)
    got = mrfpe.distance("sliced_wasserstein", post(x, lwx), post(y, lwy), p=p,
                         n_projections=7)
    assert got == pytest.approx(expect, rel=1e-9)
    if p == 1.0:
        assert got == pytest.approx(stats.wasserstein_distance(
            x, y, normalised(lwx), normalised(lwy)), rel=1e-9)


def test_sliced_w1_is_a_lower_bound_of_emd():
    rng = np.random.default_rng(7)
    for _ in range(3):
        a, b = random_post(rng, d=3), random_post(rng, d=3, loc=0.5, scale=0.5)
        assert mrfpe.distance("sliced_wasserstein", a, b, p=1) <= mrfpe.distance(
            "emd", a, b) + 1e-12


def test_sliced_of_a_translation_has_the_expected_mean():
    """SW₁(μ, μ + t) = |t|·E|cos φ| = |t|·2/π in 2-D (Monte Carlo over 5000 directions)."""
    rng = np.random.default_rng(8)
    x = rng.random((30, 2))
    t = np.array([0.6, 0.8])
    got = mrfpe.distance("sliced_wasserstein", post(x), post(x + t), p=1, n_projections=5000)
    assert got == pytest.approx(2 / np.pi, rel=0.03)


def test_sliced_is_reproducible_from_its_seed():
    rng = np.random.default_rng(9)
    a, b = random_post(rng, d=3), random_post(rng, d=3, loc=0.5)
    v0 = mrfpe.distance("sliced_wasserstein", a, b, n_projections=20, seed=0)
    assert mrfpe.distance("sliced_wasserstein", a, b, n_projections=20, seed=0) == v0
    assert mrfpe.distance("sliced_wasserstein", a, b, n_projections=20, seed=1) != v0


@pytest.mark.parametrize(("name", "params"), [
    ("emd", {"num_iter_max": 0}), ("sliced_wasserstein", {"n_projections": 0}),
    ("sliced_wasserstein", {"p": 0.5}), ("sliced_wasserstein", {"seed": None}),
    ("sliced_wasserstein", {"seed": -3}),
])
def test_bad_parameters_raise(name, params):
    rng = np.random.default_rng(10)
    a = random_post(rng)
    with pytest.raises(ValueError, match=next(iter(params))):
        mrfpe.distance(name, a, a, **params)


def test_emd_matrix_parallel_equals_serial():
    rng = np.random.default_rng(11)
    sets = [random_post(rng, S=12, loc=0.2 * k) for k in range(5)]
    m = get("emd")()
    np.testing.assert_allclose(m.pairwise(sets, n_jobs=2), m.pairwise(sets), rtol=1e-12)
