"""exp(PL)'s spread: importance-sampled moments against quadrature, and a kinked log PL
whose curvature at the mode is not its spread."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe.models.pl_spread import (
    _temperature,
    hessian,
    pl_moments,
    sample_moments,
    start_covariance,
    tempered_weights,
)
from mrfpe.targets.base import Target

BOX = np.array([[0.0, 1.0], [0.0, 1.0]])


class _Fn(Target):
    param_names = ("a", "b")
    bounds = BOX

    def __init__(self, f):
        self.f = f

    def _log_prob(self, theta):
        return self.f(theta[:, 0], theta[:, 1])


def _quadrature(f, n=601):
    g = np.linspace(0.0, 1.0, n)
    A, B = np.meshgrid(g, g, indexing="ij")
    lp = f(A.ravel(), B.ravel())
    w = np.exp(lp - lp.max())
    w /= w.sum()
    X = np.stack([A.ravel(), B.ravel()], 1)
    mean = w @ X
    return mean, (X - mean).T @ ((X - mean) * w[:, None])


def _gaussian(a, b):
    za, zb = (a - 0.45) / 0.03, (b - 0.6) / 0.05
    return -0.5 * (za**2 - 1.2 * za * zb + zb**2) / (1 - 0.36)


# A kinked log PL: a sum of absolute differences, as a BRDF scene's data terms are.
_CENTRES = np.random.default_rng(3).normal(0.0, 1.0, 400)


def _kinked(a, b):
    return (-np.abs((a[:, None] - 0.5) * 30 - _CENTRES).sum(axis=1) / 8
            - np.abs((b[:, None] - 0.4) * 20 - _CENTRES).sum(axis=1) / 8)


@pytest.mark.parametrize("f", [_gaussian, _kinked], ids=["gaussian", "kinked"])
def test_moments_match_quadrature_from_a_start_ten_times_too_narrow(f):
    mean, cov = _quadrature(f)
    sd = np.sqrt(np.diag(cov))
    mom = pl_moments(_Fn(f), mean, np.diag((sd / 10) ** 2), np.random.default_rng(0))
    np.testing.assert_allclose(mom.mean, mean, atol=0.05 * sd.min())
    np.testing.assert_allclose(mom.sd, sd, rtol=0.05)
    assert mom.ess >= 8192 / 10


def test_a_kinked_log_pl_curvature_is_not_its_spread():
    """The situation pl_spread exists for: the Laplace sd from a central difference is
    far off the posterior sd, while the moments recover it."""
    mean, cov = _quadrature(_kinked)
    target = _Fn(_kinked)
    top = mean + np.array([1e-5, -2e-5])
    H = -hessian(target._log_prob, top, np.full(2, 1e-4))
    sd = np.sqrt(np.diag(cov))
    if np.all(np.linalg.eigvalsh(H) > 0):  # a kink in the stencil: far too curved
        laplace = np.sqrt(np.diag(np.linalg.inv(H)))
        assert np.max(np.abs(np.log(laplace / sd))) > np.log(2)
    # else no kink in the stencil: no curvature at all, no Laplace approximation
    mom = pl_moments(target, top, start_covariance(H, BOX), np.random.default_rng(1))
    np.testing.assert_allclose(mom.sd, sd, rtol=0.05)


def test_moments_from_a_start_a_hundred_times_too_wide():
    """A flat curvature at the mode gives the widest start (sd a quarter of the range);
    exp(PL) a hundred times narrower is still found: the proposal shrinks onto it."""
    sd = np.array([0.002, 0.0005])
    mean = np.array([0.62, 0.31])

    def narrow(a, b):  # truncation by the box is negligible: the moments are these
        return -0.5 * (((a - mean[0]) / sd[0]) ** 2 + ((b - mean[1]) / sd[1]) ** 2)

    start = start_covariance(np.zeros((2, 2)), BOX)
    np.testing.assert_allclose(np.sqrt(np.diag(start)), 0.25)
    mom = pl_moments(_Fn(narrow), mean + 0.1, start, np.random.default_rng(4))
    assert np.all(np.abs(mom.mean - mean) < 0.05 * sd), (mom.mean, mean)
    np.testing.assert_allclose(mom.sd, sd, rtol=0.05)


def test_a_far_mode_the_start_never_meets_is_counted():
    """A sixth of the mass 12 sd from the mode the sampler starts at, with the start's
    curvature: the defensive component meets it, and the moments are the whole
    target's (quadrature), not the near mode's."""
    def two_modes(a, b):
        near = -0.5 * (((a - 0.7) / 0.01) ** 2 + ((b - 0.6) / 0.02) ** 2)
        far = -0.5 * (((a - 0.58) / 0.01) ** 2 + ((b - 0.3) / 0.01) ** 2)
        return np.logaddexp(near + np.log(5 / 0.02), far + np.log(1 / 0.01))  # masses 5 : 1

    mean, cov = _quadrature(two_modes)
    sd = np.sqrt(np.diag(cov))
    mom = pl_moments(_Fn(two_modes), np.array([0.7, 0.6]), np.diag([0.01, 0.02]) ** 2,
                     np.random.default_rng(6))
    # one Gaussian fits two modes poorly (ESS ~ n / 9): ~3 Monte Carlo standard errors;
    # the near mode alone is 0.44 sd off in the mean and 0.2x in the sds
    assert np.all(np.abs(mom.mean - mean) < 0.1 * sd), (mom.mean, mean)
    np.testing.assert_allclose(mom.sd, sd, rtol=0.1)


def test_a_mode_hundreds_of_sds_away_is_counted_from_a_global_sample(tmp_path):
    """Two narrow modes 0.45 of the box apart (over 200 of their sds), 60 : 40: the
    importance sampler started at the near one never meets the far one (its moments are
    the near mode's: 0.8 sd off, sds 0.01-0.03x), PMC annealed from the whole box does,
    and :func:`sample_moments` takes the moments from it: against the mixture's closed form."""
    mu = np.array([[0.7, 0.6], [0.25, 0.3]])
    sds = np.array([[0.002, 0.004], [0.002, 0.002]])
    p = np.array([0.6, 0.4])

    def two_modes(a, b):
        comps = [np.log(pk) - np.log(2 * np.pi * s[0] * s[1])
                 - 0.5 * (((a - m[0]) / s[0]) ** 2 + ((b - m[1]) / s[1]) ** 2)
                 for pk, m, s in zip(p, mu, sds, strict=True)]
        return np.logaddexp(*comps)

    mean = p @ mu
    cov = sum(pk * (np.diag(s**2) + np.outer(m, m)) for pk, m, s in zip(p, mu, sds, strict=True))
    sd = np.sqrt(np.diag(cov - np.outer(mean, mean)))
    target = _Fn(two_modes)
    near = pl_moments(target, mu[0], np.diag(sds[0] ** 2), np.random.default_rng(0))
    assert np.all(near.sd < 0.1 * sd)  # the far mode was never met
    post = mrfpe.sample("pmc", target, seed=0, n_samples=4000)
    mom = sample_moments(target, post)
    assert mom.rounds == 0 and mom.ess >= 100
    assert np.all(np.abs(mom.mean - mean) < 0.1 * sd), (mom.mean, mean)
    np.testing.assert_allclose(mom.sd, sd, rtol=0.05)
    assert np.allclose(mom.best_theta, mu[0], atol=0.01) or np.allclose(mom.best_theta, mu[1],
                                                                         atol=0.01)
    mrfpe.posterior.save(post, tmp_path / "pl.nc")  # the same from the file it was saved to
    np.testing.assert_array_equal(sample_moments(target, tmp_path / "pl.nc").covariance,
                                  mom.covariance)


def test_tempered_weights_share_the_weight_among_the_draws_asked_for():
    lw = np.concatenate([np.random.default_rng(5).normal(0.0, 30.0, 1000), [-np.inf] * 3])
    beta = _temperature(lw, 40.0)
    w = tempered_weights(lw, beta)
    assert 0.0 < beta < 1.0 and w[-3:].sum() == 0.0
    np.testing.assert_allclose(1.0 / np.sum(w**2), 40.0, rtol=1e-3)
    np.testing.assert_allclose(tempered_weights(lw, 0.0)[:-3], 1e-3)
    assert _temperature(lw, 2000.0) == 0.0  # fewer finite draws than asked for


def test_the_best_point_met_reveals_a_higher_mode():
    def spiked(a, b):
        spike = 4.0 * np.exp(-((a - 0.47) ** 2 + (b - 0.6) ** 2) / (2 * 0.001**2))  # 4 % mass
        return _gaussian(a, b) + spike

    mom = pl_moments(_Fn(spiked), np.array([0.45, 0.6]), np.diag([0.03, 0.05]) ** 2,
                     np.random.default_rng(2))
    assert mom.best_log_prob > 1.0  # the Gaussian part peaks at 0
    np.testing.assert_allclose(mom.best_theta, [0.47, 0.6], atol=0.003)


def test_start_covariance_inverts_a_definite_curvature_and_bounds_the_others():
    H = np.array([[400.0, 50.0], [50.0, 900.0]])
    np.testing.assert_allclose(start_covariance(H, BOX), np.linalg.inv(H))
    for bad in ([[1e6, 0.0], [0.0, -3.0]], [[266.0, 0.0], [0.0, 3.6e-7]]):  # indefinite, flat
        cov = start_covariance(np.array(bad), BOX)
        np.linalg.cholesky(cov)
        assert np.all(np.sqrt(np.diag(cov)) <= 0.25 + 1e-12)


def test_no_finite_draw_is_an_error_not_a_number():
    with pytest.raises(ValueError, match="no importance draw of round 1 has a finite PL"):
        pl_moments(_Fn(lambda a, b: np.full(a.shape, -np.inf)), np.array([0.5, 0.5]),
                   np.eye(2) * 1e-4, np.random.default_rng(0))
