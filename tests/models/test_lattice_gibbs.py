"""mrfpe.models.lattice_gibbs: the lattice kernel's draws are the general kernel's, bit for bit.

The general (CSR) kernel is forced by making ``lattice_stencil`` answer None in the
dispatching module; every comparison is exact (``assert_array_equal``).
"""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.models import lattice_gibbs as lg
from mrfpe.models import simulate as sm
from mrfpe.models import simulate_batch as sb
from mrfpe.models.discrete import MRF, Potential
from mrfpe.models.graph import Graph, lattice
from mrfpe.models.terms import Coupling, Field, NodeCovariate
from mrfpe.threads import limit_threads


def _general(module, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` with the lattice kernel switched off in ``module``."""
    saved = module.lattice_stencil
    module.lattice_stencil = lambda design: None
    try:
        return fn(*args, **kwargs)
    finally:
        module.lattice_stencil = saved


def _same_single(design, psi, seed, **kw):
    kw = {"method": "gibbs", "n_sweeps": 4, "thin": 2, **kw}
    fast = sm.simulate(design, psi, 3, seed=seed, **kw)
    slow = _general(sm, sm.simulate, design, psi, 3, seed=seed, **kw)
    np.testing.assert_array_equal(fast, slow)
    return fast


CASES = [(q, nb, periodic, shape) for q in (2, 3, 6) for nb in (4, 8)
         for periodic, shape in ((False, (7, 9)), (True, (6, 8)))]


@pytest.mark.parametrize("q, nb, periodic, shape", CASES)
def test_single_chain_draws_are_the_general_kernels(q, nb, periodic, shape):
    """Directional couplings and fields, several seeds; the lattice kernel does run."""
    m = MRF(lattice(nb, periodic=periodic, directional=True), q,
            [Coupling(by_type=True), Field()])
    design = m.compile(shape)[0]
    assert lg.lattice_stencil(design) is not None
    rng = np.random.default_rng(100 * q + nb)
    for seed in range(3):
        psi = design.psi(rng.normal(0.0, 1.2, (1, design.n_features)))[0]
        _same_single(design, psi, seed)


@pytest.mark.parametrize("q, nb", [(2, 4), (3, 8), (6, 4)])
def test_strong_couplings_and_per_node_tables(q, nb):
    """Weights that underflow (couplings of +-300: the log-weight fallback) and node tables
    of their own per node (never tabulated)."""
    design = MRF(lattice(nb), q, [Coupling(), Field()]).compile((6, 7))[0]
    for J in (300.0, -300.0):
        _same_single(design, design.psi(np.array([[J, *np.linspace(-1, 1, q - 1)]]))[0], 1)
    z = np.random.default_rng(0).normal(size=(6, 7))
    m = MRF(lattice(nb, periodic=True), q, [Coupling(), Field(), NodeCovariate("z")])
    design, names, _ = m.compile((6, 8), {"z": np.resize(z, (6, 8))})
    assert design.node.shape[0] == 48
    psi = design.psi(np.random.default_rng(1).normal(0.0, 1.0, (1, len(names))))[0]
    for seed in range(2):
        _same_single(design, psi, seed)


def test_forbidden_pairs():
    """-inf pair entries (proper 3-colourings, from an improper random start): the kernel
    falls back to the general update exactly where the general kernel does."""
    tab = np.array([[-np.inf, 0.4, 0.0], [0.4, -np.inf, 0.0], [0.0, 0.0, -np.inf]])
    pot = Potential(params=[("a", (0.0, 1.0))],
                    pair=lambda th: np.broadcast_to(tab, (th.shape[0], 3, 3)),
                    node=lambda th: np.broadcast_to([0.0, 0.2, -0.3], (th.shape[0], 3)))
    design = MRF(lattice(4), 3, potential=pot).compile((8, 9))[0]
    psi = design.psi(np.array([[0.5]]))[0]
    assert np.isneginf(psi).any()
    for seed in range(4):
        x = _same_single(design, psi, seed, n_sweeps=30)
        e = design.graph.edges
        assert np.all(x[:, e[:, 0]] != x[:, e[:, 1]])


def test_small_and_thin_lattices():
    """Lattices that are all boundary (one or two rows or columns, narrow tori)."""
    for nb in (4, 8):
        for periodic in (False, True):
            for shape in ((1, 6), (6, 1), (2, 5), (4, 2), (3, 3)):
                design = MRF(lattice(nb, periodic=periodic), 3, [Coupling(), Field()]).compile(
                    shape)[0]
                _same_single(design, design.psi(np.array([[0.7, 0.2, -0.4]]))[0], 5)


def test_batched_draws_are_the_general_kernels(monkeypatch):
    """Both layouts (one chain per thread; rows shared among threads) and the single-chain
    route agree."""
    design = MRF(lattice(8, directional=True), 3, [Coupling(by_type=True), Field()]).compile(
        (9, 10))[0]
    psi = design.psi(np.random.default_rng(7).normal(0.0, 0.8, (3, design.n_features)))
    kw = {"method": "gibbs", "n_sweeps": 5, "thin": 2, "kernel": "scalar"}
    monkeypatch.setattr(sb, "spare_cores", lambda: 2)  # the layout as chosen on an idle machine
    monkeypatch.setattr(sb, "thread_budget", lambda n: limit_threads(2))
    for threads in (1, 2):
        with limit_threads(threads):
            fast = sb.simulate_batch(design, psi, 2, seed=4, **kw)  # chains >= threads
            slow = _general(sb, sb.simulate_batch, design, psi, 2, seed=4, **kw)
            np.testing.assert_array_equal(fast, slow)
            one = sb.simulate_batch(design, psi[1:2], 2, seed=int(sb.chain_seeds(4, 3)[1]),
                                    **kw)  # rows shared on 2 threads
            np.testing.assert_array_equal(one, _general(
                sb, sb.simulate_batch, design, psi[1:2], 2, seed=int(sb.chain_seeds(4, 3)[1]),
                **kw))
    seeds = sb.chain_seeds(4, 3)
    for b in range(3):
        one = sm.simulate(design, psi[b], 2, seed=int(seeds[b]), method="gibbs", n_sweeps=5,
                          thin=2)
        np.testing.assert_array_equal(one, fast[b])


@pytest.mark.parametrize("q", [2, 6, 16])  # tabulated (2, 6) and not (16 ** 4 configurations)
def test_draws_do_not_depend_on_threads(monkeypatch, q):
    design = MRF(lattice(4, periodic=True), q, [Coupling(), Field()]).compile((128, 96))[0]
    psi = design.psi(np.array([[0.9, *np.linspace(-0.3, 0.3, q - 1)]]))[0]
    kw = {"method": "gibbs", "n_sweeps": 3, "thin": 2}
    draws = []
    for threads in (1, 2):
        monkeypatch.setattr(sm, "thread_budget", lambda n, t=threads: limit_threads(t))
        draws.append(sm.simulate(design, psi, 2, seed=3, **kw))
    np.testing.assert_array_equal(*draws)
    np.testing.assert_array_equal(draws[0], _general(sm, sm.simulate, design, psi, 2, seed=3,
                                                     **kw))


def test_which_designs_the_kernel_runs():
    """Lattices coloured by their periodic colouring only: an odd torus (coloured greedily),
    a lattice graph rebuilt without its shape, per-edge pair tables fall back."""
    m = MRF(lattice(4, periodic=True), 2, [Coupling(), Field()])
    assert lg.lattice_stencil(m.compile((5, 6))[0]) is None  # odd: greedy colouring
    st = lg.lattice_stencil(m.compile((6, 6))[0])
    assert (st.H, st.W, st.K, st.dpos, st.dtyp) == (6, 6, 2, (-6, -1, 1, 6), (0, 0, 0, 0))
    st = lg.lattice_stencil(MRF(lattice(8, directional=True), 2, [Coupling(by_type=True)])
                            .compile((5, 7))[0])
    assert st.K == 4 and st.dpos == (-8, -7, -6, -1, 1, 6, 7, 8)
    assert st.dtyp == (2, 1, 3, 0, 0, 3, 1, 2)  # diagonal, vertical, antidiagonal, horizontal
    g = lattice(4).build((4, 5))
    plain = Graph(g.n_nodes, g.edges, g.edge_type, g.edge_type_names)  # no shape
    assert lg.lattice_stencil(MRF(plain, 2, [Coupling()]).compile()[0]) is None
