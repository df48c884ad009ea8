"""AGMMP (Eqs. 8.3-8.8) against the direct formula, and its log-space robustness."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import mrfpe
from mrfpe.distances import get

from ._helpers import duplicated_vs_doubled, post, random_post


def direct(x, wx, y, wy, sigma, form):
    """Eqs. 8.4-8.8 with the densities themselves (no logs): fine for small, broad sets."""
    d = x.shape[1]

    def p_set(x, wx, y, wy):
        comp = np.array([[stats.multivariate_normal(yj, sigma * np.eye(d)).pdf(xi)
                          for yj in y] for xi in x])  # N(x_i; y_j, σI)
        per_sample = comp @ wy  # Σ_j π_j^y N(x_i; y_j, σI)
        power = np.ones(len(x)) if form == "thesis" else wx
        return np.prod(per_sample ** power)

    return 0.5 * (p_set(x, wx, y, wy) + p_set(y, wy, x, wx))


@pytest.mark.parametrize("form", ["thesis", "weighted"])
@pytest.mark.parametrize("sigma", [0.05, 0.3])
def test_against_the_direct_formula(form, sigma):
    rng = np.random.default_rng(0)
    x, y = rng.random((5, 2)), rng.random((7, 2)) + 0.1
    lwx, lwy = rng.standard_normal(5), rng.standard_normal(7)
    wx, wy = np.exp(lwx) / np.exp(lwx).sum(), np.exp(lwy) / np.exp(lwy).sum()
    a, b = post(x, lwx), post(y, lwy)
    m = get("agmmp")()
    expect = direct(x, wx, y, wy, sigma, form)
    assert m.similarity(a, b, sigma=sigma, form=form) == pytest.approx(expect, rel=1e-10)
    assert m.log_similarity(a, b, sigma=sigma, form=form) == pytest.approx(np.log(expect),
                                                                            rel=1e-10)
    assert m(a, b, sigma=sigma, form=form) == pytest.approx(-np.log(expect), rel=1e-10)


def test_symmetric_by_construction():
    rng = np.random.default_rng(1)
    a, b = random_post(rng, S=20), random_post(rng, S=13, loc=0.3)
    for form in ("thesis", "weighted"):
        assert mrfpe.distance("agmmp", a, b, form=form) == mrfpe.distance("agmmp", b, a,
                                                                          form=form)


@pytest.mark.parametrize("form", ["thesis", "weighted"])
def test_thousand_samples_tiny_sigma_stay_finite(form):
    """The densities under/overflow here; the log-space computation does not."""
    rng = np.random.default_rng(2)
    a = post(rng.random((1000, 3)), rng.standard_normal(1000))
    b = post(rng.random((1000, 3)) * 0.5 + 0.3, rng.standard_normal(1000))
    m = get("agmmp")()
    d = m(a, b, sigma=1e-4, form=form)
    assert np.isfinite(d)
    assert np.isfinite(m.log_similarity(a, b, sigma=1e-4, form=form))
    s = m.similarity(a, b, sigma=1e-4, form=form)  # exp() of a huge number: 0 or inf, no warning
    assert s >= 0 and not np.isnan(s)
    # the thesis product over 1000 samples really is beyond float range
    if form == "thesis":
        assert abs(d) > 709


def test_weighted_form_is_the_thesis_form_per_sample_for_equal_weights():
    """For equal weights L_weighted = L_thesis / N; at a = a, log AGMMP = L."""
    rng = np.random.default_rng(3)
    a = post(rng.random((40, 2)))
    m = get("agmmp")()
    thesis = m.log_similarity(a, a, sigma=0.01, form="thesis")
    weighted = m.log_similarity(a, a, sigma=0.01, form="weighted")
    assert weighted * 40 == pytest.approx(thesis, rel=1e-12)


def test_thesis_form_ignores_the_first_sets_weights():
    """Why 'weighted' is the default: in Eq. 8.7 a duplicate counts, a doubled weight does not."""
    rng = np.random.default_rng(4)
    a, b = random_post(rng, S=12, scale=0.2), random_post(rng, S=12, scale=0.2, loc=0.1)
    dup, dbl = duplicated_vs_doubled(a, 3)
    m = get("agmmp")()
    assert m(dup, b, form="thesis") != pytest.approx(m(dbl, b, form="thesis"), rel=1e-6)
    assert m(dup, b, form="weighted") == pytest.approx(m(dbl, b, form="weighted"), rel=1e-12)


def test_distance_form_can_be_negative():
    """Mixture densities exceed 1 for small σ, so −log AGMMP < 0: AGMMP.nonnegative is False."""
    rng = np.random.default_rng(5)
    a = random_post(rng, S=30, scale=0.01)
    assert get("agmmp").nonnegative is False
    assert mrfpe.distance("agmmp", a, a, sigma=1e-4) < 0


def test_zero_weight_samples_change_nothing_in_the_weighted_form():
    rng = np.random.default_rng(6)
    a, b = random_post(rng, S=10), random_post(rng, S=10, loc=0.2)
    theta = np.vstack([a["theta"].values, [[5.0, 5.0]]])
    lw = np.append(a["log_weight"].values, -np.inf)
    a0 = post(theta, lw)
    assert mrfpe.distance("agmmp", a0, b) == pytest.approx(mrfpe.distance("agmmp", a, b),
                                                           rel=1e-12)


def test_more_similar_sets_score_higher():
    rng = np.random.default_rng(7)
    a = random_post(rng, S=50, scale=0.1)
    near = random_post(rng, S=50, scale=0.1, loc=0.05)
    far = random_post(rng, S=50, scale=0.1, loc=0.8)
    m = get("agmmp")()
    for form in ("thesis", "weighted"):
        assert m.log_similarity(a, near, sigma=0.01, form=form) > m.log_similarity(
            a, far, sigma=0.01, form=form)


@pytest.mark.parametrize("form", ["thesis", "weighted"])
def test_pairwise_parallel_equals_serial(form):
    rng = np.random.default_rng(8)
    sets = [random_post(rng, S=15, loc=0.1 * k) for k in range(4)]
    m = get("agmmp")()
    serial = m.pairwise(sets, sigma=0.02, form=form)
    parallel = m.pairwise(sets, sigma=0.02, form=form, n_jobs=2)
    np.testing.assert_array_equal(serial, parallel)
    np.testing.assert_array_equal(serial, serial.T)


@pytest.mark.parametrize("params", [{"sigma": 0.0}, {"sigma": -1.0}, {"sigma": np.inf},
                                    {"form": "bogus"}])
def test_bad_parameters_raise(params):
    rng = np.random.default_rng(9)
    a = random_post(rng)
    with pytest.raises(ValueError, match=next(iter(params))):
        mrfpe.distance("agmmp", a, a, **params)


def _cdist_route(x, y, log_wy, sigma):
    """Independent route: scipy cdist squared distances + scipy logsumexp (the old body)."""
    from scipy.spatial.distance import cdist
    from scipy.special import logsumexp

    keep = np.isfinite(log_wy)
    a = -0.5 * cdist(x, y[keep], "sqeuclidean") / sigma + log_wy[keep][None, :]
    return logsumexp(a, axis=1) - 0.5 * x.shape[1] * np.log(2.0 * np.pi * sigma)


@pytest.mark.parametrize("sigma", [0.5, 5e-3, 1e-4, 1e-8])
@pytest.mark.parametrize("d", [1, 3])
def test_shared_mixture_matches_cdist_route(sigma, d):
    from mrfpe.distances.agmmp import log_mixture_density

    rng = np.random.default_rng(5)
    x = rng.random((120, d))
    y = np.vstack([rng.random((60, d)), x[:40] + 1e-9 * rng.standard_normal((40, d))])
    lw = rng.standard_normal(100)
    lw[::7] = -np.inf  # zero-weight components
    lw -= np.logaddexp.reduce(lw[np.isfinite(lw)])
    got = log_mixture_density(x, y, lw, sigma)
    want = _cdist_route(x, y, lw, sigma)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
