"""Tests of the adaptive-tempering SMC plugin (run: pytest plugins/mrfpe-smc/tests)."""

import math

import numpy as np
import pytest
from mrfpe_smc import AdaptiveTemperingSMC, next_temperature, systematic_resample
from scipy import stats
from scipy.special import logsumexp

from mrfpe.posterior import validate, weighted_cov, weighted_mean
from mrfpe.targets.base import Target
from mrfpe.testing import TwoModes, check_sampler


class Gaussian2D(Target):
    """A normalised correlated Gaussian well inside the unit square (+ a constant)."""

    param_names = ("u", "v")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    mean = np.array([0.4, 0.6])
    cov = np.array([[0.004, 0.0024], [0.0024, 0.0025]])

    def __init__(self, offset=0.0):
        self.offset = offset

    def _log_prob(self, theta):
        return stats.multivariate_normal(self.mean, self.cov).logpdf(theta) + self.offset


def test_conformance():
    report = check_sampler(AdaptiveTemperingSMC)
    assert all(v == "passed" for v in report.values()), report


@pytest.mark.parametrize("offset", [0.0, -250.0])
def test_evidence_and_moments(offset):
    # ∫ N(θ; μ, Σ) dθ over the square is 1 to within 1e-12, and vol = 1: log Z = offset.
    post = AdaptiveTemperingSMC(n_particles=2000).run(Gaussian2D(offset), seed=0)
    validate(post)
    assert abs(post.attrs["log_evidence"] - offset) < 0.15
    np.testing.assert_allclose(weighted_mean(post), Gaussian2D.mean, atol=0.1 * 0.05)
    np.testing.assert_allclose(weighted_cov(post), Gaussian2D.cov, atol=0.15 * 0.004)


def test_temperature_ladder():
    post = AdaptiveTemperingSMC(n_particles=500, ess_fraction=0.6).run(TwoModes(), seed=1)
    beta = post["beta"].values
    assert beta[0] == 0.0 and beta[-1] == 1.0 and np.all(np.diff(beta) > 0)
    # every stage but the last hits the ESS target; the last may keep more
    np.testing.assert_allclose(post["ess"].values[1:-1], 0.6 * 500, rtol=1e-4)
    assert post["ess"].values[-1] >= 0.6 * 500 * (1 - 1e-4)
    assert np.all((post["n_moves"].values[1:] >= 2) & (post["n_moves"].values[1:] <= 10))


def test_next_temperature_solves_the_ess_equation():
    lp = np.random.default_rng(0).normal(-1000, 30, 400)
    b = next_temperature(lp, 0.2, 150.0)
    lw = (b - 0.2) * lp
    ess = math.exp(2 * logsumexp(lw) - logsumexp(2 * lw))
    assert 0.2 < b < 1 and abs(ess - 150.0) < 1e-3
    assert next_temperature(np.zeros(10), 0.5, 5.0) == 1.0  # flat: one step to β = 1


def test_systematic_resampling_counts():
    # Each particle is copied floor(N w) or ceil(N w) times (the systematic property).
    rng = np.random.default_rng(3)
    w = rng.dirichlet(np.ones(50))
    for _ in range(20):
        counts = np.bincount(systematic_resample(np.log(w), rng), minlength=50)
        assert counts.sum() == 50
        assert np.all(counts >= np.floor(50 * w) - 1e-9) and np.all(counts <= np.ceil(50 * w))


def test_reproducible():
    a = AdaptiveTemperingSMC(n_particles=200).run(TwoModes(), seed=5)
    b = AdaptiveTemperingSMC(n_particles=200).run(TwoModes(), seed=5)
    np.testing.assert_array_equal(a["theta"].values, b["theta"].values)
    assert a.attrs["n_target_evals"] == b.attrs["n_target_evals"] > 0


@pytest.mark.parametrize(("kw", "match"), [
    ({"n_particles": 1}, "n_particles"), ({"ess_fraction": 1.0}, "ess_fraction"),
    ({"min_moves": 5, "max_moves": 3}, "max_moves"), ({"mixing": 0.0}, "mixing"),
])
def test_bad_config(kw, match):
    with pytest.raises(ValueError, match=match):
        AdaptiveTemperingSMC(**kw)
