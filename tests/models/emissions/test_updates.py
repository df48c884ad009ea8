"""Conjugate updates against their closed-form posteriors; truncated draws; ordered modes."""

import numpy as np
import pytest
from scipy import stats

from mrfpe.models import emissions
from mrfpe.models.emissions.truncated import (
    ordered_mode,
    truncated_gamma,
    truncated_inverse_gamma,
    truncated_normal,
)

N_DRAWS = 4000


def _draws(bound, params, x, free=None, seed=0):
    rng = np.random.default_rng(seed)
    free = np.ones(bound.d, bool) if free is None else free
    return np.array([bound.update(params, x, rng, free) for _ in range(N_DRAWS)])


def _close(draws, mean, sd, what):
    se = sd / np.sqrt(draws.size)
    assert abs(draws.mean() - mean) < 5 * se, (what, draws.mean(), mean)
    assert abs(draws.std() / sd - 1) < 5 / np.sqrt(2 * draws.size), (what, draws.std(), sd)


def test_gaussian_means_given_the_sd_are_the_normal_posterior():
    rng = np.random.default_rng(1)
    x = np.repeat([0, 1], 10)
    y = np.where(x == 0, 0.0, 5.0) + 0.7 * rng.standard_normal(20)
    b = emissions.gaussian(mean_prior=(2.0, 3.0)).bind(2, y, np.ones(20, bool), {}, {})
    free = np.array([True, True, False])  # the sd fixed at 0.7
    d = _draws(b, np.array([0.0, 5.0, 0.7]), x, free)
    for k in (0, 1):
        prec = 1 / 3.0 ** 2 + 10 / 0.7 ** 2
        mean = (2.0 / 3.0 ** 2 + y[x == k].sum() / 0.7 ** 2) / prec
        _close(d[:, k], mean, prec ** -0.5, f"mean_{k}")
    assert np.all(d[:, 2] == 0.7)


def test_gaussian_sd_given_the_means_is_the_inverse_gamma_posterior():
    rng = np.random.default_rng(2)
    x = np.repeat([0, 1], 15)
    y = np.where(x == 0, -1.0, 1.0) + 0.5 * rng.standard_normal(30)
    b = emissions.gaussian(sd_prior=(2.0, 0.3)).bind(2, y, np.ones(30, bool), {}, {})
    d = _draws(b, np.array([-1.0, 1.0, 0.5]), x, np.array([False, False, True]))
    ss = ((y - np.where(x == 0, -1.0, 1.0)) ** 2).sum()
    post = stats.invgamma(2.0 + 15, scale=0.3 + ss / 2)
    _close(d[:, 2] ** 2, post.mean(), post.std(), "sd^2")


def test_per_state_sds_each_take_their_own_states_residuals():
    rng = np.random.default_rng(3)
    x = np.repeat([0, 1], 40)
    y = np.where(x == 0, 0.0, 4.0) + np.where(x == 0, 0.2, 1.5) * rng.standard_normal(80)
    b = emissions.gaussian(shared_sd=False, sd_prior=(1.0, 0.01)).bind(2, y, np.ones(80, bool),
                                                                       {}, {})
    d = _draws(b, np.array([0.0, 4.0, 0.2, 1.5]), x, np.array([False, False, True, True]))
    for k, mean in ((0, 0.0), (1, 4.0)):
        ss = ((y[x == k] - mean) ** 2).sum()
        post = stats.invgamma(1.0 + 20, scale=0.01 + ss / 2)
        _close(d[:, 2 + k] ** 2, post.mean(), post.std(), f"sd_{k}^2")


def test_a_flat_prior_on_the_sd_gives_its_own_posterior():
    rng = np.random.default_rng(4)
    x = np.repeat([0, 1], 10)
    y = np.where(x == 0, 0.0, 3.0) + 0.5 * rng.standard_normal(20)
    b = emissions.gaussian().bind(2, y, np.ones(20, bool), {}, {"sd": (0.01, 5.0)})
    d = _draws(b, np.array([0.0, 3.0, 0.5]), x, np.array([False, False, True]))
    ss = ((y - np.where(x == 0, 0.0, 3.0)) ** 2).sum()
    post = stats.invgamma((20 - 1) / 2, scale=ss / 2)  # p(sd) ∝ 1: v^(-1/2) on v = sd^2
    _close(d[:, 2] ** 2, post.mean(), post.std(), "sd^2 (flat on sd)")


def test_means_stay_ordered_even_when_the_data_would_swap_them():
    rng = np.random.default_rng(5)
    x = np.repeat([0, 1], 5)
    y = np.where(x == 0, 1.0, 0.9) + 0.3 * rng.standard_normal(10)  # state 0 above state 1
    b = emissions.gaussian(shared_sd=False).bind(2, y, np.ones(10, bool), {}, {})
    d = _draws(b, np.array([0.0, 1.0, 0.3, 0.3]), x)
    assert np.all(d[:, 0] < d[:, 1])


