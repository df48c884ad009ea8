"""The auto-normal (Gaussian CAR) model: every estimator against dense linear algebra.

The precision matrix ``Q = tau (I - sum_t beta_t W_t)`` is built here from
scratch (adjacency matrices by looping over the lattice, or from the networkx
graph), and each estimator is compared with what the dense ``Q`` gives by an
independent route: ``scipy.stats.multivariate_normal`` for the exact
likelihood, conditional normal densities ``-Q_ii^{-1} Q_i,-i (x - mu)``,
``1 / Q_ii`` for the pseudolikelihood, and the Schur complement of the dense
covariance for block conditionals.
"""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest
from scipy import optimize, stats
from threadpoolctl import threadpool_limits

from mrfpe.models import from_adjacency, from_networkx, lattice
from mrfpe.models.gaussian import MAX_BLOCK_NODES, GaussianMRF, autonormal
from mrfpe.models.options import node_blocks

RNG = np.random.default_rng(20261205)


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Small dense matrices: threaded BLAS only adds contention on a shared machine."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield
OFFSETS = {4: [(0, 1), (1, 0)], 8: [(0, 1), (1, 0), (1, 1), (1, -1)]}


# ------------------------------------------------------------------------------------------------
# the independent route: dense matrices written out here
# ------------------------------------------------------------------------------------------------
def _lattice_W(H, W, offsets, periodic):
    """One dense 0/1 adjacency per offset, by looping over the lattice."""
    out = []
    for dr, dc in offsets:
        A = np.zeros((H * W, H * W))
        for r in range(H):
            for c in range(W):
                r2, c2 = r + dr, c + dc
                if periodic:
                    r2, c2 = r2 % H, c2 % W
                elif not (0 <= r2 < H and 0 <= c2 < W):
                    continue
                i, j = r * W + c, r2 * W + c2
                if i != j:
                    A[i, j] = A[j, i] = 1.0
        out.append(A)
    return out


def _types(Ws, directional):
    """Coupling matrices: one per offset (directional) or their union."""
    return Ws if directional else [np.minimum(sum(Ws), 1.0)]


def _Q(Ws, beta, tau):
    n = Ws[0].shape[0]
    return tau * (np.eye(n) - sum(b * W for b, W in zip(beta, Ws, strict=True)))


def _pd_theta(Ws, n_cov=0, rng=RNG, k=3, scale=0.9):
    """``k`` parameter vectors inside the PD region (sum_t |beta_t| rho_t < 1)."""
    rho = np.array([np.abs(np.linalg.eigvalsh(W)).max() or 1.0 for W in Ws])
    rows = []
    for _ in range(k):
        w = rng.dirichlet(np.ones(len(Ws)))
        beta = scale * rng.choice([-1, 1], len(Ws)) * w / rho
        rows.append([rng.normal(), *beta, rng.uniform(0.5, 3.0), *rng.normal(size=n_cov)])
    return np.array(rows)


def _exact(x, mu, Q):
    cov = np.linalg.inv(Q)
    return sum(stats.multivariate_normal(mu, cov).logpdf(xm) for xm in x)


def _pl(x, mu, Q, nodes=None):
    total = 0.0
    n = Q.shape[0]
    for xm in x:
        u = xm - mu
        for i in range(n) if nodes is None else nodes:
            others = np.arange(n) != i
            cmean = mu[i] - Q[i, others] @ u[others] / Q[i, i]
            total += stats.norm(cmean, np.sqrt(1.0 / Q[i, i])).logpdf(xm[i])
    return total


def _block(x, mu, Q, blocks):
    cov = np.linalg.inv(Q)
    n = Q.shape[0]
    total = 0.0
    for B in blocks:
        R = np.setdiff1d(np.arange(n), B)
        K = np.linalg.solve(cov[np.ix_(R, R)], cov[np.ix_(R, B)]).T  # Sigma_BR Sigma_RR^-1
        S = cov[np.ix_(B, B)] - K @ cov[np.ix_(R, B)]
        for xm in x:
            m = mu[B] + K @ (xm[R] - mu[R])
            total += stats.multivariate_normal(m, S).logpdf(xm[B])
    return total


