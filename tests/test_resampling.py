"""Tests of mrfpe.resampling: unbiasedness, variance properties, degenerate weights."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mrfpe.resampling import METHODS, resample

W = np.array([0.1, 0.2, 0.0, 0.45, 0.25])
LOG_W = np.log(W, out=np.full(W.shape, -np.inf), where=W > 0)


@pytest.mark.parametrize("method", METHODS)
def test_expected_counts_match_weights(method):
    # Unbiasedness: the mean count over many independent draws is n * w.
    rng = np.random.default_rng(0)
    n, reps = 40, 3000
    counts = np.zeros(W.size)
    for _ in range(reps):
        counts += np.bincount(resample(LOG_W, n, method, rng), minlength=W.size)
    mean = counts / reps
    # multinomial sd of a count is sqrt(n w (1-w)) <= 3.2; its mean over reps: <= 0.06
    assert np.allclose(mean, n * W, atol=0.25)
    assert mean[2] == 0  # zero weight: never selected


@pytest.mark.parametrize("method", ["systematic", "stratified", "residual"])
def test_low_variance_schemes_stay_near_n_w(method):
    rng = np.random.default_rng(1)
    n = 1000
    for _ in range(50):
        c = np.bincount(resample(LOG_W, n, method, rng), minlength=W.size)
        bound = 1 if method != "stratified" else 2 * np.sqrt(n)  # stratified: O(sqrt n) worst
        assert np.all(np.abs(c - n * W) <= bound + 1e-9)
        if method == "residual":
            assert np.all(c >= np.floor(n * W))


def test_systematic_counts_are_floor_or_ceil():
    c = np.bincount(resample(LOG_W, 37, "systematic", 3), minlength=W.size)
    assert np.all((c == np.floor(37 * W)) | (c == np.ceil(37 * W)))
    assert c.sum() == 37


@pytest.mark.parametrize("method", METHODS)
def test_degenerate_weights(method):
    assert np.all(resample([-np.inf, 0.0, -np.inf], 7, method, 0) == 1)  # one spike
    assert np.all(resample([-np.inf, np.inf, 3.0], 5, method, 0) == 1)  # +inf spike
    assert np.all(resample([np.nan, -np.inf, -1e300], 5, method, 0) == 2)  # NaN = -inf
    idx = resample(np.full(4, -np.inf), 4000, method, 0)  # all -inf: uniform
    assert set(np.unique(idx)) == {0, 1, 2, 3}
    assert np.allclose(np.bincount(idx) / 4000, 0.25, atol=0.05)
    # huge log weights do not overflow
    assert np.all(resample([1e308, -1e308], 3, method, 0) == 0)


@pytest.mark.parametrize("method", METHODS)
def test_reproducible_and_seed_dependent(method):
    lw = np.log(np.arange(1, 51, dtype=float))
    a = resample(lw, 50, method, np.random.default_rng(5))
    b = resample(lw, 50, method, np.random.default_rng(5))
    c = resample(lw, 50, method, np.random.default_rng(6))
    assert np.array_equal(a, b)
    assert not np.array_equal(np.sort(a), np.sort(c)) or method == "residual"


def test_bad_input():
    with pytest.raises(ValueError, match="log_w"):
        resample([], 3)
    with pytest.raises(ValueError, match="n must"):
        resample([0.0], 0)
    with pytest.raises(ValueError, match="n must"):
        resample([0.0], 2.5)
    with pytest.raises(ValueError, match="method"):
        resample([0.0], 2, "bogus")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.floats(-50, 50), st.just(-np.inf)), min_size=1, max_size=30),
       st.integers(1, 60), st.sampled_from(METHODS), st.integers(0, 2**32 - 1))
def test_property_valid_indices_and_support(lw, n, method, seed):
    lw = np.array(lw)
    idx = resample(lw, n, method, seed)
    assert idx.shape == (n,) and idx.dtype.kind == "i"
    assert idx.min() >= 0 and idx.max() < lw.size
    if np.isfinite(lw).any():
        assert np.all(np.isfinite(lw[idx]))  # zero-weight particles are never chosen


# -- weight utilities: boundary check, evidence, properties -------------------
from scipy import stats  # noqa: E402
from scipy.special import logsumexp  # noqa: E402

from mrfpe.resampling import (  # noqa: E402
    check_log_weights,
    ess,
    log_evidence,
    normalise_log_weights,
    perplexity,
)


def test_check_log_weights_names_the_weights():
    assert np.array_equal(check_log_weights([0.0, -np.inf]), [0.0, -np.inf])
    assert check_log_weights([np.inf, 0.0]).size == 2  # +inf allowed unless refused
    with pytest.raises(ValueError, match=r"my posterior has zero total weight.*NaN"):
        check_log_weights([np.nan, np.nan], "my posterior")
    with pytest.raises(ValueError, match="zero total weight: every log weight is -inf or NaN"):
        check_log_weights([np.nan, -np.inf])
    with pytest.raises(ValueError, match=r"w has 1 log weight\(s\) of \+inf"):
        check_log_weights([np.inf, 0.0], "w", allow_posinf=False)
    with pytest.raises(ValueError, match="holds no weights"):
        check_log_weights([])


def _gaussian_is(rng, S, d=2, sd_p=1.0, sd_q=1.5, log_c=3.0):
    """Unnormalised target c·N(0, sd_p² I) sampled by the normalised proposal N(0, sd_q² I):
    the true log normaliser is log c."""
    x = rng.normal(0, sd_q, (S, d))
    log_p = log_c + stats.norm(0, sd_p).logpdf(x).sum(1)
    log_q = stats.norm(0, sd_q).logpdf(x).sum(1)
    return log_p - log_q, log_c


def test_log_evidence_of_an_analytic_gaussian():
    lw, truth = _gaussian_is(np.random.default_rng(0), 20000)
    log_z, se = log_evidence(lw)
    assert abs(log_z - truth) < 4 * se and 0 < se < 0.02


def test_log_evidence_standard_error_is_calibrated():
    # over independent repetitions the errors scatter like the stated SE
    rng = np.random.default_rng(1)
    z = []
    for _ in range(300):
        lw, truth = _gaussian_is(rng, 400)
        log_z, se = log_evidence(lw)
        z.append((log_z - truth) / se)
    z = np.array(z)
    assert abs(z.mean()) < 0.25 and 0.8 < z.std() < 1.25


def test_log_evidence_closed_forms_and_degenerate_input():
    assert log_evidence(np.full(10, 2.0)) == (pytest.approx(2.0), 0.0)  # equal weights
    log_z, se = log_evidence([0.0, -np.inf, np.nan, 0.0])  # NaN counts as zero weight
    assert log_z == pytest.approx(np.log(0.5))
    w = np.array([1.0, 0.0, 0.0, 1.0])
    assert se == pytest.approx(np.std(w, ddof=1) / (2 * np.mean(w)))  # sd(w)/(√S mean w)
    assert np.isnan(log_evidence([1.0])[1])
    for bad in ([-np.inf, -np.inf], [np.nan], [0.0, np.inf], []):
        with pytest.raises(ValueError, match="log_w"):
            log_evidence(bad)


_LOG_W = st.lists(st.one_of(st.floats(-1e300, 1e300), st.just(-np.inf), st.just(np.nan),
                            st.sampled_from([0.0, 1.0, -700.0])), min_size=1, max_size=40)


@settings(max_examples=150, deadline=None)
@given(_LOG_W)
def test_property_weight_utilities_never_nan(lw):
    lw = np.array(lw)
    norm = normalise_log_weights(lw)
    assert not np.isnan(norm).any()
    w = np.exp(norm)
    assert np.isclose(w.sum(), 1.0)
    k = ess(lw)
    assert not np.isnan(k) and 1 - 1e-9 <= k <= lw.size * (1 + 1e-9)
    p = perplexity(lw)
    assert not np.isnan(p) and 1 / lw.size - 1e-9 <= p <= 1 + 1e-9
    if np.isfinite(lw).any():
        assert np.isclose(logsumexp(norm), 0.0)
        assert np.all(w[~np.isfinite(lw)] == 0)  # zero and NaN weights stay zero
        log_z, se = log_evidence(lw)
        assert not np.isnan(log_z) and (lw.size == 1 or se >= 0)
    idx = resample(lw, 17, "systematic", 0)
    assert idx.min() >= 0 and idx.max() < lw.size