def test_poisson_rates_are_the_gamma_posterior_with_exposure():
    rng = np.random.default_rng(6)
    x = np.repeat([0, 1], 12)
    e = rng.uniform(0.5, 2.0, 24)
    y = rng.poisson(e * np.where(x == 0, 2.0, 9.0)).astype(float)
    em = emissions.poisson(exposure="E", rate_prior=(1.5, 0.2))
    b = em.bind(2, y, np.ones(24, bool), {"E": e}, {})
    d = _draws(b, np.array([2.0, 9.0]), x)
    for k in (0, 1):
        post = stats.gamma(1.5 + y[x == k].sum(), scale=1 / (0.2 + e[x == k].sum()))
        _close(d[:, k], post.mean(), post.std(), f"rate_{k}")


def test_categorical_rows_are_the_dirichlet_posterior_and_fixed_entries_stay():
    rng = np.random.default_rng(7)
    x = np.repeat([0, 1], 30)
    y = np.where(rng.random(60) < 0.8, x, 1 - x).astype(float)
    b = emissions.categorical().bind(2, y, np.ones(60, bool), {}, {})
    d = _draws(b, np.array([0.8, 0.2, 0.2, 0.8]), x)
    for a in (0, 1):
        counts = np.bincount(y[x == a].astype(int), minlength=2)
        post = stats.beta(2 + (a == 0) + counts[0], 2 + (a == 1) + counts[1])
        _close(d[:, 2 * a], post.mean(), post.std(), f"prob_{a}_0")
    np.testing.assert_allclose(d[:, :2].sum(axis=1), 1.0)
    free = np.array([True, True, False, False])
    d = _draws(b, np.array([0.8, 0.2, 0.25, 0.75]), x, free)
    assert np.all(d[:, 2:] == [0.25, 0.75])


@pytest.mark.parametrize(("m", "p", "lo", "hi"), [(0.3, 4.0, -0.2, 0.9), (0.0, 1.0, 8.0, 9.0),
                                                 (0.0, 1.0, -40.0, -39.0), (1.0, 0.0, 0.0, 2.0)])
def test_truncated_normal_draws_have_the_truncated_distribution(m, p, lo, hi):
    u = np.random.default_rng(0).random(20000)
    d = np.array([truncated_normal(m, p, lo, hi, v) for v in u])
    assert np.all((d >= lo) & (d <= hi))
    if p == 0:
        ref = stats.uniform(lo, hi - lo)
    else:
        s = p ** -0.5
        ref = stats.truncnorm((lo - m) / s, (hi - m) / s, loc=m, scale=s)
    assert stats.kstest(d, ref.cdf).pvalue > 1e-4


@pytest.mark.parametrize(("a", "b", "lo", "hi"), [(3.0, 2.0, 0.5, 2.0), (0.5, 4.0, 0.0, 3.0),
                                                 (1.0, 0.0, 0.0, 2.0), (300.0, 2.0, 300, 400)])
def test_truncated_gamma_draws_have_the_truncated_distribution(a, b, lo, hi):
    u = np.random.default_rng(1).random(20000)
    d = np.array([truncated_gamma(a, b, lo, hi, v) for v in u])
    assert np.all((d >= lo) & (d <= hi))
    if b == 0:
        assert stats.kstest(d, stats.uniform(lo, hi - lo).cdf).pvalue > 1e-4
    elif a < 100:
        g = stats.gamma(a, scale=1 / b)
        cdf = lambda t: (g.cdf(t) - g.cdf(lo)) / (g.cdf(hi) - g.cdf(lo))  # noqa: E731
        assert stats.kstest(d, cdf).pvalue > 1e-4
    else:  # far in the upper tail: close to lo + Exponential(b - (a - 1)/lo)
        assert abs(d.mean() - (lo + 1 / (b - (a - 1) / lo))) < 0.02


def test_truncated_inverse_gamma_with_zero_shape_and_power_laws():
    u = np.random.default_rng(2).random(20000)
    d = np.array([truncated_inverse_gamma(3.0, 2.0, 0.1, 5.0, v) for v in u])
    ig = stats.invgamma(3.0, scale=2.0)
    cdf = lambda t: (ig.cdf(t) - ig.cdf(0.1)) / (ig.cdf(5.0) - ig.cdf(0.1))  # noqa: E731
    assert stats.kstest(d, cdf).pvalue > 1e-4
    d = np.array([truncated_gamma(0.0, 2.0, 0.1, 2.0, v) for v in u])  # exp(-2 w) / w
    grid = np.linspace(0.1, 2.0, 20001)
    dens = np.exp(-2 * grid) / grid
    cum = np.cumsum(dens) / dens.sum()
    assert stats.kstest(d, lambda t: np.interp(t, grid, cum)).pvalue > 1e-4


def test_ordered_mode_is_the_isotonic_regression():
    num, den = np.array([3.0, 1.0, 5.0, 2.0]), np.array([1.0, 1.0, 2.0, 1.0])
    out = ordered_mode(num, den, np.zeros(4))
    np.testing.assert_allclose(out, [2.0, 2.0, 7 / 3, 7 / 3])  # pooled weighted means
    assert np.all(np.diff(out) >= 0)
    out = ordered_mode(np.array([1.0, 0.0, 3.0]), np.array([1.0, 0.0, 1.0]),
                       np.array([9.0, 9.0, 9.0]))  # no information on the middle one
    np.testing.assert_allclose(out, [1.0, 3.0, 3.0])