def _tiles(H, W, bh, bw):
    return [np.array([r * W + c for r in range(r0, min(r0 + bh, H))
                      for c in range(c0, min(c0 + bw, W))])
            for r0 in range(0, H, bh) for c0 in range(0, W, bw)]


def _mu(theta, T, Z, n=None):
    """``m + Z gamma`` (n,), or ``m`` on every one of ``n`` nodes without covariates."""
    return theta[0] + Z @ theta[2 + T:] if Z is not None else np.full(n, theta[0])


LATTICES = [  # (neighbourhood, periodic, directional, H, W)
    (4, False, False, 4, 5),
    (4, False, True, 5, 4),
    (8, False, False, 4, 4),
    (8, False, True, 4, 5),  # separate diagonals: no closed form, sparse LU
    (4, True, False, 4, 5),
    (4, True, True, 3, 5),
    (8, True, True, 4, 3),
    (4, True, False, 2, 5),  # a width-2 torus: no closed form, eigvalsh of W
]


def _lattice_case(nb, periodic, directional, H, W, n_cov=0):
    Ws = _types(_lattice_W(H, W, OFFSETS[nb], periodic), directional)
    model = autonormal(nb, periodic=periodic, directional=directional, covariates=n_cov)
    return model, Ws


# ------------------------------------------------------------------------------------------------
# exact likelihood
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("nb", "periodic", "directional", "H", "W"), LATTICES)
def test_exact_equals_multivariate_normal_on_lattices(nb, periodic, directional, H, W):
    model, Ws = _lattice_case(nb, periodic, directional, H, W)
    x = RNG.normal(size=(2, H, W))
    theta = _pd_theta(Ws)
    t = model.target("exact", x)
    want = [_exact(x.reshape(2, -1), _mu(th, len(Ws), None, H * W), _Q(Ws, th[1:-1], th[-1]))
            for th in theta]
    np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)
    sparse = model.target("exact", x, method="sparse")
    np.testing.assert_allclose(sparse.log_prob(theta), want, rtol=1e-9)
    # only separate diagonal couplings on a free lattice lack a known spectrum
    assert t.method == ("sparse" if (nb, periodic, directional) == (8, False, True) else "eigen")


def test_exact_with_covariates_and_a_single_field():
    H, W = 4, 4
    model, Ws = _lattice_case(4, False, True, H, W, n_cov=2)
    Z = RNG.normal(size=(H, W, 2))
    x = RNG.normal(size=(H, W))
    theta = _pd_theta(Ws, n_cov=2)
    t = model.target("exact", x, covariates=Z)
    assert t.param_names == ("mean", "coupling_horizontal", "coupling_vertical", "precision",
                             "z_0", "z_1")
    want = [_exact(x.reshape(1, -1), _mu(th, 2, Z.reshape(-1, 2)),
                   _Q(Ws, th[1:3], th[3])) for th in theta]
    np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)


def test_exact_on_general_graphs():
    g = nx.gnp_random_graph(13, 0.3, seed=3)
    W = nx.to_numpy_array(g, nodelist=list(g.nodes))
    model = autonormal(g, covariates=["elevation"])
    x = RNG.normal(size=(3, 13))
    z = RNG.normal(size=13)
    theta = _pd_theta([W], n_cov=1)
    t = model.target("exact", x, covariates={"elevation": z})
    assert t.param_names == ("mean", "coupling", "precision", "elevation")
    assert t.method == "eigen"
    want = [_exact(x, th[0] + z * th[3], _Q([W], th[1:2], th[2])) for th in theta]
    np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)
    # two edge types with one coupling each: no joint spectrum, sparse LU per theta
    types = np.triu(RNG.integers(1, 3, size=(13, 13)), 1)
    types = (types + types.T) * (W > 0)
    Ws = [(types == 1).astype(float), (types == 2).astype(float)]
    typed = autonormal(from_adjacency(W, edge_type=types), directional=True)
    t2 = typed.target("exact", x)
    assert t2.method == "sparse" and t2.param_names[1:3] == ("coupling_type_1",
                                                             "coupling_type_2")
    theta2 = _pd_theta(Ws)
    want2 = [_exact(x, np.full(13, th[0]), _Q(Ws, th[1:3], th[3])) for th in theta2]
    np.testing.assert_allclose(t2.log_prob(theta2), want2, rtol=1e-9)


