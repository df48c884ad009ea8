"""Exact log Z (mrfpe.models.exact): variable elimination against independent routes.

The references are computed here, independently of the elimination code: brute
force over all ``q^n`` configurations (straight from the log-potential tables,
not through ``Design.statistics``), the closed forms of the 1-D Ising model, and
a row-by-row transfer matrix written from the model's definition.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.special import logsumexp

from mrfpe.budget import MemoryBudgetError, chunk_rows, set_memory_budget
from mrfpe.models.discrete import MRF, Potential
from mrfpe.models.exact import MAX_ENUMERATION, MAX_FACTOR_ENTRIES, LogPartition
from mrfpe.models.graph import from_adjacency, lattice
from mrfpe.models.terms import Coupling, EdgeCovariate, Field, NodeCovariate

ISING = dict(n_states=2, terms=[Coupling("product"), Field("value")], state_values=(-1, 1))


def brute_log_z(design, psi: np.ndarray) -> np.ndarray:
    """log Z (N,) by listing every configuration; node and pair tables indexed directly."""
    g, q = design.graph, design.q
    node, pair = design.tables(psi)  # (N, n|1, q), (N, T|E, q, q)
    x = np.array(list(itertools.product(range(q), repeat=g.n_nodes)))  # (M, n)
    nrow = np.arange(g.n_nodes) if node.shape[1] == g.n_nodes else np.zeros(g.n_nodes, int)
    prow = np.arange(g.n_edges) if design.pair_per_edge else g.edge_type
    i, j = g.edges[:, 0], g.edges[:, 1]
    energy = node[:, nrow, x].sum(axis=-1) + pair[:, prow, x[:, i], x[:, j]].sum(axis=-1)
    return logsumexp(energy, axis=1)


def transfer_log_z(shape: tuple[int, int], pair: np.ndarray, field: np.ndarray) -> float:
    """log Z of an isotropic 4-neighbour free-boundary lattice, line by line (q^L states).

    ``pair`` (q, q) and ``field`` (q,) are the log-potentials of one edge and one site.
    """
    L, M = min(shape), max(shape)  # the transposed lattice has the same Z
    q = field.shape[0]
    s = np.array(list(itertools.product(range(q), repeat=L)))  # (q^L, L)
    inside = field[s].sum(axis=1) + pair[s[:, :-1], s[:, 1:]].sum(axis=1)
    across = pair[s[:, None, :], s[None, :, :]].sum(axis=2)  # (q^L, q^L)
    v = inside
    for _ in range(M - 1):
        v = logsumexp(v[:, None] + across, axis=0) + inside
    return float(logsumexp(v))


def _random_graph(n: int, p: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = np.triu(rng.random((n, n)) < p, k=1)
    return (a | a.T).astype(int)


def _cycle(n: int) -> np.ndarray:
    a = np.zeros((n, n), int)
    for k in range(n):
        a[k, (k + 1) % n] = a[(k + 1) % n, k] = 1
    return a


def _directional_potential() -> Potential:
    """A general potential: one table per direction of the 8-neighbourhood, q = 3."""
    def pair(th):
        base = np.array([[1.0, 0.2, -0.5], [0.2, 0.7, 0.1], [-0.5, 0.1, 0.9]])
        scale = th[:, :1, None, None] * np.array([1.0, 0.6, -0.4, 0.3])[None, :, None, None]
        return scale * base + th[:, 1, None, None, None] * np.eye(3)

    return Potential(params=[("a", (-2, 2)), ("b", (-2, 2))], pair=pair,
                     node=lambda th: np.stack([0 * th[:, 0], th[:, 1], -th[:, 0]], axis=1))


def _case(name: str):
    """(model, shape, covariates) of each test case."""
    rng = np.random.default_rng(7)
    edges_typed = _random_graph(9, 0.4, 3)
    types = np.triu(rng.integers(1, 3, size=(9, 9)), 1)
    types = (types + types.T) * edges_typed
    return {
        "ising_3x4": (MRF(lattice(4), **ISING), (3, 4), None),
        "potts3_8nbr_directional_3x3": (
            MRF(lattice(8, directional=True), 3, [Coupling(by_type=True), Field()]), (3, 3), None),
        "periodic_3x4": (MRF(lattice(4, periodic=True), 2, [Coupling(), Field()]), (3, 4), None),
        "periodic_8nbr_q3_3x3": (MRF(lattice(8, periodic=True), 3, [Coupling()]), (3, 3), None),
        "wide_2x7": (MRF(lattice(4, directional=True), 2,
                         [Coupling("product", by_type=True), Field("value")],
                         state_values=(-1, 1)), (2, 7), None),
        "tall_4x2_q3": (MRF(lattice(8), 3, [Coupling(), Field()]), (4, 2), None),
        "random_graph_q3": (MRF(from_adjacency(_random_graph(9, 0.35, 1)), 3,
                                [Coupling(), Field()]), None, None),
        "random_graph_typed": (MRF(from_adjacency(edges_typed, types), 2,
                                   [Coupling(by_type=True), Field()]), None, None),
        "dense_graph": (MRF(from_adjacency(_random_graph(11, 0.7, 2)), 2, [Coupling(), Field()]),
                        None, None),
        "cycle_9": (MRF(from_adjacency(_cycle(9)), 3, [Coupling(), Field()]), None, None),
        "cycle_9_covariates": (MRF(from_adjacency(_cycle(9)), 2,
                                   [Coupling(), Field(), NodeCovariate("z")]), None,
                               {"z": rng.normal(size=9)}),
        "random_graph_covariates": (
            MRF(from_adjacency(_random_graph(9, 0.4, 4)), 3,
                [Coupling(), EdgeCovariate("w"), NodeCovariate("z")]), None,
            {"z": rng.normal(size=(9, 2)), "w": rng.uniform(-1, 1, size=(
                int(_random_graph(9, 0.4, 4).sum()) // 2))}),
        "disconnected": (MRF(from_adjacency(np.pad(np.kron(np.eye(3, dtype=int), _cycle(3))
                                                   [:8, :8], (0, 2))), 2,
                             [Coupling(), Field()]), None, None),  # 2 triangles, an edge, 2 nodes
        "node_covariates": (MRF(lattice(4), 3, [Coupling(), Field(), NodeCovariate("z")]),
                            (3, 3), {"z": rng.normal(size=(3, 3, 2))}),
        "edge_covariate": (MRF(lattice(8), 2, [Coupling(), EdgeCovariate("w"), Field()]),
                           (3, 4), {"w": rng.uniform(0, 2, size=29)}),
        "potential_8nbr_directional": (MRF(lattice(8, directional=True), 3,
                                           potential=_directional_potential()), (3, 3), None),
    }[name]


CASES = ["ising_3x4", "potts3_8nbr_directional_3x3", "periodic_3x4", "periodic_8nbr_q3_3x3",
         "wide_2x7", "tall_4x2_q3", "random_graph_q3", "random_graph_typed", "dense_graph",
         "cycle_9", "cycle_9_covariates", "random_graph_covariates", "disconnected",
         "node_covariates", "edge_covariate", "potential_8nbr_directional"]


@pytest.mark.parametrize("name", CASES)
def test_elimination_equals_brute_force(name):
    model, shape, cov = _case(name)
    design, names, bounds = model.compile(shape, cov)
    rng = np.random.default_rng(CASES.index(name))
    theta = rng.uniform(bounds[:, 0], bounds[:, 1], size=(4, len(names))) * 0.7
    psi = design.psi(theta)
    lz = LogPartition(design, "eliminate")
    assert lz.method == "eliminate"
    assert sorted(lz.order.tolist()) == list(range(design.graph.n_nodes))
    ref = brute_log_z(design, psi)
    np.testing.assert_allclose(lz(psi), ref, rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(LogPartition(design, "enumerate")(psi), ref, rtol=1e-13,
                               atol=1e-10)
    for k in range(psi.shape[0]):  # one row at a time equals the batch
        np.testing.assert_allclose(lz(psi[k]), ref[k:k + 1], rtol=1e-13, atol=1e-10)


@pytest.mark.parametrize("scale", [15.0, 400.0])
def test_elimination_is_stable_at_strong_couplings(scale):
    design, names, _ = MRF(lattice(8, directional=True), 3,
                           [Coupling(by_type=True), Field()]).compile((3, 3))
    theta = np.random.default_rng(5).normal(size=(3, len(names))) * scale
    psi = design.psi(theta)
    out = LogPartition(design, "eliminate")(psi)
    ref = brute_log_z(design, psi)
    assert np.all(np.isfinite(out)) and (scale < 100 or np.abs(ref).min() > 1000)  # exp overflows
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-10)


@pytest.mark.parametrize("n", [2, 7, 40])
def test_ising_chain_and_ring_closed_forms(n):
    J = np.array([-1.3, -0.2, 0.0, 0.45, 2.0])
    path = np.diag(np.ones(n - 1, int), 1)
    for ring in (False, True):
        if ring and n < 3:
            continue
        adj = _cycle(n) if ring else path + path.T
        m = MRF(from_adjacency(adj), 2, [Coupling("product")], state_values=(-1, 1))
        design, names, _ = m.compile()
        assert names == ("coupling",)
        lz = LogPartition(design, "auto")
        if n == 40:
            assert lz.method == "eliminate" and lz.width == (2 if ring else 1)
        if ring:  # (2 cosh J)^n + (2 sinh J)^n = (2 cosh J)^n (1 + tanh(J)^n)
            expect = n * np.log(2 * np.cosh(J)) + np.log1p(np.tanh(J) ** n)
        else:  # 2 (2 cosh J)^(n-1)
            expect = np.log(2.0) + (n - 1) * np.log(2 * np.cosh(J))
        np.testing.assert_allclose(lz(design.psi(J[:, None])), expect, rtol=1e-13, atol=1e-10)


def test_ising_10x10_matches_row_transfer_matrix():
    design, _, _ = MRF(lattice(4), **ISING).compile((10, 10))
    lz = LogPartition(design, "auto")
    assert lz.method == "eliminate"
    assert lz.width == 10 and lz.max_factor_entries == 2 ** 11
    theta = np.array([[0.44, 0.0], [-0.3, 0.2], [0.7, -0.05]])  # (coupling, field)
    out = lz(design.psi(theta))
    assert np.all(np.isfinite(out))
    v = np.array([-1.0, 1.0])
    for (J, h), got in zip(theta, out, strict=True):
        assert got == pytest.approx(transfer_log_z((10, 10), J * np.outer(v, v), h * v),
                                    rel=1e-13, abs=1e-10)


def test_potts_4x30_q3_is_feasible_and_matches_transfer_matrix():
    design, _, _ = MRF(lattice(4), 3, [Coupling(), Field()]).compile((4, 30))
    lz = LogPartition(design)
    assert lz.method == "eliminate"
    assert lz.width == 4 and lz.max_factor_entries == 3 ** 5
    theta = np.array([[0.9, 0.1, -0.2], [-0.4, 0.3, 0.0]])  # coupling, field_1, field_2
    out = lz(design.psi(theta))
    for (J, h1, h2), got in zip(theta, out, strict=True):
        ref = transfer_log_z((4, 30), J * np.eye(3), np.array([0.0, h1, h2]))
        assert got == pytest.approx(ref, rel=1e-13, abs=1e-10)


def test_8_neighbour_lattice_width_is_one_more():
    design, *_ = MRF(lattice(8), **ISING).compile((9, 6))
    assert LogPartition(design, "eliminate").width == 7
    design, *_ = MRF(lattice(4), **ISING).compile((9, 6))
    assert LogPartition(design, "eliminate").width == 6


@pytest.mark.parametrize("method", ["auto", "eliminate"])
def test_64x64_is_refused_with_the_sizes(method):
    design, *_ = MRF(lattice(4), **ISING).compile((64, 64))
    with pytest.raises(ValueError) as err:
        LogPartition(design, method)
    msg = str(err.value)
    assert "\n" not in msg
    assert "induced width 64" in msg and "2^65" in msg
    assert f"MAX_FACTOR_ENTRIES = {MAX_FACTOR_ENTRIES}" in msg
    assert "smaller" in msg and "enumeration" in msg and "pseudolikelihood" in msg
    if method == "auto":
        assert "2^4096" in msg and f"MAX_ENUMERATION = {MAX_ENUMERATION}" in msg


def test_exact_target_refuses_64x64_and_uses_elimination_on_3x4():
    m = MRF(lattice(4), **ISING)
    with pytest.raises(ValueError, match="2\\^65"):
        m.target("exact", np.zeros((64, 64), int))
    x = np.random.default_rng(0).integers(0, 2, size=(2, 3, 4))
    t = m.target("exact", x, method="eliminate")
    assert t.method == "eliminate" and t.describe()["method"] == "eliminate"
    theta = np.array([[0.3, -0.1], [-0.5, 0.4]])
    psi = t.design.psi(theta)
    expect = psi @ t.design.statistics(x.reshape(2, -1)).sum(axis=0) \
        - 2 * brute_log_z(t.design, psi)
    np.testing.assert_allclose(t.log_prob(theta), expect, rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(t.log_partition(theta), brute_log_z(t.design, psi), atol=1e-10)


def test_dense_general_graph_is_refused_with_both_sizes():
    n = 23  # the complete graph: width n - 1, q^n > both limits
    design, *_ = MRF(from_adjacency(1 - np.eye(n, dtype=int)), 2,
                     [Coupling(), Field()]).compile()
    with pytest.raises(ValueError, match=r"2\^23 .*2\^23 .*induced width 22 or more"):
        LogPartition(design)


def test_auto_picks_the_cheaper_method():
    design, *_ = MRF(lattice(4), **ISING).compile((2, 2))
    assert LogPartition(design).method == "enumerate"
    design, *_ = MRF(lattice(4), **ISING).compile((3, 4))
    lz = LogPartition(design)
    assert lz.method == "eliminate" and lz.width == 3
    assert LogPartition(design, "enumerate").method == "enumerate"


def test_chunked_batches_equal_one_pass(monkeypatch):
    design, names, _ = MRF(lattice(4), 3, [Coupling(), Field()]).compile((3, 5))
    lz = LogPartition(design, "eliminate")
    psi = design.psi(np.random.default_rng(2).normal(size=(37, len(names))))
    whole = lz(psi)
    monkeypatch.setattr("mrfpe.budget.WORKING_CHUNK_BYTES", 2 * lz._row_bytes)
    assert len(chunk_rows(37, lz._row_bytes, minimum=1)) > 10
    np.testing.assert_allclose(lz(psi), whole, rtol=1e-15, atol=0)
    assert lz(psi[:0]).shape == (0,)


def test_memory_budget_is_checked_up_front():
    design, *_ = MRF(lattice(4), **ISING).compile((12, 12))
    old = set_memory_budget(10_000)
    try:
        with pytest.raises(MemoryBudgetError, match="variable elimination"):
            LogPartition(design, "eliminate")
    finally:
        set_memory_budget(old)


def test_bad_method_and_too_many_configurations():
    design, *_ = MRF(lattice(4), **ISING).compile((3, 3))
    with pytest.raises(ValueError, match="method must be"):
        LogPartition(design, "exact")
    design, *_ = MRF(lattice(4), **ISING).compile((5, 5))
    with pytest.raises(ValueError, match="enumeration is limited"):
        LogPartition(design, "enumerate")
