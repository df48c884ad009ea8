"""mrfpe.models.multispin against independent routes.

Exact expectations come from brute-force enumeration of every configuration of a small
lattice (edges from :func:`mrfpe.models.graph.lattice`, log-weights straight from the
parameters). The replicas' chains are independent, so a Monte-Carlo mean's standard
error is the spread of the per-replica chain means over the replicas (autocorrelation
included), never below the i.i.d. error from the exact variance; each check has a
negative control that the same tolerance rejects.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from mrfpe import models
from mrfpe.models.graph import lattice
from mrfpe.models.multispin import (
    applies,
    lattice_parameters,
    multispin_gibbs,
    pack,
    unpack,
    why_not,
)
from mrfpe.models.multispin_kernels import _count
from mrfpe.models.simulate import simulate
from mrfpe.threads import limit_threads


@settings(max_examples=40, deadline=None)
@given(R=st.integers(1, 200), H=st.integers(1, 4), W=st.integers(1, 5), seed=st.integers(0, 99))
def test_pack_unpack_round_trip(R, H, W, seed):
    x = np.random.default_rng(seed).integers(0, 2, (R, H, W)).astype(np.int8)
    words = pack(x)
    assert words.shape == (-(-R // 64), H, W) and words.dtype == np.uint64
    assert np.array_equal(unpack(words, R), x)
    assert int(words[0, 0, 0] & np.uint64(1)) == x[0, 0, 0]  # bit r is replica r


@settings(max_examples=60, deadline=None)
@given(words=st.lists(st.integers(0, 2**64 - 1), min_size=9, max_size=9),
       eight=st.booleans())
def test_bit_sliced_counts_equal_a_direct_count(words, eight):
    xp = np.array(words, dtype=np.uint64).reshape(1, 3, 3)
    offsets = np.array(((0, 1), (1, 0), (1, 1), (1, -1))[:4 if eight else 2], dtype=np.int64)
    T = len(offsets)
    s0, s1, cb = (np.zeros(T, np.uint64), np.zeros(T, np.uint64), np.zeros(4, np.uint64))
    _count(xp, 0, 1, 1, offsets, s0, s1, cb)
    bits = unpack(xp, 64).astype(int)  # (64, 3, 3)
    total = np.zeros(64, int)
    for t, (dr, dc) in enumerate(offsets):
        m = bits[:, 1 + dr, 1 + dc] + bits[:, 1 - dr, 1 - dc]
        total += m
        assert np.array_equal(unpack(s0[t:t + 1], 64) + 2 * unpack(s1[t:t + 1], 64), m)
    planes = unpack(cb[None, :], 64).astype(int)  # (64, 4): replica, plane
    assert np.array_equal(planes @ (1 << np.arange(4)), total)


def _exact(shape, nb, periodic, J, f, d):
    """Exact means of every spin and of S(x) = (sum x, per type sum [x_i == x_j]), with their
    variances, by enumeration; J, d per edge type (length 1 or the offsets'), f scalar or
    (H, W)."""
    g = lattice(nb, periodic=periodic, directional=True).build(shape)
    X = np.array(list(itertools.product((0, 1), repeat=g.n_nodes)))
    e, t = g.edges, g.edge_type
    J, d = np.asarray(J, float), np.asarray(d, float)
    Je, de = (J[t] if J.size > 1 else np.full(t.size, J[0])), (d[t] if d.size > 1 else
                                                               np.full(t.size, d[0]))
    eq = X[:, e[:, 0]] == X[:, e[:, 1]]
    lw = X @ np.broadcast_to(f, shape).reshape(-1) + eq @ Je + (X[:, e[:, 0]] + X[:, e[:, 1]]) @ de
    p = np.exp(lw - lw.max())
    p /= p.sum()
    S = _stats(X, g)
    mean = p @ S
    return mean, p @ (S - mean) ** 2, g


def _stats(X, g):
    X = X.reshape(X.shape[0], -1)
    eq = X[:, g.edges[:, 0]] == X[:, g.edges[:, 1]]
    by_type = np.stack([eq[:, g.edge_type == k].sum(1) for k in range(g.n_edge_types)], 1)
    return np.column_stack([X, X.sum(1), by_type]).astype(float)


def _z(draws, g, mean, var):
    """|MC mean - exact| / se per statistic; draws (R, n, H, W) of independent replicas."""
    R, n = draws.shape[:2]
    S = _stats(draws.reshape(R * n, -1), g).reshape(R, n, -1)
    chain = S.mean(axis=1)
    se = np.maximum(chain.std(axis=0, ddof=1) / np.sqrt(R), np.sqrt(var / (R * n)))
    return np.abs(chain.mean(axis=0) - mean) / np.maximum(se, 1e-12)


CASES = [  # (shape, neighbourhood, periodic, J per type, f, d)
    ((3, 4), 4, False, [0.5], 0.2, [0.0]),
    ((3, 4), 4, False, [0.4, -0.3], -0.3, [0.1, -0.2]),
    ((3, 4), 8, False, [0.5], -0.1, [0.05]),
    ((3, 4), 8, False, [0.4, -0.3, 0.2, 0.6], -0.3, [0.1, 0.0, -0.1, 0.2]),
    ((4, 4), 4, True, [0.6], 0.1, [0.0]),
    ((4, 4), 8, True, [0.2, 0.3, -0.4, 0.1], 0.2, [-0.1, 0.0, 0.1, 0.0]),
]


@pytest.mark.parametrize("case", CASES, ids=[f"{c[0]}-{c[1]}-{'per' if c[2] else 'free'}-"
                                             f"T{len(c[3])}" for c in CASES])
def test_exact_expectations(case):
    shape, nb, periodic, J, f, d = case
    mean, var, g = _exact(shape, nb, periodic, J, f, d)
    R = 64
    draws = multispin_gibbs(np.tile(J, (R, 1)), np.full(R, f), shape, 20, seed=3,
                            neighbourhood=nb, periodic=periodic, edge_field=np.tile(d, (R, 1)),
                            thin=1, n=1500)
    assert np.max(_z(draws, g, mean, var)) < 5
    shifted, _, _ = _exact(shape, nb, periodic, np.add(J, 0.3), f, d)  # negative control
    assert np.max(_z(draws, g, shifted, var)) > 5


def test_per_replica_parameters_and_per_node_field():
    """Replica k at its own (J, f): four designs of 16 replicas; a per-node field too."""
    shape, R = (3, 4), 64
    Js, fs = np.array([-0.5, 0.0, 0.4, 0.9]), np.array([0.3, -0.6, 0.0, 0.2])
    group = np.arange(R) % 4
    node_f = np.linspace(-1, 1, 12).reshape(shape)
    for per_node in (False, True):
        field = fs[group] if not per_node else fs[group][:, None, None] + node_f
        draws = multispin_gibbs(Js[group][:, None], field, shape, 20, seed=5, thin=1, n=1500)
        for k in range(4):
            f = fs[k] + (node_f if per_node else 0.0)
            mean, var, g = _exact(shape, 4, False, [Js[k]], f, [0.0])
            assert np.max(_z(draws[group == k], g, mean, var)) < 5, (per_node, k)
            wrong, _, _ = _exact(shape, 4, False, [Js[k]], f + 0.5, [0.0])
            assert np.max(_z(draws[group == k], g, wrong, var)) > 5


def test_same_distribution_as_the_scalar_kernel():
    """16 x 16 autologistic from a compiled design: the sufficient statistics of the scalar
    Gibbs kernel's draws and of the replicas' (two-sample KS and a mean test)."""
    m = models.autologistic()
    design, _, _ = m.compile((16, 16))
    psi = design.psi(np.array([[0.5, -0.4]]))
    assert applies(design)
    params = lattice_parameters(design, np.repeat(psi, 64, axis=0))
    ms = multispin_gibbs(**params.arguments(), n_sweeps=50, seed=1, thin=10, n=8)
    S_ms = design.statistics(ms.reshape(-1, 256).astype(np.int64))
    scalar = [simulate(design, psi[0], 128, seed=s, method="gibbs", n_sweeps=50, thin=10)
              for s in range(4)]
    S_sc = design.statistics(np.concatenate(scalar))
    for k in range(S_ms.shape[1]):
        assert stats.ks_2samp(S_ms[:, k], S_sc[:, k]).pvalue > 1e-3
        chains = [S_ms.reshape(64, 8, -1)[:, :, k].mean(1),
                  np.array([design.statistics(c)[:, k].mean() for c in scalar])]
        se = np.hypot(*(c.std(ddof=1) / np.sqrt(c.size) for c in chains))
        assert abs(chains[0].mean() - chains[1].mean()) < 5 * se
    other = lattice_parameters(design, design.psi(np.array([[0.8, -0.4]])).repeat(64, 0))
    ms2 = multispin_gibbs(**other.arguments(), n_sweeps=50, seed=1, thin=10, n=8)
    S2 = design.statistics(ms2.reshape(-1, 256).astype(np.int64))  # a control: it differs
    assert min(stats.ks_2samp(S2[:, k], S_sc[:, k]).pvalue for k in range(S2.shape[1])) < 1e-3


@pytest.mark.parametrize("kind", ["shared", "directional8", "per_node"])
def test_reproducible_and_independent_of_threads(kind):
    shape, R = (128, 256), 70  # large enough that the library takes two threads
    J = np.full((R, 4 if kind == "directional8" else 1), 0.3)
    J[:, 0] = np.linspace(0, 1, R)
    field = np.zeros(R) if kind != "per_node" else np.zeros((R, *shape))
    nb = 8 if kind == "directional8" else 4
    if kind == "per_node":
        shape, field = (32, 32), np.zeros((R, 32, 32))

    def run(threads, seed=7):
        with limit_threads(threads):
            return multispin_gibbs(J, field, shape, 3, seed=seed, neighbourhood=nb, n=2, thin=1)

    a, b = run(1), run(2)
    assert np.array_equal(a, b) and np.array_equal(a, run(2))
    assert not np.array_equal(a, run(2, seed=8))


def test_replicas_are_independent():
    """Correlation, over draws, between replicas' magnetisations: ~0 (no shared uniforms)."""
    R, n = 64, 400
    x = multispin_gibbs(np.full((R, 1), 0.3), np.zeros(R), (8, 8), 10, seed=2, thin=3, n=n)
    mag = x.reshape(R, n, -1).mean(axis=2)
    C = np.corrcoef(mag)
    off = C[~np.eye(R, dtype=bool)]
    # each correlation has sd ~ 1 / sqrt(n) (nearly independent draws at thin 3)
    assert abs(off.mean()) < 5 / np.sqrt(n * R)
    assert np.abs(off).max() < 5.5 / np.sqrt(n)


@pytest.mark.parametrize("kwargs, match", [
    ({"coupling": np.ones((4, 3))}, "coupling must have shape"),
    ({"coupling": np.ones(4)}, "coupling must have shape"),
    ({"coupling": np.full((4, 1), np.nan)}, "coupling must hold finite"),
    ({"field": np.ones(5)}, "field must have shape"),
    ({"field": np.array([0, np.nan, 0, 0])}, "field must hold finite"),
    ({"edge_field": np.ones((4, 2))}, "edge_field must have shape"),
    ({"edge_field": np.full((4, 1), np.inf)}, "edge_field must hold finite"),
    ({"shape": (3,)}, "shape must be"),
    ({"shape": (5, 6), "periodic": True}, "shape must be even"),
    ({"neighbourhood": 6}, "neighbourhood must be 4 or 8"),
    ({"init": np.full((4, 6, 6), 2)}, "init must hold spins"),
    ({"init": np.zeros((3, 6, 6))}, "init must be None or spins of shape"),
    ({"n_sweeps": -1}, "n_sweeps must be"),
    ({"thin": 0}, "thin must be"),
    ({"seed": -3}, "seed must be"),
])
def test_bad_input_gives_one_line_errors(kwargs, match):
    args = {"coupling": np.ones((4, 1)), "field": np.zeros(4), "shape": (6, 6),
            "n_sweeps": 1, **kwargs}
    with pytest.raises(ValueError, match=match) as err:
        multispin_gibbs(**args)
    assert "\n" not in str(err.value)


def test_applies_to_binary_lattice_designs_only():
    ising = models.ising().compile((6, 6))[0]
    assert applies(ising) and lattice_parameters(ising, ising.psi(np.ones((1, 2)))).shape == (6, 6)
    d8 = models.MRF(lattice(8, directional=True, periodic=True), 2,
                    [models.Coupling(by_type=True), models.Field()]).compile((6, 8))[0]
    p = lattice_parameters(d8, d8.psi(np.ones((3, d8.n_features))))
    assert p.coupling.shape == (3, 4) and p.neighbourhood == 8 and p.periodic
    assert "3 states" in why_not(models.potts(3).compile((6, 6))[0])
    odd = models.MRF(lattice(4, periodic=True), 2, [models.Coupling()]).compile((5, 6))[0]
    assert "periodic" in why_not(odd)
    assert not applies("not a design")
    with pytest.raises(ValueError, match="design cannot be run by multispin_gibbs"):
        lattice_parameters(odd, np.ones(1))
