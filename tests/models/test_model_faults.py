"""Declared models fail fast, in one line naming the argument, or give the right number.

Cases an audit found mishandled: an O(q^2) name check, bare numpy ``MemoryError``s from
huge designs and simulations, +inf / NaN log-potentials, a finite log-potential meeting
the old -1e300 "forbidden" stand-in, wrong advice for an empty support, and NaN edges.
Numbers are checked against brute force written here from the potential's tables.
"""

from __future__ import annotations

import itertools
import signal
import time
from contextlib import contextmanager

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.special import logsumexp

from mrfpe import models
from mrfpe.budget import MemoryBudgetError, set_memory_budget
from mrfpe.models import MRF, Coupling, Field, NodeCovariate, Potential, lattice
from mrfpe.models.graph import from_adjacency, from_networkx
from mrfpe.models.simulate import simulate


@contextmanager
def _deadline(seconds):
    """Fail (rather than hang) if the block runs longer than ``seconds``."""
    def _raise(*_):
        raise TimeoutError(f"over {seconds} s")
    old = signal.signal(signal.SIGALRM, _raise)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@contextmanager
def _budget(value):
    old = set_memory_budget(value)
    try:
        yield
    finally:
        set_memory_budget(old)


def _one_line(err):
    assert "\n" not in str(err.value), str(err.value)
    return str(err.value)


def test_param_names_of_a_million_states_is_linear():
    with _deadline(60):
        t = time.perf_counter()
        names = MRF(lattice(4), 10**6, [Field()]).param_names()
        took = time.perf_counter() - t
    assert len(names) == 10**6 - 1 and names[-1] == "field_999999" and took < 30
    with pytest.raises(ValueError, match=r"declare the parameter name\(s\) field_1, field_2 twice"):
        MRF(4, 3, [Field(), Field()]).param_names()


@pytest.mark.parametrize("terms", [[Coupling()], [Field()], [Coupling(), NodeCovariate("z")]])
def test_a_million_states_fail_on_the_memory_budget_naming_n_states(terms):
    m = MRF(lattice(4), 10**6, terms)
    cov = {"z": np.zeros((3, 3))} if len(terms) > 1 else {}
    with _budget("8GB"), _deadline(30), pytest.raises(MemoryBudgetError) as err:
        m.target("pl", np.zeros((3, 3), dtype=int), covariates=cov or None)
    msg = _one_line(err)
    assert "n_states=1000000" in msg and "TB" in msg and "memory budget of 8 GB" in msg
    if not cov:
        with _budget("8GB"), pytest.raises(MemoryBudgetError, match="n_states=1000000"):
            m.simulate(np.zeros(len(m.param_names())), shape=(3, 3))


def test_a_potential_design_is_checked_before_it_is_built():
    pot = Potential([("a", (0.0, 1.0))], pair=lambda th: np.zeros((th.shape[0], 300, 300)))
    with _budget("100MB"), pytest.raises(MemoryBudgetError, match=r"n_states=300 .* needs "
                                                                   r"about 261 GB"):
        MRF(4, 300, potential=pot).target("pl", np.zeros((3, 3), dtype=int))


@pytest.mark.parametrize("kwargs,names", [
    ({"n": 10**9, "shape": (64, 64)}, ("n=1000000000", "shape=(64, 64)")),
    ({"shape": (100000, 100000)}, ("n=1", "shape=(100000, 100000)")),
    ({"shape": (20000, 20000)}, ("n=1", "shape=(20000, 20000)")),
])
def test_simulate_checks_memory_before_any_work(kwargs, names):
    m = models.potts(3)
    with _budget("8GB"), _deadline(30), pytest.raises(MemoryBudgetError) as err:
        t = time.perf_counter()
        m.simulate([0.5, 0.0, 0.0], seed=0, **kwargs)
    assert time.perf_counter() - t < 1.0
    msg = _one_line(err)
    assert all(s in msg for s in names) and "needs about" in msg and "draw fewer (n)" in msg