# ------------------------------------------------------------------------------------------------
# pseudolikelihood, codings, blocks
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("nb", "periodic", "directional", "H", "W"), LATTICES[:7])
def test_pl_codings_and_blocks_against_dense_conditionals(nb, periodic, directional, H, W):
    model, Ws = _lattice_case(nb, periodic, directional, H, W, n_cov=1)
    x = RNG.normal(size=(2, H, W))
    # four fields: enough observations for every coding to identify theta (a coding of two
    # nodes and two fields, against six parameters, is refused)
    x = np.concatenate([x, 1.0 + 0.5 * x[::-1]])
    Z = RNG.normal(size=(H, W))
    theta = _pd_theta(Ws, n_cov=1)
    T = len(Ws)
    X = x.reshape(4, -1)
    pl = model.target("pl", x, covariates=Z)
    want = [_pl(X, _mu(th, T, Z.reshape(-1, 1)), _Q(Ws, th[1:1 + T], th[1 + T]))
            for th in theta]
    got = pl.log_prob(theta)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    k = model.n_codings((H, W))
    codings = [model.target("coding", x, coding=c, covariates=Z) for c in range(k)]
    np.testing.assert_allclose(sum(c.log_prob(theta) for c in codings), got, rtol=1e-9)
    assert sum(c.cost for c in codings) == pytest.approx(1.0)
    single = model.target("block", x, block=(1, 1), covariates=Z)
    np.testing.assert_allclose(single.log_prob(theta), got, rtol=1e-9)
    for tile in ((2, 2), (2, 3), (H, W)):
        blk = model.target("block", x, block=tile, covariates=Z)
        want_b = [_block(X, _mu(th, T, Z.reshape(-1, 1)), _Q(Ws, th[1:1 + T], th[1 + T]),
                         _tiles(H, W, *tile)) for th in theta]
        np.testing.assert_allclose(blk.log_prob(theta), want_b, rtol=1e-9)
    # one block holding every node is the exact likelihood
    np.testing.assert_allclose(model.target("block", x, block=(H, W), covariates=Z)
                               .log_prob(theta),
                               model.target("exact", x, covariates=Z).log_prob(theta),
                               rtol=1e-9)


@pytest.mark.parametrize(("directional", "tile", "H", "W"), [(False, (2, 2), 9, 10),
                                                            (True, (3, 2), 18, 10)])
def test_block_second_moments_on_a_larger_lattice(directional, tile, H, W):
    """Many blocks per structure: their summed second moments (not per-block residuals)."""
    model, Ws = _lattice_case(4, False, directional, H, W, n_cov=1)
    x = RNG.normal(size=(2, H, W))
    Z = RNG.normal(size=(H, W))
    theta = _pd_theta(Ws, n_cov=1)
    T = len(Ws)
    # the theta are arbitrary, not near these white-noise data's: a box that holds them
    t = model.target("block", x, block=tile, covariates=Z, bounds={"precision": (0.0, 10.0)})
    assert any(kind == "moment" for kind, *_ in t._groups)
    assert t.n_groups <= 4  # interior, right, bottom and corner tiles
    want = [_block(x.reshape(2, -1), _mu(th, T, Z.reshape(-1, 1)),
                   _Q(Ws, th[1:1 + T], th[1 + T]), _tiles(H, W, *tile)) for th in theta]
    np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)


def test_large_offsets_lose_no_accuracy():
    """Data and covariates far from 0: the centred moments keep the quadratic forms exact."""
    H, W = 6, 7
    model, Ws = _lattice_case(4, False, False, H, W, n_cov=1)
    Z = 1e3 + RNG.normal(size=(H, W))
    th = np.array([1e6, 0.2, 1.5, 3.0])
    x = model.simulate(th, shape=(H, W), covariates=Z, seed=4)
    mu, Q = _mu(th, 1, Z.reshape(-1, 1)), _Q(Ws, th[1:2], th[2])
    for est, want in (("pl", _pl(x.reshape(1, -1), mu, Q)),
                      ("exact", _exact(x.reshape(1, -1), mu, Q))):
        got = model.target(est, x, covariates=Z).log_prob(th)[0]
        assert abs(got - want) < 1e-8 * abs(want)


