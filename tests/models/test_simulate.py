"""mrfpe.models.simulate against independent routes.

Exact expectations come from brute-force enumeration of all q^n configurations,
with log-weights computed here straight from theta (and the covariates), not
from the design's tables; Monte-Carlo means of the sufficient statistics must
agree within 5 standard errors (batch means, never below the i.i.d. error from
the exact variance).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mrfpe.models.discrete import MRF, Potential
from mrfpe.models.graph import from_adjacency, lattice
from mrfpe.models.short_forms import gibbs_sample
from mrfpe.models.simulate import simulate, swendsen_wang_form
from mrfpe.models.terms import Coupling, EdgeCovariate, Field, NodeCovariate
from mrfpe.threads import limit_threads


def _all(q: int, n: int) -> np.ndarray:
    return np.array(list(itertools.product(range(q), repeat=n)), dtype=np.int64)


def _exact(design, logw):
    """Exact mean and variance of S(x) from log-weights of every configuration."""
    X = _all(design.q, design.graph.n_nodes)
    lw = np.asarray(logw(X), dtype=float)
    p = np.exp(lw - lw.max())
    p /= p.sum()
    S = design.statistics(X)
    mean = p @ S
    return mean, p @ (S - mean) ** 2


def _check(design, draws, logw, n_batches=20):
    mean, var = _exact(design, logw)
    S = design.statistics(draws)
    m = S.shape[0] // n_batches
    batch = S[:m * n_batches].reshape(n_batches, m, -1).mean(axis=1)
    se = np.maximum(batch.std(axis=0, ddof=1) / np.sqrt(n_batches), np.sqrt(var / S.shape[0]))
    err = np.abs(S.mean(axis=0) - mean)
    assert np.all(err <= 5 * se + 1e-12), (err / np.maximum(se, 1e-300), mean, S.mean(axis=0))


def _potts_logw(edges, etype, J, h):
    """sum_i h[x_i] + sum_e J[type e] [x_i == x_j]; J per edge type, h per state."""
    def logw(X):
        eq = X[:, edges[:, 0]] == X[:, edges[:, 1]]
        return eq @ np.asarray(J)[etype] + np.asarray(h)[X].sum(axis=1)
    return logw


METHODS = ("gibbs", "swendsen_wang")


@pytest.mark.parametrize("method", METHODS)
def test_ising_3x3_with_field(method):
    m = MRF(lattice(4), 2, [Coupling(), Field()])
    design, names, _ = m.compile((3, 3))
    assert names == ("coupling", "field")
    theta = np.array([0.4, -0.2])
    x = simulate(design, design.psi(theta[None])[0], 20000, seed=1, method=method,
                 n_sweeps=20, thin=2)
    assert x.shape == (20000, 9) and x.dtype == np.int64
    g = design.graph
    _check(design, x, _potts_logw(g.edges, g.edge_type, [0.4], [0.0, -0.2]))


@pytest.mark.parametrize("method, J", [("gibbs", [0.5, -0.4, 0.3, 0.8]),
                                        ("swendsen_wang", [0.5, 0.1, 0.9, 0.3])])
def test_eight_neighbour_directional_q3(method, J):
    m = MRF(lattice(8, directional=True), 3, [Coupling(by_type=True), Field()])
    design, names, _ = m.compile((2, 3))
    assert names[:4] == ("coupling_horizontal", "coupling_vertical", "coupling_diagonal",
                         "coupling_antidiagonal")
    h = [0.0, 0.3, -0.4]
    psi = design.psi(np.array([[*J, *h[1:]]]))[0]
    x = simulate(design, psi, 12000, seed=2, method=method, n_sweeps=20, thin=3)
    g = design.graph
    _check(design, x, _potts_logw(g.edges, g.edge_type, J, h))


def _general_model():
    A = np.zeros((5, 5), int)
    T = np.zeros((5, 5), int)
    for i, j, t in [(0, 1, 1), (1, 2, 1), (2, 3, 2), (3, 0, 2), (1, 3, 1), (3, 4, 2)]:
        A[i, j] = A[j, i] = 1
        T[i, j] = T[j, i] = t
    g = from_adjacency(sp.csr_matrix(A), T)
    z = np.array([0.5, -1.0, 0.0, 1.5, -0.5])
    w = np.linspace(0.5, 1.5, g.n_edges)
    m = MRF(g, 3, [Coupling(by_type=True), Field(), NodeCovariate("z"), EdgeCovariate("w")])
    return m, g, z, w


@pytest.mark.parametrize("method, theta", [
    ("gibbs", [0.6, -0.5, 0.2, -0.3, 0.4, -0.6, 0.7]),
    ("swendsen_wang", [0.6, 0.2, 0.2, -0.3, 0.4, -0.6, 0.5])])
def test_general_graph_with_covariates(method, theta):
    """Node covariates (per-node tables) and an edge covariate (per-edge tables)."""
    m, g, z, w = _general_model()
    design, names, _ = m.compile(covariates={"z": z, "w": w})
    assert design.pair_per_edge and not design.node_shared
    assert names == ("coupling_type_1", "coupling_type_2", "field_1", "field_2", "z_1", "z_2",
                     "w")
    x = simulate(design, design.psi(np.array([theta]))[0], 12000, seed=3, method=method,
                 n_sweeps=20, thin=3)
    J, h, beta, gamma = theta[:2], [0.0, *theta[2:4]], [0.0, *theta[4:6]], theta[6]

    def logw(X):
        eq = X[:, g.edges[:, 0]] == X[:, g.edges[:, 1]]
        return (eq @ (np.asarray(J)[g.edge_type] + gamma * w) + np.asarray(h)[X].sum(axis=1)
                + (np.asarray(beta)[X] * z).sum(axis=1))
    _check(design, x, logw)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("values", [(0.0, 1.0), (-1.0, 1.0)])
def test_autologistic(values, method):
    """``J v(a) v(b)`` with v = (0, 1) is Potts plus node terms: Swendsen-Wang applies."""
    m = MRF(lattice(4), 2, [Coupling("product"), Field("value")], state_values=values)
    design, _, _ = m.compile((3, 3))
    theta = np.array([0.7, -0.3])
    psi = design.psi(theta[None])[0]
    x = simulate(design, psi, 20000, seed=4, method=method, n_sweeps=20, thin=2)
    v = np.asarray(values)
    e = design.graph.edges
    _check(design, x, lambda X: 0.7 * (v[X[:, e[:, 0]]] * v[X[:, e[:, 1]]]).sum(axis=1)
           - 0.3 * v[X].sum(axis=1))
    # "auto" takes Swendsen-Wang here: the same draws
    np.testing.assert_array_equal(
        simulate(design, psi, 5, seed=9, n_sweeps=3, thin=2),
        simulate(design, psi, 5, seed=9, n_sweeps=3, thin=2, method="swendsen_wang"))


def test_swendsen_wang_form():
    J, f = swendsen_wang_form(np.array([[[1.0, 0.2], [0.2, 3.0]]]))  # any ferro q = 2 table
    t = J[0] * np.eye(2) + f[0][:, None] + f[0][None, :]
    assert np.allclose(t - t[0, 1], np.array([[1.0, 0.2], [0.2, 3.0]]) - 0.2)
    assert "antiferromagnetic" in swendsen_wang_form(np.array([[[0.0, 1.0], [1.0, 0.0]]]))
    v = np.arange(3.0)
    assert "not J [a == b]" in swendsen_wang_form(np.outer(v, v)[None])
    assert "finite" in swendsen_wang_form(np.array([[[0.0, -np.inf], [-np.inf, 0.0]]]))


def test_swendsen_wang_refuses_other_tables():
    m = MRF(lattice(4), 3, [Coupling("product")])
    design, _, _ = m.compile((3, 3))
    psi = design.psi(np.array([[0.5]]))[0]
    with pytest.raises(ValueError, match=r"method='swendsen_wang'.*not J"):
        simulate(design, psi, method="swendsen_wang")
    m = MRF(lattice(4), 2, [Coupling()])
    design, _, _ = m.compile((3, 3))
    with pytest.raises(ValueError, match=r"method='swendsen_wang'.*antiferromagnetic"):
        simulate(design, design.psi(np.array([[-0.5]]))[0], method="swendsen_wang")
    # "auto" falls back to Gibbs: the same draws
    psi = design.psi(np.array([[-0.5]]))[0]
    np.testing.assert_array_equal(simulate(design, psi, 4, seed=5, n_sweeps=2),
                                  simulate(design, psi, 4, seed=5, n_sweeps=2, method="gibbs"))


def _colouring_potential(node_tab):
    """q = 3: a pair of equal states is forbidden (-inf), 0-1 pairs weigh 0.4."""
    pair_tab = np.array([[-np.inf, 0.4, 0.0], [0.4, -np.inf, 0.0], [0.0, 0.0, -np.inf]])
    return Potential(params=[("a", (0.0, 1.0))],
                     pair=lambda th: np.broadcast_to(pair_tab, (th.shape[0], 3, 3)),
                     node=lambda th: np.broadcast_to(node_tab, (th.shape[0], 3))), pair_tab


def test_forbidden_states_are_never_drawn():
    """Proper 3-colourings of a 2x3 lattice, from a random (improper) start, by Gibbs."""
    pot, pair_tab = _colouring_potential(np.array([0.0, 0.2, -0.3]))
    design, _, _ = MRF(lattice(4), 3, potential=pot).compile((2, 3))
    psi = design.psi(np.array([[0.5]]))[0]
    assert np.isneginf(psi).any()  # forbidden entries stay -inf (no finite stand-in)
    x = simulate(design, psi, 12000, seed=6, n_sweeps=20, thin=3)  # auto: Gibbs
    e = design.graph.edges
    assert np.all(x[:, e[:, 0]] != x[:, e[:, 1]])
    _check(design, x, lambda X: pair_tab[X[:, e[:, 0]], X[:, e[:, 1]]].sum(axis=1)
           + np.array([0.0, 0.2, -0.3])[X].sum(axis=1))


def test_forbidden_node_state_and_dead_node():
    pot, _ = _colouring_potential(np.array([0.0, 0.2, -np.inf]))  # 2 colours left: a chain
    g = from_adjacency(np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]]))
    design, _, _ = MRF(g, 3, potential=pot).compile()
    psi = design.psi(np.array([[0.5]]))[0]
    for seed in range(6):  # Gibbs cannot move between the two; each start finds one
        x = simulate(design, psi, 5, seed=seed, n_sweeps=5, thin=1)
        assert {tuple(r) for r in x.tolist()} <= {(0, 1, 0), (1, 0, 1)}
    with pytest.raises(ValueError, match="init puts node 1 in state 2"):
        simulate(design, psi, init=[0, 2, 0])
    pot, _ = _colouring_potential(np.full(3, -np.inf))
    design, _, _ = MRF(g, 3, potential=pot).compile()
    with pytest.raises(ValueError, match="every state of node 0 has log-potential -inf"):
        simulate(design, design.psi(np.array([[0.5]]))[0])


def test_unreachable_support_is_reported():
    """Two colours on a triangle: no proper configuration exists; every draw is checked."""
    pot, _ = _colouring_potential(np.array([0.0, 0.0, -np.inf]))
    g = from_adjacency(np.ones((3, 3)) - np.eye(3))
    design, _, _ = MRF(g, 3, potential=pot).compile()
    with pytest.raises(ValueError, match=r"forbidden pair.*raise n_sweeps.*or the pair "
                                         r"constraints admit no configuration"):
        simulate(design, design.psi(np.array([[0.5]]))[0], seed=0, n_sweeps=5)


DELTA = np.array([[0.0, 0.3, -0.2], [0.3, 0.0, 0.5], [-0.2, 0.5, 0.0]])


@pytest.mark.parametrize("case", ["products", "underflow", "forbidden", "tied"])
def test_site_update_is_the_full_conditional(case):
    """One Gibbs site update against its conditional computed here, with stratified
    uniforms (u = (k + 1/2) / N: the drawn frequencies are the CDF's steps to 1/N).

    ``products``: the fast path; ``underflow``: every state's product underflows, so
    log-weights decide; ``forbidden``: every state has a -inf pair (a start outside the
    support), so the state with the fewest of them is drawn; ``tied``: every state has
    two, and their finite log-potentials (here the node's) decide among them.
    """
    from mrfpe.models.simulate import _exp_rows, _site

    node = np.array([[0.0, 0.5, -0.3]])
    off = {"products": -1.0, "underflow": -400.0, "forbidden": -np.inf, "tied": -np.inf}[case]
    pair = (np.where(np.eye(3) == 1, 0.0, off) + DELTA)[None]
    if case == "forbidden":
        pair[0, 1, 1] = pair[0, 2, 2] = -np.inf  # state 0 now meets the fewest forbidden pairs
    x = np.array([0, 0, 1, 2], dtype=np.uint32)  # node 0's neighbours hold 0, 1, 2
    indptr, nbr, ntab = (np.array(a, dtype=np.uint32) for a in ([0, 3], [1, 2, 3], [0, 0, 0]))
    lw = node[0] + pair[0][:, [0, 1, 2]].sum(axis=1)
    if case == "forbidden":
        p = np.array([1.0, 0.0, 0.0])
    elif case == "tied":
        p = np.exp(node[0]) / np.exp(node[0]).sum()
    else:
        assert case == "products" or np.all(np.exp(lw) == 0)  # products would underflow
        p = np.exp(lw - lw.max()) / np.exp(lw - lw.max()).sum()
    N = 20000
    counts = np.zeros(3)
    for k in range(N):
        _site(0, x, node, pair, _exp_rows(node), _exp_rows(pair).reshape(-1, 3), indptr, nbr,
              ntab, (k + 0.5) / N, np.empty(3))
        counts[x[0]] += 1
    assert np.all(np.abs(counts / N - p) <= 2 / N), (counts / N, p)


@pytest.mark.parametrize("method", METHODS)
def test_seeds_reproduce_and_differ(method):
    m = MRF(lattice(4), 3, [Coupling(), Field()])
    design, _, _ = m.compile((10, 12))
    psi = design.psi(np.array([[0.8, 0.1, -0.2]]))[0]
    a = simulate(design, psi, 3, seed=11, method=method, n_sweeps=5, thin=2)
    b = simulate(design, psi, 3, seed=11, method=method, n_sweeps=5, thin=2)
    c = simulate(design, psi, 3, seed=12, method=method, n_sweeps=5, thin=2)
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)
    assert not np.array_equal(a[0], a[1])  # successive draws move


def test_draws_do_not_depend_on_threads():
    m = MRF(lattice(4), 16, [Coupling(), Field()])
    design, _, _ = m.compile((330, 330))  # 1.7e6 site-states: the budget allows two threads
    psi = design.psi(np.array([[0.6, *np.linspace(-0.5, 0.5, 15)]]))[0]
    with limit_threads(1):
        one = simulate(design, psi, 2, seed=3, method="gibbs", n_sweeps=3, thin=2)
    with limit_threads(2):
        two = simulate(design, psi, 2, seed=3, method="gibbs", n_sweeps=3, thin=2)
    np.testing.assert_array_equal(one, two)


def test_init_and_schedule():
    m = MRF(lattice(4), 3, [Coupling()])
    design, _, _ = m.compile((3, 4))
    psi = design.psi(np.array([[0.3]]))[0]
    init = np.arange(12).reshape(3, 4) % 3
    x = simulate(design, psi, 3, seed=0, n_sweeps=0, thin=1, init=init)
    np.testing.assert_array_equal(x[0], init.ravel())  # draw 0 after no sweep is the start
    y = simulate(design, psi, 3, seed=0, n_sweeps=0, thin=1, init=init.ravel())
    np.testing.assert_array_equal(x, y)
    # draw k is the state after n_sweeps + k * thin sweeps of one chain
    long = simulate(design, psi, 7, seed=4, n_sweeps=2, thin=1, init=init, method="gibbs")
    short = simulate(design, psi, 3, seed=4, n_sweeps=2, thin=2, init=init, method="gibbs")
    np.testing.assert_array_equal(short, long[::2][:3])


def test_agrees_with_potts_gibbs_sample():
    """The NumPy checkerboard sampler of mrfpe.models.short_forms, in distribution."""
    theta = np.array([0.7, 0.2, -0.3])
    design, _, _ = MRF(lattice(4), 3, [Coupling(), Field()]).compile((6, 6))
    ours = design.statistics(simulate(design, design.psi(theta[None])[0], 3000, seed=1,
                                      method="gibbs", n_sweeps=50, thin=2))
    ref = design.statistics(gibbs_sample(theta, (6, 6), 3, n_samples=3000, n_sweeps=50,
                                         thin=2, seed=2).reshape(3000, -1))

    def mean_se(S, nb=20):
        b = S.reshape(nb, -1, S.shape[1]).mean(axis=1)
        return S.mean(axis=0), b.std(axis=0, ddof=1) / np.sqrt(nb)

    (m1, s1), (m2, s2) = mean_se(ours), mean_se(ref)
    assert np.all(np.abs(m1 - m2) <= 5 * np.hypot(s1, s2)), (m1, m2, s1, s2)


def test_model_simulate_shape():
    m = MRF(lattice(4), 2, [Coupling(), Field()])
    x = m.simulate([0.3, 0.1], shape=(4, 5), n=2, seed=0, n_sweeps=3, thin=1)
    assert x.shape == (2, 4, 5) and x.dtype == np.int64


@pytest.mark.parametrize("kwargs, match", [
    ({"n": 0}, "n must be an integer >= 1"),
    ({"n": 2.0}, "n must be an integer >= 1"),
    ({"n": True}, "n must be an integer >= 1"),
    ({"n_sweeps": -1}, "n_sweeps must be an integer >= 0"),
    ({"thin": 0}, "thin must be an integer >= 1"),
    ({"method": "metropolis"}, "method must be one of auto, gibbs, swendsen_wang"),
    ({"seed": -1}, r"seed must be an integer in \[0, 2\*\*63 - 1\]"),
    ({"seed": 1.5}, r"seed must be an integer in \[0, 2\*\*63 - 1\]"),
    ({"init": "zeros"}, "init must be 'random' or an array"),
    ({"init": np.zeros((4, 3), int)}, r"init must be .* shape \(12,\) or \(3, 4\)"),
    ({"init": np.zeros((2, 12), int)}, r"init must be .* shape \(12,\)"),
    ({"init": np.full(12, 2)}, r"init must lie in \[0, 1\]"),
    ({"init": np.full(12, 0.5)}, "init must hold integer states"),
])
def test_bad_arguments(kwargs, match):
    design, _, _ = MRF(lattice(4), 2, [Coupling()]).compile((3, 4))
    psi = design.psi(np.array([[0.3]]))[0]
    with pytest.raises(ValueError, match=match):
        simulate(design, psi, **kwargs)


def test_bad_design_and_psi():
    design, _, _ = MRF(lattice(4), 2, [Coupling()]).compile((3, 4))
    with pytest.raises(ValueError, match=r"design must be an mrfpe\.models Design"):
        simulate("design", np.zeros(1))
    with pytest.raises(ValueError, match=r"psi must be one feature vector \(1,\)"):
        simulate(design, np.zeros((2, 1)))
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="psi must hold finite numbers, or -inf"):
            simulate(design, np.array([bad]))
    # -inf times a negative feature (v(a) v(b) = -1) would be a +inf log-potential
    design, _, _ = MRF(lattice(4), 2, [Coupling("product")], state_values=(-1, 1)).compile((2, 2))
    with pytest.raises(ValueError, match=r"-inf \(forbidden\) where no feature is negative"):
        simulate(design, np.array([-np.inf]))


def test_minus_inf_in_psi_draws_as_the_potentials_minus_inf():
    """A hand-made -inf in psi forbids as the potential's own -inf does."""
    pot, _ = _colouring_potential(np.array([0.0, 0.2, -0.3]))
    design, _, _ = MRF(lattice(4), 3, potential=pot).compile((2, 3))
    psi = design.psi(np.array([[0.5]]))[0]
    by_hand = np.where(np.isneginf(psi), -np.inf, psi.copy())
    np.testing.assert_array_equal(simulate(design, by_hand, 20, seed=8, n_sweeps=10, thin=2),
                                  simulate(design, psi, 20, seed=8, n_sweeps=10, thin=2))