def test_simulate_on_a_design_and_the_likelihood_simulator_check_memory_too():
    m = models.potts(2)
    design, _, _ = m.compile((3, 3))
    with _budget("200KB"):
        with pytest.raises(MemoryBudgetError, match=r"simulate\(n=10000, shape=\(3, 3\)\)"):
            simulate(design, design.psi(np.array([[0.5, 0.0]]))[0], 10**4)
        lik = m.target("likelihood", np.zeros((3, 3), dtype=int))
        with pytest.raises(MemoryBudgetError, match=r"n=10000"):
            lik.simulate([0.5, 0.0], n=10**4)
        assert simulate(design, design.psi(np.array([[0.5, 0.0]]))[0], 10).shape == (10, 9)


def _pot(tab, node=None, names=(("a", (0.0, 1.0)),)):
    """A potential with one fixed pair table (scaled by nothing) and optional node table."""
    tab = np.asarray(tab, dtype=float)
    return Potential(list(names), pair=lambda th: np.broadcast_to(tab, (th.shape[0], *tab.shape)),
                     node=None if node is None else lambda th: np.broadcast_to(
                         np.asarray(node, float), (th.shape[0], len(node))))


@pytest.mark.parametrize("bad,word", [(np.inf, r"\+inf"), (np.nan, "NaN")])
def test_plus_inf_and_nan_potentials_are_refused_naming_theta_and_the_callable(bad, word):
    def pair(th):
        t = np.broadcast_to(np.eye(3), (th.shape[0], 3, 3)) * th[:, :1, None]
        return np.where(th[:, :1, None] > 0.5, bad, t)  # bad only at some theta

    m = MRF(4, 3, potential=Potential([("lam", (0.0, 1.0)), ("tau", (0.0, 1.0))], pair=pair))
    x = np.random.default_rng(0).integers(0, 3, (4, 4))
    pl = m.target("pl", x)
    assert np.isfinite(pl.log_prob([[0.3, 0.2]])).all()
    for est in ("pl", "exact", "likelihood"):
        with pytest.raises(ValueError, match=rf"^Potential pair returned {word} at theta "
                                             rf"\(lam=0\.7, tau=0\.2\)") as err:
            m.target(est, x).log_prob([[0.3, 0.2], [0.7, 0.2]])
        _one_line(err)
    node = Potential([("a", (0.0, 1.0))], pair=lambda th: np.zeros((th.shape[0], 3, 3)),
                     node=lambda th: np.full((th.shape[0], 3), bad))
    with pytest.raises(ValueError, match=rf"^Potential node returned {word} at theta \(a=0\.5"):
        MRF(4, 3, potential=node).simulate([0.5], shape=(3, 3))


def test_an_asymmetric_forbidden_pattern_is_refused():
    tab = np.zeros((3, 3))
    tab[0, 1] = -np.inf
    with pytest.raises(ValueError, match=r"symmetric in the two states \(its -inf entries too\)"):
        MRF(4, 3, potential=_pot(tab)).target("pl", np.zeros((3, 3), int)).log_prob([[0.5]])


def _brute(tab, node, edges, n, q):
    """log p(x) of every configuration from the tables, -inf entries as zero weight."""
    X = np.array(list(itertools.product(range(q), repeat=n)))
    e = np.asarray(edges)
    lw = tab[X[:, e[:, 0]], X[:, e[:, 1]]].sum(1) + np.asarray(node)[X].sum(1)
    return X, lw - logsumexp(lw)


def _brute_pl(tab, node, edges, x, q):
    total = 0.0
    for i in range(x.size):
        alt = np.repeat(x[None], q, 0)
        alt[:, i] = np.arange(q)
        e = np.asarray(edges)
        lw = tab[alt[:, e[:, 0]], alt[:, e[:, 1]]].sum(1) + np.asarray(node)[alt].sum(1)
        total += lw[x[i]] - logsumexp(lw)
    return total