def test_coding_matches_dense_conditionals_of_its_colour_class():
    model, Ws = _lattice_case(8, False, False, 5, 4)
    x = RNG.normal(size=(5, 4))
    theta = _pd_theta(Ws)
    classes = model.graph((5, 4)).colour_classes()
    assert len(classes) == model.n_codings((5, 4)) == 4
    for c, nodes in enumerate(classes):
        t = model.target("coding", x, coding=c)
        want = [_pl(x.reshape(1, -1), np.full(20, th[0]), _Q(Ws, th[1:2], th[2]), nodes)
                for th in theta]
        np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)


def test_block_on_a_general_graph_partition():
    g = nx.connected_watts_strogatz_graph(16, 4, 0.3, seed=2)
    W = nx.to_numpy_array(g, nodelist=list(g.nodes))
    model = autonormal(g)
    x = RNG.normal(size=(2, 16))
    theta = _pd_theta([W])
    labels = RNG.integers(0, 4, size=16)
    blocks = [np.flatnonzero(labels == k) for k in np.unique(labels)]
    for spec in (labels, blocks, 3):
        t = model.target("block", x, block=spec)
        # an int grows connected blocks (the partition is the library's; the values are not)
        bl = blocks if not isinstance(spec, int) else node_blocks(model.graph(), 3)
        want = [_block(x, np.full(16, th[0]), _Q([W], th[1:2], th[2]), bl) for th in theta]
        np.testing.assert_allclose(t.log_prob(theta), want, rtol=1e-9)
    pl = model.target("pl", x).log_prob(theta)
    want_pl = [_pl(x, np.full(16, th[0]), _Q([W], th[1:2], th[2])) for th in theta]
    np.testing.assert_allclose(pl, want_pl, rtol=1e-9)
    np.testing.assert_allclose(model.target("block", x, block=1).log_prob(theta), pl,
                               rtol=1e-9)


def test_pl_is_cheap_on_large_lattices():
    """The PL's precomputed moments: a batch costs the same on 256 x 256 as on 8 x 8."""
    import time

    t = autonormal(4).target("pl", RNG.normal(size=(256, 256)), bounds={"precision": (0, 10)})
    theta = np.column_stack([RNG.normal(size=2000), RNG.uniform(-0.24, 0.24, 2000),
                             RNG.uniform(0.5, 2, 2000)])
    start = time.perf_counter()
    out = t.log_prob(theta)
    assert time.perf_counter() - start < 0.5
    assert np.all(np.isfinite(out))


# ------------------------------------------------------------------------------------------------
# positive definiteness and bounds
# ------------------------------------------------------------------------------------------------
def test_default_coupling_bounds_are_the_exact_pd_interval():
    x = RNG.normal(size=(6, 8))
    per = autonormal(4, periodic=True).target("pl", x)
    np.testing.assert_allclose(per.bounds[1], [-0.25, 0.25])
    free = autonormal(4).target("pl", x)
    edge = 1.0 / (2 * np.cos(np.pi / 7) + 2 * np.cos(np.pi / 9))
    np.testing.assert_allclose(free.bounds[1], [-edge, edge])
    eight = autonormal(8, periodic=True).target("pl", x)
    ev = np.linalg.eigvalsh(_types(_lattice_W(6, 8, OFFSETS[8], True), False)[0])
    np.testing.assert_allclose(eight.bounds[1], [1 / ev[0], 1 / ev[-1]])
    g = nx.gnp_random_graph(30, 0.2, seed=1)
    ev = np.linalg.eigvalsh(nx.to_numpy_array(g, nodelist=list(g.nodes)))
    b = autonormal(g).target("pl", RNG.normal(size=30)).bounds
    np.testing.assert_allclose(b[1], [1 / ev[0], 1 / ev[-1]])
    assert b[2, 0] == 0 and b[2, 1] > 0  # precision
    assert b[0, 0] < RNG.normal() < b[0, 1]  # the mean box holds the data's range and more


