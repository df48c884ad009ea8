"""Discrete MRFs: every estimator against brute force from the model's definition.

Each test model's unnormalised log-probability is written out by hand here (an
independent route), and the pseudolikelihood, codings, block pseudolikelihood
and exact likelihood are computed from it by changing states one node (or one
block) at a time, or by listing every configuration.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.special import logsumexp

from mrfpe import models
from mrfpe.models import MRF, Coupling, EdgeCovariate, Field, NodeCovariate, Potential, lattice

RNG = np.random.default_rng(20261205)


def _lattice_pairs(H, W, offsets):
    for r in range(H):
        for c in range(W):
            for t, (dr, dc) in enumerate(offsets):
                r2, c2 = r + dr, c + dc
                if 0 <= r2 < H and 0 <= c2 < W:
                    yield r * W + c, r2 * W + c2, t


def _pl(energy, x, q, nodes=None):
    x = x.ravel()
    total = 0.0
    for i in (range(x.size) if nodes is None else nodes):
        alt = []
        for a in range(q):
            y = x.copy()
            y[i] = a
            alt.append(energy(y))
        total += energy(x) - logsumexp(alt)
    return total


def _block(energy, x, q, blocks):
    x = x.ravel()
    total = 0.0
    for b in blocks:
        alt = []
        for ys in itertools.product(range(q), repeat=len(b)):
            y = x.copy()
            y[list(b)] = ys
            alt.append(energy(y))
        total += energy(x) - logsumexp(alt)
    return total


def _exact(energy, x, q):
    n = x.size
    logz = logsumexp([energy(np.array(c)) for c in itertools.product(range(q), repeat=n)])
    return energy(x.ravel()) - logz


def _cases():
    """(name, model, data shape, theta, covariates, energy(theta, cov) -> f(x))."""
    out = []
    # 8-neighbour Potts, q = 3
    off8 = ((0, 1), (1, 0), (1, 1), (1, -1))

    def potts8(th, cov, H=3, W=3):
        J, h = th[0], np.r_[0.0, th[1:]]
        pairs = list(_lattice_pairs(H, W, off8))
        return lambda x: J * sum(x[i] == x[j] for i, j, _ in pairs) + h[x].sum()
    out.append(("potts8", models.potts(3, 8), (3, 3), np.array([0.6, -0.3, 0.4]), None, potts8))

    # one coupling per direction of the 8-neighbourhood: the block pseudolikelihood must
    # take each internal edge's table by its type (the antidiagonal is not edge 3's type)
    def potts8_dir(th, cov, H=3, W=3):
        pairs = list(_lattice_pairs(H, W, off8))
        return lambda x: sum(th[t] * (x[i] == x[j]) for i, j, t in pairs)
    out.append(("potts8_dir", MRF(lattice(8, directional=True), 2, [Coupling(by_type=True)]),
                (3, 3), np.array([0.5, -0.2, 0.3, 0.9]), None, potts8_dir))

    # Ising in spins with separate horizontal/vertical couplings and a node covariate
    z = RNG.normal(size=(3, 4))

    def ising_dir(th, cov, H=3, W=4):
        Jh, Jv, h, b = th
        pairs = list(_lattice_pairs(H, W, ((0, 1), (1, 0))))
        zz = cov["z"].ravel()

        def f(x):
            s = 2.0 * x - 1
            return (sum((Jh if t == 0 else Jv) * s[i] * s[j] for i, j, t in pairs)
                    + h * s.sum() + b * (zz * s).sum())
        return f
    m = MRF(lattice(4, directional=True), 2,
            [Coupling("product", by_type=True), Field("value"), NodeCovariate("z", "value")],
            state_values=(-1, 1), name="ising_dir")
    out.append(("ising_dir", m, (3, 4), np.array([0.5, -0.2, 0.1, 0.7]), {"z": z}, ising_dir))

    # Potts with an edge covariate (contrast-sensitive) and per-state covariate effects, q = 3
    z2 = RNG.normal(size=(3, 3, 2))

    def w_fn(graph, cov):
        zz = cov["img"].reshape(graph.n_nodes, -1)
        return np.exp(-np.abs(zz[graph.edges[:, 0], 0] - zz[graph.edges[:, 1], 0]))

    def crf(th, cov, H=3, W=3):
        J, g = th[0], th[1]
        beta = th[2:].reshape(2, 2)  # feature-major: (feature, state 1..2)
        zz = cov["img"].reshape(H * W, 2)
        pairs = list(_lattice_pairs(H, W, ((0, 1), (1, 0))))
        w = {(i, j): np.exp(-abs(zz[i, 0] - zz[j, 0])) for i, j, _ in pairs}

        def f(x):
            e = sum((J + g * w[(i, j)]) * (x[i] == x[j]) for i, j, _ in pairs)
            for i in range(H * W):
                if x[i] > 0:
                    e += zz[i] @ beta[:, x[i] - 1]
            return e
        return f
    m = MRF(lattice(4), 3, [Coupling(), EdgeCovariate("contrast", values=w_fn),
                            NodeCovariate("img")], name="crf")
    out.append(("crf", m, (3, 3), np.array([0.4, 0.8, 0.3, -0.5, 0.2, 0.6]), {"img": z2}, crf))

    # a general (not log-linear) potential on a general graph: a truncated-linear pair cost
    A = np.zeros((6, 6))
    for i, j in [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 0), (0, 3)]:
        A[i, j] = A[j, i] = 1

    def pair(theta):
        lam, tau = theta[:, 0], theta[:, 1]
        d = np.abs(np.arange(4)[:, None] - np.arange(4)[None, :])
        return -lam[:, None, None] * np.minimum(d[None], tau[:, None, None])

    def node(theta):
        return np.outer(theta[:, 2], np.arange(4.0))

    pot = Potential([("smooth", (0.0, 2.0)), ("trunc", (0.5, 3.0)), ("slope", (-1.0, 1.0))],
                    pair=pair, node=node)
    m = MRF(models.from_adjacency(A), 4, potential=pot, name="trunc")

    def trunc(th, cov):
        lam, tau, sl = th
        edges = [(i, j) for i in range(6) for j in range(i + 1, 6) if A[i, j]]
        return lambda x: (-lam * sum(min(abs(int(x[i]) - int(x[j])), tau) for i, j in edges)
                          + sl * x.sum())
    out.append(("trunc", m, (6,), np.array([0.7, 1.5, 0.2]), None, trunc))
    return out


CASES = _cases()


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_estimators_against_brute_force(case):
    _name, m, shape, theta, cov, energy = case
    q = m.n_states
    x = RNG.integers(0, q, (2, *shape))
    f = energy(theta, cov)
    opts = {} if cov is None else {"covariates": cov}
    # PL
    want = sum(_pl(f, xi, q) for xi in x)
    got = m.target("pl", x, **opts).log_prob(theta)[0]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # codings: each against brute force on its colour class, and they sum to the PL
    g = m.graph(shape if len(shape) == 2 else None)
    total = 0.0
    for k, cls in enumerate(g.colour_classes()):
        ck = m.target("coding", x, coding=k, **opts).log_prob(theta)[0]
        np.testing.assert_allclose(ck, sum(_pl(f, xi, q, cls) for xi in x), rtol=1e-12)
        total += ck
    np.testing.assert_allclose(total, want, rtol=1e-12)
    assert m.n_codings(shape if len(shape) == 2 else None) == g.n_colours
    # block pseudolikelihood
    if len(shape) == 2:
        from mrfpe.models.estimators import make_blocks

        block = (2, 2)
        blocks = make_blocks(g, block, q)
    else:
        block = [np.array([0, 1]), np.array([2, 3, 4]), np.array([5])]
        blocks = block
    bt = m.target("block", x, block=block, **opts).log_prob(theta)[0]
    np.testing.assert_allclose(bt, sum(_block(f, xi, q, blocks) for xi in x), rtol=1e-12)
    # exact
    ex = m.target("exact", x, **opts).log_prob(theta)[0]
    np.testing.assert_allclose(ex, sum(_exact(f, xi, q) for xi in x), rtol=1e-10)
    # likelihood: the unnormalised log-likelihood is the energy
    lt = m.target("likelihood", x, **opts)
    np.testing.assert_allclose(lt.log_prob(theta)[0], sum(f(xi.ravel()) for xi in x), rtol=1e-12)


def test_batched_rows_are_independent():
    _name, m, shape, theta, cov, _energy = CASES[2]
    x = RNG.integers(0, 2, shape)
    t = m.target("pl", x, covariates=cov)
    th = theta + RNG.normal(scale=0.1, size=(9, theta.size))
    full = t.log_prob(th)
    np.testing.assert_allclose([t.log_prob(r)[0] for r in th], full, rtol=1e-12)
    assert t.param_names == ("coupling_horizontal", "coupling_vertical", "field", "z")


def test_distinct_rows_do_not_grow_with_the_lattice():
    m = models.potts(2, 4)
    rng = np.random.default_rng(0)  # its own stream: the shared one depends on test order
    small = m.target("pl", rng.integers(0, 2, (16, 16)))
    big = m.target("pl", rng.integers(0, 2, (256, 256)))
    # rows are (neighbour counts, state) pairs: bounded by 2 x 5 x 5 whatever the lattice
    # (which of the rare boundary rows a small lattice holds is chance, so no order)
    assert small.n_rows <= 2 * 5 * 5 and big.n_rows <= 2 * 5 * 5
    assert big.n_rows < 1e-3 * big.x.size


def test_block_tiles_cover_partial_edges():
    from mrfpe.models.estimators import make_blocks

    g = lattice(4).build((5, 7))
    blocks = make_blocks(g, (2, 3), 2)
    assert sorted(np.concatenate(blocks).tolist()) == list(range(35))
    assert sorted({b.size for b in blocks}) == [1, 2, 3, 6]  # 2x3, 2x1, 1x3, 1x1


def test_clear_errors_before_work():
    m = models.potts(2, 4)
    x = np.zeros((4, 4), dtype=int)
    with pytest.raises(ValueError, match="estimator must be one of"):
        m.target("pseudo", x)
    with pytest.raises(ValueError, match="valid options"):
        m.target("pl", x, neighbourhood=8)
    with pytest.raises(ValueError, match=r"lie in \[0, 1\]"):
        m.target("pl", np.full((3, 3), 2))
    with pytest.raises(ValueError, match="integer states"):
        m.target("pl", np.full((3, 3), 0.5))
    with pytest.raises(ValueError, match="joint states"):
        m.target("block", x, block=(4, 4))
    with pytest.raises(ValueError, match="coding must be in"):
        m.target("coding", x, coding=2)
    with pytest.raises(ValueError, match="bounds must be"):
        m.target("pl", x, bounds=[[0, 1]])
    crf = models.autologistic(["z"])
    with pytest.raises(ValueError, match="covariates must include 'z'"):
        crf.target("pl", x)
    with pytest.raises(ValueError, match=r"covariate 'z' must have shape \(4, 4\)"):
        crf.target("pl", x, covariates={"z": np.zeros((3, 4))})
    with pytest.raises(ValueError, match="not used by any term"):
        crf.target("pl", x, covariates={"z": np.zeros((4, 4)), "w": np.zeros((4, 4))})
    with pytest.raises(ValueError, match="exactly one of terms"):
        MRF(4, 2)
    with pytest.raises(ValueError, match="symmetric"):
        pot = Potential([("a", (0, 1))], pair=lambda th: np.tile(np.triu(np.ones((2, 2))),
                                                               (th.shape[0], 1, 1)))
        MRF(4, 2, potential=pot).target("pl", x).log_prob([[0.5]])