@pytest.mark.parametrize("c", [0.7, 1e300])
def test_a_huge_finite_log_potential_does_not_meet_the_forbidden_marker(c):
    """State 2 goes with anything, 0-1 pairs are forbidden, 0-0 pairs weigh ``c``. With the
    old -1e300 stand-in, c = 1e300 made a forbidden alternative weigh exp(0)."""
    tab = np.array([[c, -np.inf, 0.0], [-np.inf, 0.0, 0.0], [0.0, 0.0, 0.0]])
    node = [0.0, 0.1, -0.2]
    g = from_adjacency(np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]]))  # the path 0 - 1 - 2
    m = MRF(g, 3, potential=_pot(tab, node))
    x = np.array([0, 2, 1])  # the middle node's alternatives 0 and 1 are forbidden
    got = m.target("pl", x).log_prob([[0.5]])[0]
    want = _brute_pl(tab, node, g.edges, x, 3)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    _, lp = _brute(tab, node, g.edges, 3, 3)
    for method in ("enumerate", "eliminate"):
        exact = m.target("exact", x, method=method).log_prob([[0.5]])[0]
        np.testing.assert_allclose(exact, lp[9 * 0 + 3 * 2 + 1], rtol=1e-12)
    assert m.target("pl", np.array([0, 1, 2])).log_prob([[0.5]])[0] == -np.inf  # forbidden data
    assert m.target("exact", np.array([0, 1, 2])).log_prob([[0.5]])[0] == -np.inf
    assert m.target("likelihood", np.array([0, 1, 2])).log_prob([[0.5]])[0] == -np.inf
    draws = m.simulate([0.5], n=200, seed=1, n_sweeps=20, thin=1, init=[0, 2, 1])
    assert not np.any((draws[:, :-1] + draws[:, 1:] == 1) & (draws[:, :-1] != draws[:, 1:]))
    if c > 1:  # all the mass on 0 0 0
        assert np.all(draws[-100:] == 0)


def test_forbidden_configurations_in_codings_blocks_and_the_calibration_statistics():
    tab = np.array([[0.3, -np.inf, 0.0], [-np.inf, 0.5, 0.1], [0.0, 0.1, -0.2]])
    m = MRF(lattice(4), 3, potential=_pot(tab))
    x = np.array([[0, 0, 2], [2, 2, 1], [1, 1, 1]])
    total = sum(m.target("coding", x, coding=k).log_prob([[0.5]])[0] for k in range(2))
    np.testing.assert_allclose(total, m.target("pl", x).log_prob([[0.5]])[0], rtol=1e-12)
    np.testing.assert_allclose(m.target("pl", x).log_prob([[0.5]])[0],
                               _brute_pl(tab, [0, 0, 0], m.graph((3, 3)).edges, x.ravel(), 3),
                               rtol=1e-12)
    blocks = [np.array([0, 1, 3, 4]), np.array([2, 5]), np.array([6, 7]), np.array([8])]
    e, flat, want = m.graph((3, 3)).edges, x.ravel(), 0.0
    for b in blocks:  # the block conditionals, forbidden alternatives as zero weight
        Y = np.array(list(itertools.product(range(3), repeat=b.size)))
        alt = np.repeat(flat[None], Y.shape[0], 0)
        alt[:, b] = Y
        lw = tab[alt[:, e[:, 0]], alt[:, e[:, 1]]].sum(1)
        want += tab[flat[e[:, 0]], flat[e[:, 1]]].sum() - logsumexp(lw)
    np.testing.assert_allclose(m.target("block", x, block=(2, 2)).log_prob([[0.5]])[0], want,
                               rtol=1e-12)
    _, lp = _brute(tab, [0, 0, 0], e, 9, 3)
    for method in ("enumerate", "eliminate"):
        np.testing.assert_allclose(m.target("exact", x, method=method).log_prob([[0.5]])[0],
                                   lp[int(np.ravel_multi_index(tuple(flat), (3,) * 9))],
                                   rtol=1e-12)
    lik = m.target("likelihood", x)
    ys = np.array([x.ravel(), [0, 1, 2, 2, 1, 1, 1, 1, 2]])  # the second holds a 0-1 pair
    lf = lik.log_f_of_draws(ys)(np.array([[0.5], [0.2]]))
    assert lf.shape == (2, 2) and np.all(np.isfinite(lf[:, 0])) and np.all(lf[:, 1] == -np.inf)


