"""Graphs: lattices, adjacency and networkx input, colourings, validation."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp

from mrfpe.models.graph import Graph, as_graph_spec, from_adjacency, from_networkx, lattice


def _proper(g: Graph) -> bool:
    c = g.colouring()
    return not np.any(c[g.edges[:, 0]] == c[g.edges[:, 1]])


@pytest.mark.parametrize("nbhd,periodic,edges", [(4, False, 3 * 3 + 2 * 4), (8, False, 17 + 12),
                                                 (4, True, 24), (8, True, 48)])
def test_lattice_edge_counts(nbhd, periodic, edges):
    g = lattice(nbhd, periodic=periodic).build((3, 4))
    assert g.n_edges == edges and g.shape == (3, 4) and _proper(g)


def test_lattice_neighbours_by_brute_force():
    g = lattice(8).build((4, 5))
    want = {(min(r * 5 + c, r2 * 5 + c2), max(r * 5 + c, r2 * 5 + c2))
            for r in range(4) for c in range(5) for r2 in range(4) for c2 in range(5)
            if max(abs(r - r2), abs(c - c2)) == 1}
    assert set(map(tuple, g.edges.tolist())) == want


def test_codings_counts_and_proper():
    assert lattice(4).n_codings((6, 7)) == 2
    assert lattice(8).n_codings((6, 7)) == 4
    g = lattice(8, periodic=True).build((5, 5))  # odd torus: greedy colouring, still proper
    assert _proper(g) and g.n_colours >= 5
    classes = g.colour_classes()
    assert sorted(np.concatenate(classes).tolist()) == list(range(25))


def test_directional_types():
    g = lattice(8, directional=True).build((3, 3))
    assert g.edge_type_names == ("horizontal", "vertical", "diagonal", "antidiagonal")
    for (i, j), t in zip(g.edges, g.edge_type, strict=True):
        (ri, ci), (rj, cj) = divmod(int(i), 3), divmod(int(j), 3)
        d = (rj - ri, cj - ci)
        assert {0: (0, 1), 1: (1, 0), 2: (1, 1), 3: (1, -1)}[int(t)] == d


def test_custom_offsets_and_mirrors():
    spec = lattice([(0, 2), (-1, 0)], directional=True)
    assert spec.offsets == ((0, 2), (1, 0))
    with pytest.raises(ValueError, match="twice"):
        lattice([(0, 1), (0, -1)])
    with pytest.raises(ValueError, match=r"\(0, 0\)"):
        lattice([(0, 0)])
    with pytest.raises(ValueError, match="neighbourhood"):
        lattice(6)


def test_from_adjacency_and_networkx_agree():
    G = nx.petersen_graph()
    a = from_networkx(G)
    b = from_adjacency(nx.to_scipy_sparse_array(G))
    assert np.array_equal(a.edges, b.edges) and _proper(a) and a.n_colours <= 4
    assert isinstance(as_graph_spec(G), Graph)


def test_bad_graphs_rejected():
    with pytest.raises(ValueError, match="self-loops"):
        from_adjacency(np.eye(3))
    A = np.zeros((3, 3))
    A[0, 1] = 1
    with pytest.raises(ValueError, match="symmetric"):
        from_adjacency(sp.csr_matrix(A))
    with pytest.raises(ValueError, match="square"):
        from_adjacency(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="self-loops"):
        Graph(3, [[1, 1]])
    with pytest.raises(ValueError, match="twice"):
        Graph(3, [[0, 1], [1, 0]])
    with pytest.raises(ValueError, match="shape"):
        lattice(4).build((0, 3))


def test_edge_types_from_adjacency():
    A = np.array([[0, 1, 2], [1, 0, 0], [2, 0, 0]])
    g = from_adjacency(A != 0, edge_type=A)
    assert g.edge_type_names == ("type_1", "type_2") and g.edge_type.tolist() == [0, 1]
