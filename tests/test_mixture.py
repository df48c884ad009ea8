"""The numba mixture density against scipy's multivariate normal + logsumexp and NumPy."""

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

from mrfpe.mixture import log_mixture_density, log_mixture_density_numpy


def _scipy(x, c, log_w, sigma):
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), (x.shape[1],))
    comp = np.stack([stats.multivariate_normal(ci, np.diag(sig**2)).logpdf(x) for ci in c], 1)
    return logsumexp(comp + log_w[None, :], axis=1)


@pytest.mark.parametrize("sigma", [0.05, np.array([0.03, 0.1, 0.2])])
def test_matches_scipy(sigma):
    rng = np.random.default_rng(0)
    c, x = rng.random((37, 3)), rng.random((200, 3))
    log_w = np.log(rng.dirichlet(np.ones(37)))
    got = log_mixture_density(x, c, log_w, sigma)
    ref = _scipy(x, c, log_w, sigma)
    assert np.max(np.abs(got - ref) / np.maximum(1.0, np.abs(ref))) < 1e-12
    assert np.max(np.abs(got - log_mixture_density_numpy(x, c, log_w, sigma, chunk=7))
                  / np.maximum(1.0, np.abs(ref))) < 1e-12


def test_far_points_zero_weights_and_empty():
    rng = np.random.default_rng(1)
    c = rng.random((5, 2))
    with np.errstate(divide="ignore"):
        log_w = np.log([0.5, 0.5, 0.0, 0.0, 0.0])  # -inf components are ignored
    x = np.vstack([rng.random((3, 2)), [[40.0, -40.0]]])  # far: log density ~ -1e5, finite
    got = log_mixture_density(x, c, log_w, 0.01)
    assert np.all(np.isfinite(got))
    assert np.allclose(got, _scipy(x, c[:2], np.log([0.5, 0.5]), 0.01), rtol=1e-12, atol=0)
    assert np.all(log_mixture_density(x, c, np.full(5, -np.inf), 0.1) == -np.inf)
    assert log_mixture_density(np.empty((0, 2)), c, log_w, 0.1).shape == (0,)


def test_large_batch_agrees_with_numpy_route():
    # PMC's size (1000 particles, ~600 distinct ancestors): the parallel path
    rng = np.random.default_rng(2)
    c, x = rng.random((600, 3)), rng.random((1000, 3))
    log_w = np.log(rng.dirichlet(np.ones(600)))
    got = log_mixture_density(x, c, log_w, 0.02)
    ref = log_mixture_density_numpy(x, c, log_w, 0.02)
    assert np.max(np.abs(got - ref) / np.maximum(1.0, np.abs(ref))) < 1e-12