@pytest.mark.parametrize("estimator", ["pl", "coding", "block", "exact", "likelihood"])
def test_minus_inf_outside_the_positive_definite_region(estimator):
    x = RNG.normal(size=(6, 6))
    model = autonormal(4, periodic=True, bounds={"coupling": (-0.5, 0.5),
                                                "precision": (-1.0, 5.0)})
    t = model.target(estimator, x)
    theta = np.array([[0.1, 0.3, 1.0], [0.1, -0.26, 1.0], [0.1, 0.25, 1.0], [0.1, -0.25, 1.0],
                      [0.1, 0.1, 0.0], [0.1, 0.1, -0.5], [0.1, 0.2499, 1.0], [0.1, -0.2, 2.0]])
    out = t.log_prob(theta)
    assert not np.any(np.isnan(out))
    assert np.all(out[:6] == -np.inf)
    assert np.all(np.isfinite(out[6:]))
    # directional: the default box holds the PD diamond |b_h| l_h + |b_v| l_v < 1, its corners not
    d = autonormal(4, directional=True).target(estimator, RNG.normal(size=(5, 7)))
    (lo_h, hi_h), hi_v = d.bounds[1], d.bounds[2, 1]
    corner = np.array([[0.0, 0.9 * hi_h, 0.9 * hi_v, 1.0], [0.0, 0.9 * lo_h, 0.9 * hi_v, 1.0],
                       [0.0, 0.45 * hi_h, 0.45 * hi_v, 1.0], [0.0, 0.99 * hi_h, 0.0, 1.0]])
    out = d.log_prob(corner)
    assert np.all(out[:2] == -np.inf) and np.all(np.isfinite(out[2:]))


def test_pd_region_of_a_typed_graph_is_decided_by_factorisation():
    g = nx.gnp_random_graph(20, 0.3, seed=5)
    W = nx.to_numpy_array(g, nodelist=list(g.nodes))
    types = np.triu(RNG.integers(1, 3, size=(20, 20)), 1)
    types = (types + types.T) * (W > 0)
    Ws = [(types == 1).astype(float), (types == 2).astype(float)]
    model = autonormal(from_adjacency(W, edge_type=types), directional=True)
    t = model.target("pl", RNG.normal(size=20))
    theta = np.column_stack([np.zeros(200), RNG.uniform(*t.bounds[1], 200),
                             RNG.uniform(*t.bounds[2], 200), np.ones(200)])
    pd = np.array([np.linalg.eigvalsh(_Q(Ws, th[1:3], 1.0)).min() > 0 for th in theta])
    assert 10 < pd.sum() < 190
    for est in ("pl", "exact", "block"):
        out = model.target(est, RNG.normal(size=20), block=4).log_prob(theta) if est == \
            "block" else model.target(est, RNG.normal(size=20)).log_prob(theta)
        np.testing.assert_array_equal(np.isfinite(out), pd)


# ------------------------------------------------------------------------------------------------
# simulation
# ------------------------------------------------------------------------------------------------
def _check_moments(draws, mu, Q, z=5.0):
    n = draws.shape[0]
    cov = np.linalg.inv(Q)
    se_mean = np.sqrt(np.diag(cov) / n)
    assert np.max(np.abs(draws.mean(axis=0) - mu) / se_mean) < z
    d = np.diag(cov)
    se_cov = np.sqrt((np.outer(d, d) + cov ** 2) / n)
    emp = np.cov(draws, rowvar=False)
    assert np.max(np.abs(emp - cov) / se_cov) < z


@pytest.mark.parametrize(("nb", "periodic", "directional", "H", "W", "method"), [
    (8, False, False, 4, 5, "dense"),
    (8, False, True, 4, 5, "sparse"),
    (4, True, True, 4, 5, "fft"),
    (8, True, False, 3, 4, "auto"),
])
def test_simulate_matches_mean_and_covariance(nb, periodic, directional, H, W, method):
    model, Ws = _lattice_case(nb, periodic, directional, H, W, n_cov=1)
    Z = RNG.normal(size=(H, W))
    th = _pd_theta(Ws, n_cov=1, k=1, scale=0.95)[0]
    T = len(Ws)
    draws = model.simulate(th, shape=(H, W), n=30000, seed=7, covariates=Z, method=method)
    assert draws.shape == (30000, H, W)
    _check_moments(draws.reshape(30000, -1), _mu(th, T, Z.reshape(-1, 1)),
                   _Q(Ws, th[1:1 + T], th[1 + T]))


