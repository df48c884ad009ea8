"""Corner-vertex lattice: indexing, triangulation, triplet cliques, partitions."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.lattice import Lattice


def _csr_lists(csr, n):
    indptr, idx = csr
    assert indptr.shape == (n + 1,) and indptr[0] == 0 and indptr[-1] == len(idx)
    return [list(idx[indptr[i]:indptr[i + 1]]) for i in range(n)]


@pytest.mark.parametrize("H,W", [(1, 1), (2, 3), (4, 5)])
def test_sizes_and_pixel_nodes(H, W):
    L = Lattice(H, W)
    assert L.shape == (H, W) and L.node_shape == (H + 1, W + 1)
    assert L.n_nodes == (H + 1) * (W + 1) and L.n_pixels == H * W
    for r in range(H):
        for c in range(W):
            p = r * W + c
            tl = r * (W + 1) + c
            assert list(L.pixel_nodes[p]) == [tl, tl + 1, tl + W + 1, tl + W + 2]
    rr, cc = L.node_rc(np.arange(L.n_nodes))
    assert np.array_equal(L.node_id(rr, cc), np.arange(L.n_nodes))


@pytest.mark.parametrize("H,W", [(1, 1), (3, 4)])
def test_triangles_split_each_pixel_along_one_diagonal(H, W):
    L = Lattice(H, W)
    assert L.triangles.shape == (2 * H * W, 3)
    assert np.array_equal(np.bincount(L.triangle_pixel), np.full(H * W, 2))
    xy = np.stack(np.divmod(np.arange(L.n_nodes), W + 1)[::-1], axis=1).astype(float)
    for p in range(H * W):
        tris = L.triangles[L.triangle_pixel == p]
        corners = set(L.pixel_nodes[p])
        tl, _, _, br = L.pixel_nodes[p]
        areas = []
        for tri in tris:
            assert set(tri) <= corners and len(set(tri)) == 3
            assert tl in tri and br in tri  # the shared diagonal TL-BR
            a, b, c = xy[tri]
            u, w = b - a, c - a
            areas.append(0.5 * (u[0] * w[1] - u[1] * w[0]))
        # Same winding (same sign of signed area), each covering half a pixel.
        assert np.allclose(areas, [0.5, 0.5])


def test_node_triangles_and_pixels_against_brute_force():
    L = Lattice(3, 4)
    tri_lists = _csr_lists(L.node_triangles, L.n_nodes)
    pix_lists = _csr_lists(L.node_pixels, L.n_nodes)
    for i in range(L.n_nodes):
        assert tri_lists[i] == [t for t in range(L.n_triangles) if i in L.triangles[t]]
        assert pix_lists[i] == [p for p in range(L.n_pixels) if i in L.pixel_nodes[p]]
        assert len(tri_lists[i]) <= 6 and len(pix_lists[i]) <= 4
    # Interior nodes: six triangles, four pixels.
    interior = L.node_id(1, 1)
    assert len(tri_lists[interior]) == 6 and len(pix_lists[interior]) == 4


def test_clique_counts():
    H, W = 3, 4
    L = Lattice(H, W)
    assert L.cliques.shape == (4 * H * W, 3)
    counts = np.bincount(L.cliques[:, 0], minlength=L.n_nodes).reshape(H + 1, W + 1)
    expected = np.full((H + 1, W + 1), 4)
    expected[0, :] = expected[-1, :] = 2
    expected[:, 0] = expected[:, -1] = 2
    expected[[0, 0, -1, -1], [0, -1, 0, -1]] = 1
    assert np.array_equal(counts, expected)
    lists = _csr_lists(L.node_cliques, L.n_nodes)
    for i in range(L.n_nodes):
        assert lists[i] == list(np.flatnonzero(L.cliques[:, 0] == i))


def test_cliques_are_edge_neighbour_triplets_in_one_pixel():
    H, W = 3, 3
    L = Lattice(H, W)
    rc = np.stack(L.node_rc(L.cliques), axis=-1)  # (n, 3, 2)
    for (i, j, k), p, pts in zip(L.cliques, L.clique_pixel, rc):
        assert {i, j, k} <= set(L.pixel_nodes[p])
        di, dj = pts[1] - pts[0], pts[2] - pts[0]
        assert abs(di).sum() == 1 and di[0] == 0  # j: horizontal neighbour
        assert abs(dj).sum() == 1 and dj[1] == 0  # k: vertical neighbour
    # Every (pixel, corner) pair appears exactly once.
    pairs = {(int(p), int(i)) for p, i in zip(L.clique_pixel, L.cliques[:, 0])}
    assert len(pairs) == 4 * H * W


@pytest.mark.parametrize("kind", ["strided", "block"])
@pytest.mark.parametrize("k", [1, 3, 7, 20])
def test_partition_disjoint_and_covering(kind, k):
    L = Lattice(3, 4)
    parts = L.partition(k, kind=kind)
    assert len(parts) == k
    allids = np.concatenate(parts)
    assert np.array_equal(np.sort(allids), np.arange(L.n_nodes))
    if kind == "strided":
        for n, part in enumerate(parts):
            assert np.array_equal(part, np.arange(n, L.n_nodes, k))
    else:
        for part in parts:
            assert np.all(np.diff(part) == 1)


def test_partition_bad_k():
    L = Lattice(2, 2)
    with pytest.raises(ValueError, match="k must be in"):
        L.partition(0)
    with pytest.raises(ValueError, match="k must be in"):
        L.partition(L.n_nodes + 1)
    with pytest.raises(ValueError, match="k must be an integer"):
        L.partition(2.5)


def test_partition_bad_kind():
    with pytest.raises(ValueError, match="kind must be"):
        Lattice(2, 2).partition(2, kind="random")


def test_bad_size():
    with pytest.raises(ValueError, match="H must be an integer >= 1"):
        Lattice(0, 3)
    with pytest.raises(ValueError, match="W must be an integer >= 1"):
        Lattice(3, 2.0)


def test_arrays_read_only():
    L = Lattice(2, 2)
    with pytest.raises(ValueError):
        L.triangles[0, 0] = 5


def test_every_partition_uses_split_ids():
    from mrfpe.models.short_forms import gibbs_sample
    from mrfpe.targets import get
    from mrfpe.targets.partition import split_ids
    from mrfpe.testing import CorrelatedGaussian

    lat = Lattice(3, 4)
    for kind in ("strided", "block"):
        want = split_ids(np.arange(lat.n_nodes), 3, kind)
        assert all(np.array_equal(a, b) for a, b in zip(lat.partition(3, kind), want,
                                                        strict=True))
        x = gibbs_sample([0.3, 0.0], (3, 4), seed=0)
        sites = [p.nodes for p in get("potts", x).partition(3, kind)]
        assert all(np.array_equal(a, b) for a, b in zip(sites, split_ids(np.arange(12), 3,
                                                                         kind), strict=True))
        g = CorrelatedGaussian(12)
        obs = [p.obs for p in g.partition(3, kind)]
        assert all(np.array_equal(a, g.obs[b]) for a, b in zip(obs, split_ids(np.arange(12), 3,
                                                                           kind), strict=True))
