"""mrfpe.models.simulate_batch: B chains in one call, against exact and single-chain routes.

Exact expectations come from enumerating every configuration of a 3 x 3 lattice, the
log-weights written here from theta (not from the design's tables). A chain's mean
sufficient statistic must agree within 5 Monte Carlo standard errors, the error from the
draws' integrated autocorrelation time (initial positive sequence, Geyer 1992), never
below the i.i.d. error from the exact variance.
"""

from __future__ import annotations

import itertools

import numba
import numpy as np
import pytest

import mrfpe.threads
from mrfpe.budget import MemoryBudgetError, set_memory_budget
from mrfpe.models import simulate_batch as sb
from mrfpe.models.discrete import MRF
from mrfpe.models.graph import lattice
from mrfpe.models.simulate import simulate
from mrfpe.models.simulate_batch import chain_seeds, simulate_batch
from mrfpe.models.terms import Coupling, Field


def _model(q: int) -> MRF:
    return MRF(lattice(4), q, [Coupling(), Field()])


def _exact_moments(q: int, shape: tuple[int, int], theta: np.ndarray):
    """Mean and variance of S(x) at ``theta`` = (J, h_1 .. h_{q-1}) by enumeration."""
    design, _, _ = _model(q).compile(shape)
    X = np.array(list(itertools.product(range(q), repeat=design.graph.n_nodes)))
    e = design.graph.edges
    h = np.concatenate([[0.0], theta[1:]])
    lw = theta[0] * (X[:, e[:, 0]] == X[:, e[:, 1]]).sum(axis=1) + h[X].sum(axis=1)
    p = np.exp(lw - lw.max())
    p /= p.sum()
    S = design.statistics(X)
    mean = p @ S
    return mean, p @ (S - mean) ** 2