def test_simulate_on_a_graph_and_from_the_likelihood_target():
    g = nx.connected_watts_strogatz_graph(12, 4, 0.3, seed=4)
    W = nx.to_numpy_array(g, nodelist=list(g.nodes))
    model = autonormal(g)
    th = _pd_theta([W], k=1, scale=0.95)[0]
    for method in ("dense", "sparse"):
        draws = model.simulate(th, n=30000, seed=3, method=method)
        assert draws.shape == (30000, 12)
        _check_moments(draws, np.full(12, th[0]), _Q([W], th[1:2], th[2]))
    lik = model.target("likelihood", RNG.normal(size=(2, 12)), sampler="sparse")
    draws = lik.simulate(th, n=30000, seed=5)
    _check_moments(draws, np.full(12, th[0]), _Q([W], th[1:2], th[2]))
    assert lik.simulate(th, seed=1).shape == (2, 12)
    # unnormalised: -1/2 (x - mu)' Q (x - mu), the exact likelihood without log det
    x = RNG.normal(size=(3, 12))
    Q = _Q([W], th[1:2], th[2])
    want = -0.5 * sum((xm - th[0]) @ Q @ (xm - th[0]) for xm in x)
    np.testing.assert_allclose(lik.unnormalised(th, x), [want], rtol=1e-9)
    exact = model.target("exact", x)
    np.testing.assert_allclose(model.target("likelihood", x).log_prob(th),
                               exact.log_prob(th) + 3 * exact.log_partition(th), rtol=1e-9)


def test_simulate_is_reproducible_by_seed():
    for model, shape in ((autonormal(4, periodic=True), (8, 8)), (autonormal(8), (6, 7)),
                         (autonormal(4), (40, 40))):  # fft, dense, sparse
        a = model.simulate([1.0, 0.1, 2.0], shape=shape, n=3, seed=11)
        b = model.simulate([1.0, 0.1, 2.0], shape=shape, n=3, seed=11)
        c = model.simulate([1.0, 0.1, 2.0], shape=shape, n=3, seed=12)
        assert a.shape == (3, *shape)
        np.testing.assert_array_equal(a, b)
        assert not np.allclose(a, c)


def test_simulate_rejects_theta_outside_the_pd_region():
    for model, shape in ((autonormal(4, periodic=True), (6, 6)), (autonormal(4), (4, 4)),
                         (autonormal(8, directional=True), (40, 40))):
        d = len(model.param_names())
        bad = [0.0, *([0.35] * (d - 2)), 1.0]  # 0.35 * 2 (2 cos(pi / 5)) > 1 on 4 x 4
        with pytest.raises(ValueError, match=r"theta \[0\.0, 0\.35.*positive-definite"):
            model.simulate(bad, shape=shape, seed=0)
        with pytest.raises(ValueError, match="positive-definite"):
            model.simulate([0.0, *([0.05] * (d - 2)), -1.0], shape=shape)


# ------------------------------------------------------------------------------------------------
# estimation: the estimators recover theta from a 64 x 64 draw
# ------------------------------------------------------------------------------------------------
def _maximise(target, start):
    """L-BFGS-B on ``-log_prob`` per node; outside the PD region a large finite penalty, so
    that the line search backs off instead of meeting ``inf``."""
    n = target.x.size

    def f(th):
        v = target.log_prob(th)[0]
        return -v / n if np.isfinite(v) else 1e6

    b = target.bounds.copy()
    b[:, 0] += 1e-6 * (b[:, 1] - b[:, 0])
    b[:, 1] -= 1e-6 * (b[:, 1] - b[:, 0])
    res = optimize.minimize(f, start, method="L-BFGS-B", bounds=b)
    assert res.success, res.message
    return res.x


@pytest.mark.parametrize("estimator", ["pl", "exact", "block"])
def test_estimators_recover_theta_from_a_64x64_draw(estimator):
    truth = np.array([1.0, 0.2, 2.0])
    model = autonormal(4)
    x = model.simulate(truth, shape=(64, 64), seed=2026)
    t = model.target(estimator, x, block=(4, 4)) if estimator == "block" else \
        model.target(estimator, x)
    est = _maximise(t, [0.0, 0.0, 1.0])
    assert abs(est[0] - truth[0]) < 0.15
    assert abs(est[1] - truth[1]) < 0.02
    assert abs(est[2] / truth[2] - 1) < 0.1


