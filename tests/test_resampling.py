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
