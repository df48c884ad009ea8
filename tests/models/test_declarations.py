"""State-specific covariates and couplings shared across edge types, against brute force.

Each model's sufficient statistics are written out here from the declaration's meaning
(edges listed from the offsets, states counted by hand), not from the design; the
pseudolikelihood, codings, block pseudolikelihood and exact likelihood are computed from
them by changing one node (block) at a time or by listing all q^n configurations, and
the simulator's draws are compared with the exact means of the statistics.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.special import logsumexp

from mrfpe import models
from mrfpe.models import MRF, Coupling, EdgeCovariate, Field, NodeCovariate, lattice

RNG = np.random.default_rng(20270114)
OFF8 = ((0, 1), (1, 0), (1, 1), (1, -1))  # horizontal, vertical, diagonal, antidiagonal


def _pairs(H, W, offsets=OFF8):
    """(E, 3): node i, node j, offset index, listed from the offsets."""
    return np.array([(r * W + c, (r + dr) * W + c + dc, t) for r in range(H) for c in range(W)
                     for t, (dr, dc) in enumerate(offsets)
                     if 0 <= r + dr < H and 0 <= c + dc < W])


def _all(q, n):
    return np.array(list(itertools.product(range(q), repeat=n)), dtype=np.int64)


def _potts_stats(H, W, z):
    """Straight/diagonal Potts with fields and a covariate on state 2 only:
    S(x) = (# equal straight pairs, # equal diagonal pairs, n_1, n_2, sum_i z_i [x_i = 2])."""
    P = _pairs(H, W)
    straight, zz = P[:, 2] < 2, z.ravel()

    def stats(X):
        X = np.atleast_2d(X)
        eq = X[:, P[:, 0]] == X[:, P[:, 1]]
        return np.stack([eq[:, straight].sum(1), eq[:, ~straight].sum(1), (X == 1).sum(1),
                         (X == 2).sum(1), ((X == 2) * zz).sum(1)], axis=1).astype(float)
    return stats


def _product_stats(H, W, z):
    """Spins v = (-1, 0, 1) coupled by products in two groups of directions, a 2-feature
    covariate on states 0 and 2: S(x) = (main, cross, w_0_0, w_0_2, w_1_0, w_1_2)."""
    P = _pairs(H, W)
    main = np.isin(P[:, 2], (0, 2))  # horizontal and diagonal
    zz = z.reshape(H * W, 2)

    def stats(X):
        X = np.atleast_2d(X)
        v = X - 1.0
        prod = v[:, P[:, 0]] * v[:, P[:, 1]]
        cov = [((X == a) * zz[:, k]).sum(1) for k in range(2) for a in (0, 2)]
        return np.stack([prod[:, main].sum(1), prod[:, ~main].sum(1), *cov], axis=1)
    return stats


def _cases():
    z = RNG.normal(size=(3, 3))
    potts = MRF(lattice(8, directional=True), 3,
                [Coupling(by_type={"straight": ("horizontal", "vertical"),
                                   "diagonal": ("diagonal", "antidiagonal")}),
                 Field(), NodeCovariate("z", states=(2,))], name="potts8_state_cov")
    w = RNG.normal(size=(2, 3, 2))
    prod = MRF(lattice(8, directional=True), 3,
               [Coupling("product", by_type={"main": ("horizontal", "diagonal"),
                                             "cross": ("vertical", "antidiagonal")}),
                NodeCovariate("w", states=[0, 2])], state_values=(-1, 0, 1), name="prod")
    return [("potts8", potts, (3, 3), {"z": z}, _potts_stats(3, 3, z),
             ("coupling_straight", "coupling_diagonal", "field_1", "field_2", "z_2"),
             np.array([0.5, -0.3, 0.2, -0.4, 0.7])),
            ("product", prod, (2, 3), {"w": w}, _product_stats(2, 3, w),
             ("coupling_main", "coupling_cross", "w_0_0", "w_0_2", "w_1_0", "w_1_2"),
             np.array([0.6, -0.4, 0.3, -0.5, 0.8, 0.2]))]


CASES = _cases()


def _cond(theta, stats, x, q, nodes):
    """sum over ``nodes`` of log p(x_i | rest), one node changed at a time."""
    total = 0.0
    for i in nodes:
        alt = np.repeat(x[None], q, axis=0)
        alt[:, i] = np.arange(q)
        e = stats(alt) @ theta
        total += e[x[i]] - logsumexp(e)
    return total


def _block(theta, stats, x, q, blocks):
    total = 0.0
    for b in blocks:
        Y = _all(q, len(b))
        alt = np.repeat(x[None], Y.shape[0], axis=0)
        alt[:, b] = Y
        e = stats(alt) @ theta
        total += stats(x)[0] @ theta - logsumexp(e)
    return total


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_parameter_names(case):
    _, m, shape, cov, _, names, _ = case
    assert m.param_names(covariates=cov, shape=shape) == names


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_estimators_against_brute_force(case):
    _, m, shape, cov, stats, _, theta = case
    q, n = m.n_states, int(np.prod(shape))
    x = RNG.integers(0, q, (2, *shape))
    flat = x.reshape(2, n)
    want = sum(_cond(theta, stats, xm, q, range(n)) for xm in flat)
    np.testing.assert_allclose(m.target("pl", x, covariates=cov).log_prob(theta)[0], want,
                               rtol=1e-12)
    g = m.graph(shape)
    for k, nodes in enumerate(g.colour_classes()):
        got = m.target("coding", x, coding=k, covariates=cov).log_prob(theta)[0]
        np.testing.assert_allclose(got, sum(_cond(theta, stats, xm, q, nodes) for xm in flat),
                                   rtol=1e-12)
    from mrfpe.models.estimators import make_blocks

    blocks = make_blocks(g, (2, 2), q)
    got = m.target("block", x, block=(2, 2), covariates=cov).log_prob(theta)[0]
    np.testing.assert_allclose(got, sum(_block(theta, stats, xm, q, blocks) for xm in flat),
                               rtol=1e-12)
    logz = logsumexp(stats(_all(q, n)) @ theta)
    np.testing.assert_allclose(m.target("exact", x, covariates=cov).log_prob(theta)[0],
                               (stats(flat) @ theta).sum() - 2 * logz, rtol=1e-10)
    np.testing.assert_allclose(m.target("likelihood", x, covariates=cov).log_prob(theta)[0],
                               (stats(flat) @ theta).sum(), rtol=1e-12)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_simulator_against_exact_means(case):
    """Means of S(x) over the draws within 5 standard errors (batch means) of the exact ones."""
    _, m, shape, cov, stats, _, theta = case
    q, n = m.n_states, int(np.prod(shape))
    X = _all(q, n)
    S_all = stats(X)
    lw = S_all @ theta
    p = np.exp(lw - lw.max())
    p /= p.sum()
    mean = p @ S_all
    var = p @ (S_all - mean) ** 2
    draws = m.simulate(theta, shape=shape, n=6000, seed=3, covariates=cov, n_sweeps=50, thin=2)
    S = stats(draws.reshape(draws.shape[0], n))
    batch = S.reshape(20, -1, S.shape[1]).mean(axis=1)
    se = np.maximum(batch.std(axis=0, ddof=1) / np.sqrt(20), np.sqrt(var / S.shape[0]))
    err = np.abs(S.mean(axis=0) - mean)
    assert np.all(err <= 5 * se + 1e-12), (err / np.maximum(se, 1e-300), mean, S.mean(axis=0))


def test_an_array_edge_covariate_follows_model_graph_edges():
    """The documented route: build the array in the order of ``model.graph((H, W)).edges``;
    the PL equals brute force with the weights keyed by node pair, and the callable route."""
    H, W = 3, 4
    img = RNG.normal(size=(H, W))
    arr_model = MRF(lattice(8), 2, [Coupling(), EdgeCovariate("w"), Field()])
    g = arr_model.graph((H, W))
    assert np.all(g.edges[:, 0] < g.edges[:, 1])
    assert np.all(np.diff(g.edges[:, 0] * g.n_nodes + g.edges[:, 1]) > 0)  # sorted pairs
    flat = img.ravel()
    w = np.exp(-np.abs(flat[g.edges[:, 0]] - flat[g.edges[:, 1]]))
    theta = np.array([0.3, 0.9, -0.2])
    x = RNG.integers(0, 2, (H, W))
    got = arr_model.target("pl", x, covariates={"w": w}).log_prob(theta)[0]
    P = _pairs(H, W)
    wp = np.exp(-np.abs(flat[P[:, 0]] - flat[P[:, 1]]))  # keyed by the pairs listed here

    def stats(X):
        X = np.atleast_2d(X)
        eq = X[:, P[:, 0]] == X[:, P[:, 1]]
        return np.stack([eq.sum(1), eq @ wp, (X == 1).sum(1)], axis=1).astype(float)
    np.testing.assert_allclose(got, _cond(theta, stats, x.ravel(), 2, range(H * W)),
                               rtol=1e-12)

    def contrast(graph, cov):
        z = cov["img"]
        return np.exp(-np.abs(z[graph.edges[:, 0]] - z[graph.edges[:, 1]]))
    fn_model = MRF(lattice(8), 2, [Coupling(), EdgeCovariate("w", values=contrast), Field()])
    np.testing.assert_allclose(fn_model.target("pl", x, covariates={"img": img}).log_prob(theta),
                               got, rtol=1e-12)


def test_a_group_may_be_one_type_and_leave_others_to_another_term():
    """Edge types a mapping leaves out get no coupling from that term: two terms of different
    kinds cover the straight and the diagonal edges."""
    m = MRF(lattice(8, directional=True), 2,
            [Coupling(by_type={"straight": ("horizontal", "vertical")}),
             Coupling("product", by_type={"diag": "diagonal", "anti": ["antidiagonal"]},
                      name="spin")], state_values=(-1, 1))
    assert m.param_names() == ("coupling_straight", "spin_diag", "spin_anti")
    P = _pairs(3, 3)

    def stats(X):
        X = np.atleast_2d(X)
        v = 2.0 * X - 1
        eq = X[:, P[:, 0]] == X[:, P[:, 1]]
        prod = v[:, P[:, 0]] * v[:, P[:, 1]]
        return np.stack([eq[:, P[:, 2] < 2].sum(1), prod[:, P[:, 2] == 2].sum(1),
                         prod[:, P[:, 2] == 3].sum(1)], axis=1)
    theta = np.array([0.4, -0.3, 0.6])
    x = RNG.integers(0, 2, (3, 3))
    np.testing.assert_allclose(m.target("pl", x).log_prob(theta)[0],
                               _cond(theta, stats, x.ravel(), 2, range(9)), rtol=1e-12)


def test_one_edge_type_grouped_names_the_group():
    m = MRF(lattice(4), 2, [Coupling(by_type={"all": "edge"})])
    assert m.param_names() == ("coupling_all",)
    np.testing.assert_allclose(m.target("pl", np.eye(3, dtype=int)).log_prob([0.5]),
                               models.potts(2).target("pl", np.eye(3, dtype=int)).log_prob(
                                   [[0.5, 0.0]]), rtol=1e-12)


@pytest.mark.parametrize("build,match", [
    (lambda: MRF(lattice(8, directional=True), 3, [Coupling(by_type={"s": ("horizontal", "up")})]),
     r"^Coupling by_type names edge type\(s\) 'up' the graph does not have; its edge types: "
     r"'horizontal', 'vertical', 'diagonal', 'antidiagonal'$"),
    (lambda: MRF(lattice(4), 3, [Coupling(by_type={"s": ("horizontal",)})]),
     r"^Coupling by_type names edge type\(s\) 'horizontal' the graph does not have; its edge "
     r"types: 'edge'$"),
    (lambda: Coupling(by_type={"a": ("horizontal", "vertical"), "b": ("vertical",)}),
     r"^Coupling by_type lists the edge type 'vertical' twice \(in 'a' and 'b'\)"),
    (lambda: Coupling(by_type={"a": ("horizontal", "horizontal")}),
     r"^Coupling by_type lists the edge type 'horizontal' twice"),
    (lambda: Coupling(by_type={}), r"^Coupling by_type must be True, False or a non-empty"),
    (lambda: Coupling(by_type={"a b": "horizontal"}), r"^Coupling by_type group names must be"),
    (lambda: Coupling(by_type={"a": ()}), r"^Coupling by_type\['a'\] must be an edge type"),
    (lambda: Coupling(by_type={"a": (1, 2)}), r"^Coupling by_type\['a'\] must be an edge type"),
    (lambda: Coupling(by_type="horizontal"), r"^Coupling by_type must be True, False or a "),
    (lambda: MRF(lattice(4), 3, [NodeCovariate("z", states=(3,))]),
     r"^NodeCovariate 'z' states must lie in \[0, 2\] for n_states=3; got \(3,\)$"),
    (lambda: MRF(lattice(4), 3, [NodeCovariate("z", states=(0, 1, 2))]),
     r"^NodeCovariate 'z' states lists all 3 states"),
    (lambda: NodeCovariate("z", states=(1, 1)), r"^states lists the state 1 twice"),
    (lambda: NodeCovariate("z", states=(-1,)), r"^states must be one state or a non-empty"),
    (lambda: NodeCovariate("z", states=()), r"^states must be one state or a non-empty"),
    (lambda: NodeCovariate("z", states=(True,)), r"^states must be one state or a non-empty"),
    (lambda: NodeCovariate("z", states="12"), r"^states must be one state or a non-empty"),
    (lambda: NodeCovariate("z", kind="value", states=(1,)),
     r"^NodeCovariate 'z': states= needs kind='indicator'"),
])
def test_declaration_errors_are_one_line_naming_the_argument(build, match):
    with pytest.raises(ValueError, match=match) as err:
        build()
    assert "\n" not in str(err.value)


def test_one_state_and_numpy_states_are_accepted():
    a = MRF(4, 3, [NodeCovariate("z", states=2)])
    b = MRF(4, 3, [NodeCovariate("z", states=np.array([2]))])
    z = RNG.normal(size=(3, 3))
    assert a.param_names(covariates={"z": z}, shape=(3, 3)) == ("z_2",)
    assert b.param_names(covariates={"z": z}, shape=(3, 3)) == ("z_2",)
    assert hash(Coupling(by_type={"a": "edge"})) == hash(Coupling(by_type={"a": "edge"}))