def _iat(y: np.ndarray) -> float:
    """Integrated autocorrelation time of the series ``y`` (Geyer's initial positive sequence)."""
    y = y - y.mean()
    if not np.any(y):
        return 1.0
    f = np.fft.rfft(y, 2 * y.size)
    acf = np.fft.irfft(f * np.conj(f))[:y.size]
    acf /= acf[0]
    tau = 1.0
    for k in range(1, y.size - 1, 2):
        pair = acf[k] + acf[k + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return tau


def _check_chain(S: np.ndarray, mean: np.ndarray, var: np.ndarray) -> None:
    N = S.shape[0]
    for p in range(S.shape[1]):
        se = max(np.sqrt(S[:, p].var() * _iat(S[:, p]) / N), np.sqrt(var[p] / N))
        err = abs(S[:, p].mean() - mean[p])
        assert err <= 5 * se + 1e-12, (p, err / se, mean, S.mean(axis=0))


@pytest.mark.parametrize("q", [2, 3])
@pytest.mark.parametrize("method", ["gibbs", "swendsen_wang"])
def test_rows_match_exact_expectations(q, method):
    shape = (3, 3)
    design, _, _ = _model(q).compile(shape)
    theta = np.array([[0.0, *[0.3] * (q - 1)], [0.5, *np.linspace(-0.4, 0.2, q - 1)],
                      [1.0, *[0.0] * (q - 1)]])
    out = simulate_batch(design, design.psi(theta), 3000, seed=3, method=method,
                         n_sweeps=20, thin=1)
    assert out.shape == (3, 3000, 9) and out.dtype == np.int64
    for b in range(theta.shape[0]):
        _check_chain(design.statistics(out[b]), *_exact_moments(q, shape, theta[b]))


def test_chain_equals_single_chain_call_with_its_seed():
    """Chain b is simulate(psi_b, seed=chain_seeds(seed, B)[b]): Gibbs and Swendsen-Wang
    chains mixed under "auto" (a negative coupling is not ferromagnetic)."""
    design, _, _ = _model(3).compile((6, 7))
    theta = np.array([[0.4, 0.1, -0.2], [-0.5, 0.0, 0.3], [0.9, 0.2, 0.2], [-0.1, 0.0, 0.0]])
    psi = design.psi(theta)
    out = simulate_batch(design, psi, 4, seed=11, n_sweeps=3, thin=2)
    seeds = chain_seeds(11, theta.shape[0])
    for b in range(theta.shape[0]):
        ref = simulate(design, psi[b], 4, seed=int(seeds[b]), n_sweeps=3, thin=2)
        np.testing.assert_array_equal(out[b], ref)
    # a shorter batch is a prefix of a longer one
    np.testing.assert_array_equal(simulate_batch(design, psi[:2], 4, seed=11, n_sweeps=3,
                                                 thin=2), out[:2])
    assert np.array_equal(chain_seeds(5, 3), chain_seeds(5, 8)[:3])


@pytest.mark.parametrize("n_chains", [1, 5])
@pytest.mark.parametrize("method", ["gibbs", "swendsen_wang"])
def test_draws_do_not_depend_on_thread_count(monkeypatch, n_chains, method):
    """One thread vs two: with one chain and two threads the blocks layout runs (forced:
    every core counted spare, a thread for any work), else one chain per thread."""
    monkeypatch.setattr(sb, "spare_cores", lambda: 2)
    monkeypatch.setattr(mrfpe.threads, "MIN_EVALS_PER_THREAD", 1)
    design, _, _ = _model(2).compile((96, 96))  # 4608 nodes a class: two blocks
    psi = design.psi(np.linspace([0.2, -0.1], [0.8, 0.1], n_chains))
    have = numba.get_num_threads()
    try:
        runs = []
        for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(t)
            runs.append(simulate_batch(design, psi, 2, seed=4, method=method, n_sweeps=3,
                                       thin=1))
    finally:
        numba.set_num_threads(have)
    np.testing.assert_array_equal(runs[0], runs[1])


def test_init_one_or_one_per_chain():
    design, _, _ = _model(3).compile((4, 5))
    psi = design.psi(np.array([[0.3, 0.0, 0.0]] * 3))
    starts = np.random.default_rng(0).integers(0, 3, (3, 4, 5))
    out = simulate_batch(design, psi, 2, seed=0, n_sweeps=0, thin=1, init=starts)
    np.testing.assert_array_equal(out[:, 0], starts.reshape(3, -1))
    out = simulate_batch(design, psi, 1, seed=0, n_sweeps=0, init=starts[0])
    np.testing.assert_array_equal(out[:, 0], np.broadcast_to(starts[0].reshape(-1), (3, 20)))
    flat = simulate_batch(design, psi, 1, seed=0, n_sweeps=2, init=starts.reshape(3, -1))
    np.testing.assert_array_equal(flat, simulate_batch(design, psi, 1, seed=0, n_sweeps=2,
                                                       init=starts))


def test_model_simulate_theta_rows():
    m = _model(2)
    theta = np.array([[0.3, 0.0], [0.6, 0.1]])
    x = m.simulate(theta, shape=(5, 6), n=3, seed=2, n_sweeps=4, thin=1)
    assert x.shape == (2, 3, 5, 6)
    seeds = chain_seeds(2, 2)
    for b in range(2):
        one = m.simulate(theta[b], shape=(5, 6), n=3, seed=int(seeds[b]), n_sweeps=4, thin=1)
        assert one.shape == (3, 5, 6)
        np.testing.assert_array_equal(x[b], one)


@pytest.mark.parametrize(("theta", "match"), [
    ([[0.3, 0.0, 1.0]], r"theta rows must have 2 entries"),
    ([[0.3, 0.0], [np.nan, 0.0]], r"theta row 1 must be finite"),
    ([[0.3, 0.0], [0.1, np.inf]], r"theta row 1 must be finite"),
])
def test_bad_theta_rows(theta, match):
    with pytest.raises(ValueError, match=match):
        _model(2).simulate(theta, shape=(4, 4))


def test_bad_inputs_refused_before_work():
    design, _, _ = _model(2).compile((4, 4))
    psi = design.psi(np.array([[0.3, 0.0], [0.2, 0.0]]))
    with pytest.raises(ValueError, match=r"psi_rows must be \(B, 2\)"):
        simulate_batch(design, psi[:, :1])
    with pytest.raises(ValueError, match=r"psi_rows row 1 must hold finite"):
        simulate_batch(design, np.array([[0.3, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match=r"init must be .*one per chain \(2, 16\); got "
                                         r"shape \(3, 16\)"):
        simulate_batch(design, psi, init=np.zeros((3, 16), int))
    with pytest.raises(ValueError, match="method must be one of"):
        simulate_batch(design, psi, method="metropolis")
    with pytest.raises(ValueError, match=r"method=.swendsen_wang. needs .* row 1"):
        simulate_batch(design, design.psi(np.array([[0.3, 0.0], [-0.2, 0.0]])),
                       method="swendsen_wang")


def test_memory_refused_naming_the_size():
    set_memory_budget(10**6)
    try:
        with pytest.raises(MemoryBudgetError, match=r"simulate\(B=100 chains, n=5, shape=\(64, "
                                                    r"64\)\).* needs about [0-9.]+ MB"):
            _model(2).simulate(np.zeros((100, 2)), shape=(64, 64), n=5)
        design, _, _ = _model(2).compile((64, 64))
        with pytest.raises(MemoryBudgetError, match=r"B=100 chains"):
            simulate_batch(design, np.zeros((100, 2)), 5)
    finally:
        set_memory_budget(None)