def test_directional_mle_on_a_torus():
    truth = np.array([-0.5, 0.3, 0.12, 0.5, 1.5])
    model = autonormal(4, periodic=True, directional=True, covariates=1)
    z = np.linspace(-1, 1, 64)[None, :] * np.ones((64, 1))
    x = model.simulate(truth, shape=(64, 64), seed=9, covariates=z)
    t = model.target("exact", x, covariates=z)
    est = _maximise(t, [0.0, 0.0, 0.0, 1.0, 0.0])
    assert np.all(np.abs(est - truth) < [0.3, 0.03, 0.03, 0.05, 0.5]), est


# ------------------------------------------------------------------------------------------------
# interface and errors
# ------------------------------------------------------------------------------------------------
def test_interface_and_description():
    m = autonormal(8, directional=True, covariates=["a", "b"])
    assert isinstance(m, GaussianMRF)
    assert m.param_names() == ("mean", "coupling_horizontal", "coupling_vertical",
                               "coupling_diagonal", "coupling_antidiagonal", "precision", "a",
                               "b")
    assert autonormal().param_names() == ("mean", "coupling", "precision")
    assert autonormal(covariates=1).param_names() == ("mean", "coupling", "precision", "z")
    assert m.n_codings((5, 5)) == 4 and autonormal().n_codings((5, 5)) == 2
    json.dumps(m.describe())
    x = RNG.normal(size=(5, 6))
    Z = RNG.normal(size=(5, 6, 2))
    for est in m.estimators:  # 30 values carry no interior MPLE for 8 parameters to adjust
        if est != "pl_adjusted":
            json.dumps(m.target(est, x, covariates=Z).describe())
    # a Graph or an adjacency matrix as the graph; a lattice rule with periodic added
    g = nx.path_graph(5)
    assert autonormal(from_networkx(g)).param_names() == ("mean", "coupling", "precision")
    assert autonormal(nx.to_numpy_array(g)).graph().n_edges == 4
    assert autonormal(lattice(4), periodic=True).graph((4, 4)).n_edges == 32


def test_check_model_conformance():
    from mrfpe.testing import check_model

    x = autonormal(4).simulate([0.5, 0.15, 1.0], shape=(16, 16), n=2, seed=1)
    out = check_model(autonormal(4), x, theta=[0.5, 0.15, 1.0])
    assert set(out.values()) <= {"passed"}
    g = nx.cycle_graph(7)
    y = autonormal(g).simulate([0.5, 0.15, 1.0], n=2, seed=1)
    out = check_model(autonormal(g, covariates=0), y, theta=[0.5, 0.15, 1.0],
                      estimators=("pl", "coding", "block", "exact", "likelihood"))
    assert out["codings"] == "passed"