def test_an_all_forbidden_potential_is_refused_without_advising_more_sweeps():
    m = MRF(lattice(4), 3, potential=_pot(np.full((3, 3), -np.inf)))
    with pytest.raises(ValueError, match="forbid every configuration") as err:
        m.simulate([0.5], shape=(3, 3), seed=0)
    assert "n_sweeps" not in _one_line(err)
    lik = m.target("likelihood", np.zeros((3, 3), int))
    assert lik.log_prob([[0.5]])[0] == -np.inf
    assert m.target("exact", np.zeros((3, 3), int)).log_prob([[0.5]])[0] == -np.inf
    # a node potential that leaves only states the pair table forbids together
    tab = np.array([[-np.inf, 0.0], [0.0, 0.0]])
    m = MRF(lattice(4), 2, potential=_pot(tab, node=[0.0, -np.inf]))
    with pytest.raises(ValueError, match="no state of node 0 is allowed"):
        m.simulate([0.5], shape=(2, 2))


def test_a_support_arc_consistency_cannot_refute_gets_both_pieces_of_advice():
    """Two colours on a triangle: every pair is allowed somewhere, no colouring exists."""
    tab = np.array([[-np.inf, 0.0, 0.0], [0.0, -np.inf, 0.0], [0.0, 0.0, -np.inf]])
    m = MRF(from_adjacency(np.ones((3, 3)) - np.eye(3)), 3,
            potential=_pot(tab, node=[0.0, 0.0, -np.inf]))
    with pytest.raises(ValueError, match=r"after 5 sweeps: either the chain has not reached the "
                                         r"support \(raise n_sweeps.*or the pair constraints "
                                         r"admit no configuration") as err:
        m.simulate([0.5], seed=0, n_sweeps=5)
    _one_line(err)


def test_nan_adjacency_entries_are_refused_naming_how_many_and_the_first():
    A = np.zeros((4, 4))
    A[0, 1] = A[1, 0] = 1.0
    A[2, 3] = A[3, 2] = np.nan
    A[1, 2] = A[2, 1] = np.nan
    for adj in (A, sp.csr_matrix(A), sp.coo_matrix(A)):
        with pytest.raises(ValueError, match=r"^adjacency holds 4 NaN entries \(the first at "
                                             r"\(1, 2\)\)") as err:
            from_adjacency(adj)
        _one_line(err)
    B = np.zeros((3, 3))
    B[0, 1] = B[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"^adjacency holds 2 NaN entries \(the first at \(0, 1"):
        MRF(B, 2, [Coupling()])
    ok = np.array([[0, 1], [1, 0]])
    with pytest.raises(ValueError, match=r"^edge_type holds 2 NaN entries"):
        from_adjacency(ok, edge_type=np.array([[0, np.nan], [np.nan, 0]]))
    with pytest.raises(ValueError, match=r"^edge_type must hold integer types 1 \.\. T; edge "
                                         r"\(0, 1\) has 1\.5"):
        from_adjacency(ok, edge_type=np.array([[0, 1.5], [1.5, 0]]))
    with pytest.raises(ValueError, match=r"^graph must be a simple networkx\.Graph"):
        from_networkx(nx.MultiGraph([(0, 1), (0, 1)]))
