"""Auto-logistic Ising/Potts: PL vs exact enumeration, Gibbs sampler."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from mrfpe.models.short_forms import (
    PottsExactLikelihood,
    PottsPseudoLikelihood,
    gibbs_sample,
    sufficient_statistics,
)
from mrfpe.targets import get, maximise


def _energy(theta, x, q):
    """log of the unnormalised probability, written directly from the definition."""
    J, h = theta[0], np.concatenate([[0.0], theta[1:]])
    pairs = sum(x[r, c] == x[r + dr, c + dc] for r in range(x.shape[0]) for c in range(x.shape[1])
                for dr, dc in ((0, 1), (1, 0))
                if r + dr < x.shape[0] and c + dc < x.shape[1])
    return J * pairs + sum(h[v] for v in x.ravel())


@pytest.mark.parametrize("q,shape", [(2, (2, 3)), (3, (2, 2))])
def test_exact_and_pl_against_enumeration(q, shape):
    rng = np.random.default_rng(q)
    x = rng.integers(0, q, (2, *shape))
    theta = np.array([0.7, *rng.normal(size=q - 1)])
    n = int(np.prod(shape))
    allc = [np.array(c).reshape(shape) for c in itertools.product(range(q), repeat=n)]
    logz = np.logaddexp.reduce([_energy(theta, c, q) for c in allc])
    exact = sum(_energy(theta, xi, q) - logz for xi in x)
    t_exact = PottsExactLikelihood(x, n_states=q)
    np.testing.assert_allclose(t_exact.log_prob(theta)[0], exact, rtol=1e-12)
    np.testing.assert_allclose(t_exact.log_partition(theta)[0], logz, rtol=1e-12)
    # PL: each site's conditional from the definition p(x_i | rest) = p(x) / sum_a p(x with a)
    pl = 0.0
    for xi in x:
        for r, c in itertools.product(range(shape[0]), range(shape[1])):
            alts = []
            for a in range(q):
                y = xi.copy()
                y[r, c] = a
                alts.append(_energy(theta, y, q))
            pl += _energy(theta, xi, q) - np.logaddexp.reduce(alts)
    t_pl = PottsPseudoLikelihood(x, n_states=q)
    np.testing.assert_allclose(t_pl.log_prob(theta)[0], pl, rtol=1e-12)
    # the PL is an upper bound of nothing in general, but equals the likelihood at J = 0
    th0 = theta.copy()
    th0[0] = 0.0
    np.testing.assert_allclose(t_pl.log_prob(th0), t_exact.log_prob(th0), rtol=1e-12)


def test_pl_and_ml_agree_on_gibbs_data():
    x = gibbs_sample([0.5, 0.3], (3, 4), n_samples=300, n_sweeps=50, thin=3, seed=0)
    ml, _ = maximise(get("potts_exact", x), grid=9)
    pl, _ = maximise(get("potts", x), grid=9)
    assert np.linalg.norm(ml - [0.5, 0.3]) < 0.25
    assert np.linalg.norm(pl - ml) < 0.25


def test_gibbs_reproducible_and_independent_at_zero_coupling():
    a = gibbs_sample([0.4, -0.2, 0.5], (6, 5), n_states=3, n_samples=3, n_sweeps=5, seed=9)
    b = gibbs_sample([0.4, -0.2, 0.5], (6, 5), n_states=3, n_samples=3, n_sweeps=5, seed=9)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (3, 6, 5) and a.min() >= 0 and a.max() <= 2
    h = np.array([0.0, -0.2, 0.5])
    x = gibbs_sample([0.0, -0.2, 0.5], (40, 40), n_states=3, n_samples=10, n_sweeps=2, seed=1)
    freq = np.bincount(x.ravel(), minlength=3) / x.size
    p = np.exp(h) / np.exp(h).sum()
    se = np.sqrt(p * (1 - p) / x.size)
    assert np.all(np.abs(freq - p) < 5 * se)


def test_partition_and_stats():
    x = gibbs_sample([0.8, 0.0], (10, 11), n_samples=2, seed=3)
    t = PottsPseudoLikelihood(x)
    th = np.random.default_rng(0).uniform(-1, 1, (6, 2))
    for kind in ("strided", "block"):
        parts = t.partition(4, kind)
        np.testing.assert_allclose(sum(p.log_prob(th) for p in parts), t.log_prob(th), rtol=1e-12)
        assert sum(p.cost for p in parts) == pytest.approx(1.0)
    s = sufficient_statistics(x, 2)
    assert s.shape == (2, 2) and np.all(s[:, 0] <= 10 * 10 + 11 * 9)
    assert t.log_prob([[5.0, 0.0]])[0] == -np.inf  # outside the default bounds


def test_bad_input():
    with pytest.raises(ValueError, match="integer states"):
        PottsPseudoLikelihood(np.full((3, 3), 0.5))
    with pytest.raises(ValueError, match="MAX_FACTOR_ENTRIES"):  # 6 x 6 is within elimination
        PottsExactLikelihood(np.zeros((40, 40), dtype=int))
    with pytest.raises(ValueError, match="n_states"):
        PottsPseudoLikelihood(np.zeros((3, 3), dtype=int), n_states=1)
    with pytest.raises(ValueError, match="lie in"):
        PottsPseudoLikelihood(np.full((3, 3), 2), n_states=2)
    with pytest.raises(ValueError, match="bounds"):
        PottsPseudoLikelihood(np.zeros((3, 3), dtype=int), bounds=[[0, 1]])
    with pytest.raises(ValueError, match="theta"):
        gibbs_sample([0.1], (3, 3))
    t = PottsPseudoLikelihood(np.zeros((3, 3), dtype=int))
    with pytest.raises(ValueError, match="NaN"):
        t.log_prob([[np.nan, 0.0]])
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        t.log_prob([[0.0, 0.0, 0.0]])


@pytest.mark.parametrize(("value", "dtype"), [(2**40, np.int64), (10**7, np.int64),
                                              (1e19, np.float64), (2**63 + 5, np.uint64)])
def test_huge_state_values_are_refused_with_the_value(value, dtype):
    x = np.zeros((4, 4), dtype=dtype)
    x[0, 0] = value
    with pytest.raises(ValueError, match=r"must lie in \[0, 1023\] \(at most 1024 states\); "
                                         rf"got values in \[0(\.0)?, {re.escape(repr(value))}\]"):
        get("potts", x)
