"""The exchange sampler's start near the pseudolikelihood's maximum, against exact posteriors:
the auto-normal model's by integrating its exact likelihood on a grid, the Ising model's by
transfer matrices on a narrow lattice."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe import models
from mrfpe.samplers.exchange import pl_start, pseudolikelihood_of
from mrfpe.testing import CorrelatedGaussian


def _grid_moments(target, centre, half, n):
    """Mean and sd of exp(log_prob) on a grid of ``n`` points per axis, ``centre ± half``."""
    g = [np.linspace(c - h, c + h, n) for c, h in zip(centre, half, strict=True)]
    G = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, len(centre))
    lp = target.log_prob(G)
    w = np.exp(lp - lp.max())
    w /= w.sum()
    mean = w @ G
    return mean, np.sqrt(w @ (G - mean) ** 2)


def _exact_posterior(m, x, bounds=None, n=41):
    """The flat-prior posterior's mean and sd: a coarse grid over the PL start's region, then
    a fine one over +-7 sd of it (the grid must hold the mass, and resolve it)."""
    exact = m.target("exact", x, bounds=bounds)
    centre, cov = pl_start(m.target("pl", x, bounds=bounds), exact.bounds)
    mean, sd = _grid_moments(exact, centre, 6 * np.sqrt(np.diag(cov)), n)
    return _grid_moments(exact, mean, 7 * sd, n)


def _check(post, mean, sd, tol_mean=0.15, tol_sd=0.15):
    th = post["theta"].values
    assert post.attrs["diag_reliable"], post.attrs["diag_messages"]
    assert post.attrs["diag_rhat"] <= 1.01
    assert post.attrs["start"] == "pl"
    err = np.abs(th.mean(0) - mean) / sd
    ratio = th.std(0) / sd
    assert np.all(err < tol_mean), (th.mean(0), mean, sd)
    assert np.all(np.abs(ratio - 1) < tol_sd), ratio


def test_the_gaussian_case_converges():
    """16 x 16 auto-normal field: from uniform starts in the old precision box (0, 1e4 /
    var) the chains stayed 10^3-10^4 times too precise (R-hat 3.8, mean 280 against 2.0);
    from the PL's maximum they agree with the exact posterior."""
    m = models.autonormal(4)
    y = m.simulate([1, 0.2, 2], shape=(16, 16), seed=0)
    wide = {"precision": (0.0, 1e4 / float(np.var(y)))}  # the former default box
    mean, sd = _exact_posterior(m, y, wide)
    post = mrfpe.sample("exchange", m.target("likelihood", y, bounds=wide), seed=0)
    _check(post, mean, sd)


CASES = {
    "autonormal_4": (lambda: models.autonormal(4), [0.5, 0.15, 1.5], (8, 8), {}),
    "autonormal_periodic": (lambda: models.autonormal(4, periodic=True), [0.0, -0.1, 3.0],
                            (8, 8), {}),
    "autonormal_8": (lambda: models.autonormal(8), [2.0, 0.08, 1.0], (8, 8), {}),
    "ising_narrow": (lambda: models.ising(), [0.3, 0.05], (4, 10), {"n_sweeps": 300}),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_exchange_agrees_with_the_exact_posterior(case):
    """Property: on every model with an exact likelihood to compare with, exchange at its
    defaults agrees with the exact posterior -- mean within 0.15 sd, sd within 15 % -- and
    flags itself reliable (R-hat <= 1.01, ESS >= 100)."""
    make, theta, shape, sim = CASES[case]
    m = make()
    x = m.simulate(theta, shape=shape, n=2, seed=7, **sim)
    mean, sd = _exact_posterior(m, x)
    post = mrfpe.sample("exchange", m.target("likelihood", x), seed=1)
    _check(post, mean, sd)


def test_starts_and_first_proposal_follow_the_pl():
    m = models.autonormal(4)
    y = m.simulate([1, 0.2, 2], shape=(16, 16), seed=0)
    lik = m.target("likelihood", y, bounds={"precision": (0.0, 1e4)})
    pl = pseudolikelihood_of(lik)
    np.testing.assert_array_equal(pl.log_prob([[1, 0.2, 2]]),
                                  m.target("pl", y, bounds={"precision": (0.0, 1e4)})
                                  .log_prob([[1, 0.2, 2]]))
    centre, cov = pl_start(pl, lik.bounds)
    post = mrfpe.sample("exchange", lik, seed=0, n_steps=60, burn_in=10)
    first = post["theta"].values[:4]  # the first kept step: four chains near the PL's maximum
    assert np.all(np.abs(first - centre) < 6 * 3.0 * np.sqrt(np.diag(cov)))
    uni = mrfpe.sample("exchange", lik, seed=0, n_steps=60, burn_in=10, start="uniform")
    assert uni.attrs["start"] == "uniform" and post.attrs["start"] == "pl"
    with pytest.raises(ValueError, match="start"):
        mrfpe.sample("exchange", lik, seed=0, start="mple")
    # a discrete model's PL is its design's, the rows model.target("pl", x) sums
    i = models.ising()
    x = i.simulate([0.3, 0.0], shape=(8, 8), seed=0, n_sweeps=200)
    th = np.array([[0.3, 0.0], [0.1, 0.2]])
    np.testing.assert_allclose(pseudolikelihood_of(i.target("likelihood", x)).log_prob(th),
                               i.target("pl", x).log_prob(th), rtol=1e-12)
    assert pseudolikelihood_of(CorrelatedGaussian()) is None  # no PL: uniform starts