@pytest.mark.parametrize(("call", "match"), [
    (lambda m: m.target("pl", np.full((4, 4), np.nan)), "data must be finite"),
    (lambda m: m.target("pl", np.zeros(16)), r"data must be an \(H, W\)"),
    (lambda m: m.target("pl", np.zeros((2, 2, 4, 4))), r"data must be an \(H, W\)"),
    (lambda m: m.target("pl", np.array([["a", "b"]])), "real numbers"),
    (lambda m: m.target("pl", np.zeros((4, 4)) + 1j), "real numbers"),
    (lambda m: m.target("pl", np.zeros((4, 4)), covariates=np.zeros((4, 4))),
     "declares none"),
    (lambda m: m.target("block", np.zeros((4, 4)), block=(0, 2)), "positive integers"),
    (lambda m: m.target("block", np.zeros((25, 25)), block=(21, 21)),
     f"m <= {MAX_BLOCK_NODES}"),
    (lambda m: m.target("block", np.zeros((4, 4)), block=(0, 2)), "positive"),
    (lambda m: m.target("coding", np.zeros((4, 4)), coding=2), r"coding must be in \[0, 1\]"),
    (lambda m: m.target("pl", np.zeros((4, 4)), bounds=[[0, 1], [0, 1]]), r"bounds must be \(3"),
    (lambda m: m.target("pl", np.zeros((4, 4)), bounds=np.zeros((3, 2))), "lower < upper"),
    (lambda m: m.target("pl", np.zeros((4, 4)), bounds={"couplng": (0, 1)}), "unknown"),
    (lambda m: m.target("pl", np.zeros((4, 4)), bounds={"coupling": (1, 0)}), "low < high"),
    (lambda m: m.target("block", np.zeros((4, 4)), blok=2), "did you mean 'block'"),
    (lambda m: m.target("mple", np.zeros((4, 4))), "estimator must be one of"),
    (lambda m: m.target("exact", np.zeros((4, 4)), method="dense"), "method must be one of"),
    (lambda m: m.simulate([0, 0.1, 1.0]), "shape must be given"),
    (lambda m: m.simulate([0, 0.1], shape=(3, 3)), "theta must be 3 finite numbers"),
    (lambda m: m.simulate([0, 0.1, 1.0], shape=(3, 3), n=0), "n must be"),
    (lambda m: m.simulate([0, 0.1, 1.0], shape=(3, 3), seed=-1), "seed must be"),
    (lambda m: m.simulate([0, 0.1, 1.0], shape=(3, 3), method="fft"), "needs a periodic"),
])
def test_bad_input_on_a_lattice(call, match):
    with pytest.raises(ValueError, match=match) as info:
        call(autonormal(4))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("call", "match"), [
    (lambda m: m.target("pl", np.zeros(5)), r"data must have shape \(6,\)"),
    (lambda m: m.target("pl", np.zeros((6, 6))), "covariates must be given"),
    (lambda m: m.target("pl", np.zeros(6), covariates={"a": np.zeros(6)}), "exactly 'a', 'b'"),
    (lambda m: m.target("pl", np.zeros(6), covariates={"a": np.zeros(5), "b": np.zeros(6)}),
     r"covariate 'a' must have shape \(6,\)"),
    (lambda m: m.target("pl", np.zeros(6), covariates=np.zeros((6, 3))),
     r"covariates must have shape \(6, 2\)"),
    (lambda m: m.target("pl", np.zeros(6), covariates={"a": np.zeros(6), "b": [np.inf] * 6}),
     "must be finite"),
    (lambda m: m.target("block", np.zeros(6), covariates=np.zeros((6, 2)), block=(2, 2)),
     "needs a lattice"),
    (lambda m: m.target("block", np.zeros(6), covariates=np.zeros((6, 2)),
                        block=[np.arange(3), np.arange(2, 6)]), "disjoint"),
    (lambda m: m.target("block", np.zeros(6), covariates=np.zeros((6, 2)),
                        block=np.zeros(5, dtype=int)), "one entry per node"),
    (lambda m: m.target("exact", np.zeros(6), covariates=np.zeros((6, 2)), method="eigen"),
     None),  # one coupling on 6 nodes: the spectrum is known, no error
])
def test_bad_input_on_a_graph(call, match):
    m = autonormal(nx.cycle_graph(6), covariates=["a", "b"])
    if match is None:
        call(m)
        return
    with pytest.raises(ValueError, match=match) as info:
        call(m)
    assert "\n" not in str(info.value)


def test_bad_model_declarations():
    g = nx.cycle_graph(5)
    with pytest.raises(ValueError, match="periodic applies to lattices"):
        autonormal(g, periodic=True)
    with pytest.raises(ValueError, match="must not be named 'precision'"):
        autonormal(covariates=["precision"])
    with pytest.raises(ValueError, match="distinct non-empty names"):
        autonormal(covariates=["a", "a"])
    with pytest.raises(ValueError, match="covariates must be"):
        autonormal(covariates=1.5)
    with pytest.raises(ValueError, match="directional must be True or False"):
        autonormal(directional="yes")
    with pytest.raises(ValueError, match=r"bounds must be \(3, 2\)"):
        autonormal(bounds=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="graph must be"):
        autonormal("grid")
    with pytest.raises(ValueError, match="method 'eigen' needs"):
        autonormal(8, directional=True).target("exact", np.zeros((4, 4)), method="eigen")
