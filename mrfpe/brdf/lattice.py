"""The corner-vertex lattice of the thesis (4.2, Figs. 4.1-4.3, 4.27).

An H x W image has (H+1) x (W+1) *corner-vertex nodes* at the pixel corners.
Node ``(r, c)`` (row ``r`` in 0..H, column ``c`` in 0..W) has id
``r * (W + 1) + c`` and sits at image position ``(x, y) = (c, r)`` in pixel
units; pixel ``(r, c)`` has id ``r * W + c`` and covers ``[c, c+1] x [r, r+1]``.

Two triangulations live on the lattice:

* ``triangles``: the renderer's and default data term's split of every pixel
  into two triangles along the top-left -> bottom-right diagonal,
  ``2p = (TL, TR, BR)`` (upper-right half) and ``2p + 1 = (TL, BR, BL)``
  (lower-left half). Both have the same winding in the image, so a consistent
  normal orientation follows from the vertex order.
* ``cliques``: the thesis's triplet cliques (4.27): every node ``i`` with its
  horizontal neighbour ``j`` and vertical neighbour ``k`` inside one pixel it
  touches -- four per interior node (one per quadrant), two on an edge, one at
  a corner; 4HW in all, ordered by centre node, then quadrant (up-left,
  up-right, down-left, down-right).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from mrfpe.targets.partition import PARTITION_KINDS, split_ids

__all__ = ["PARTITION_KINDS", "Lattice", "split_ids"]


def _csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR map key -> sorted positions of ``keys`` (ids 0..len(keys)-1) equal to it."""
    order = np.argsort(keys, kind="stable")
    counts = np.bincount(keys, minlength=n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    return indptr, order.astype(np.int64)


@dataclass(frozen=True)
class Lattice:
    """Corner-vertex lattice of an H x W image (see module docstring).

    Attributes
    ----------
    shape : (H, W)
    node_shape : (H+1, W+1)
    n_nodes, n_pixels : int
    pixel_nodes : ndarray (HW, 4)
        Corner node ids of each pixel: top-left, top-right, bottom-left, bottom-right.
    triangles : ndarray (2HW, 3)
        Node ids of the two triangles per pixel (renderer / default data term).
    triangle_pixel : ndarray (2HW,)
    node_triangles : (indptr, indices)
        CSR: the (up to 6) triangles containing each node.
    node_pixels : (indptr, indices)
        CSR: the (up to 4) pixels touching each node.
    cliques : ndarray (4HW, 3)
        Thesis triplets ``(i, j, k)``: centre, horizontal and vertical neighbour.
    clique_pixel : ndarray (4HW,)
    node_cliques : (indptr, indices)
        CSR: the cliques centred on each node (cliques are ordered by centre).
    """

    H: int
    W: int

    def __post_init__(self) -> None:
        for name in ("H", "W"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, int | np.integer) or val < 1:
                raise ValueError(f"{name} must be an integer >= 1; got {val!r}")

    # -- derived arrays: computed on first use, read-only -----------------------------
    @cached_property
    def _arrays(self) -> dict[str, Any]:
        """Every derived array at once (they share their intermediate steps)."""
        H, W = int(self.H), int(self.W)
        W1 = W + 1
        r, c = np.divmod(np.arange(H * W, dtype=np.int64), W)
        tl = r * W1 + c
        pn = np.stack([tl, tl + 1, tl + W1, tl + W1 + 1], axis=1)
        tri = np.empty((2 * H * W, 3), dtype=np.int64)
        tri[0::2] = pn[:, [0, 1, 3]]  # upper-right half (TL, TR, BR)
        tri[1::2] = pn[:, [0, 3, 2]]  # lower-left half (TL, BR, BL)
        tri_pix = np.repeat(np.arange(H * W, dtype=np.int64), 2)

        # Triplet cliques: for corner q of pixel p, centre = that corner, j = the
        # horizontal neighbour in p, k = the vertical neighbour in p.
        # corner index q: 0 TL, 1 TR, 2 BL, 3 BR -> (j, k) corner indices.
        jk = np.array([[1, 2], [0, 3], [3, 0], [2, 1]])
        cen = pn.reshape(-1)  # (HW*4,) centre node of pixel p corner q
        pix = np.repeat(np.arange(H * W, dtype=np.int64), 4)
        q = np.tile(np.arange(4), H * W)
        cl = np.stack([cen, pn[pix, jk[q, 0]], pn[pix, jk[q, 1]]], axis=1)
        # Quadrant of the pixel seen from the centre: corner BR -> up-left (0), BL ->
        # up-right (1), TR -> down-left (2), TL -> down-right (3).
        quad = 3 - q
        order = np.lexsort((quad, cen))
        cl = cl[order]
        cl_pix = pix[order]

        n_nodes = (H + 1) * W1
        for arr in (pn, tri, tri_pix, cl, cl_pix):
            arr.flags.writeable = False
        return {"pixel_nodes": pn, "triangles": tri, "triangle_pixel": tri_pix,
                "node_triangles": _csr_from_pairs(tri.reshape(-1), n_nodes, 3),
                "node_pixels": _csr_from_pairs(pn.reshape(-1), n_nodes, 4),
                "cliques": cl, "clique_pixel": cl_pix, "node_cliques": _csr(cl[:, 0], n_nodes)}

    @property
    def pixel_nodes(self) -> np.ndarray:
        return self._arrays["pixel_nodes"]

    @property
    def triangles(self) -> np.ndarray:
        return self._arrays["triangles"]

    @property
    def triangle_pixel(self) -> np.ndarray:
        return self._arrays["triangle_pixel"]

    @property
    def node_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        return self._arrays["node_triangles"]

    @property
    def node_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        return self._arrays["node_pixels"]

    @property
    def cliques(self) -> np.ndarray:
        return self._arrays["cliques"]

    @property
    def clique_pixel(self) -> np.ndarray:
        return self._arrays["clique_pixel"]

    @property
    def node_cliques(self) -> tuple[np.ndarray, np.ndarray]:
        return self._arrays["node_cliques"]

    # -- sizes --------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.H), int(self.W))

    @property
    def node_shape(self) -> tuple[int, int]:
        return (int(self.H) + 1, int(self.W) + 1)

    @property
    def n_nodes(self) -> int:
        return (int(self.H) + 1) * (int(self.W) + 1)

    @property
    def n_pixels(self) -> int:
        return int(self.H) * int(self.W)

    @property
    def n_triangles(self) -> int:
        return 2 * int(self.H) * int(self.W)

    def node_id(self, r, c):
        """Node id of row ``r``, column ``c`` (arrays allowed)."""
        return np.asarray(r) * (self.W + 1) + np.asarray(c)

    def node_rc(self, i):
        """(row, column) of node id(s) ``i``."""
        return np.divmod(np.asarray(i), self.W + 1)

    # -- sub-lattices -----------------------------------------------------------------
    def partition(self, k: int, kind: str = "strided") -> list[np.ndarray]:
        """Split the node ids into ``k`` disjoint sub-lattices covering all nodes.

        ``kind="strided"``: ``S^n = {n, n+k, n+2k, ...}`` (thesis 5.68, 7.8 with k=3).
        ``kind="block"``: ``k`` contiguous runs of node ids of (nearly) equal size
        (thesis 5.67, which fixes the block *size*; here the number of blocks is given).
        See :func:`mrfpe.targets.partition.split_ids`, the one rule every target's
        ``partition`` uses.
        """
        return split_ids(np.arange(self.n_nodes, dtype=np.int64), k, kind, what="n_nodes")

    def codings(self) -> list[np.ndarray]:
        """Node ids of Besag's codings (1974, Sec. 6.1): the classes ``2 (r % 2) + c % 2``.

        A node's pseudolikelihood term involves the nodes of the pixels around it
        (its 8-neighbourhood), so these four classes -- no two nodes of one class
        share a pixel -- are conditionally independent given the rest. (The
        ``strided`` sub-lattices of :meth:`partition` are codings only by accident
        of the width.)
        """
        r, c = np.divmod(np.arange(self.n_nodes, dtype=np.int64), self.node_shape[1])
        colour = 2 * (r % 2) + c % 2
        return [np.flatnonzero(colour == k) for k in range(4) if np.any(colour == k)]


def _csr_from_pairs(keys: np.ndarray, n: int, group: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR key -> ids ``pos // group`` of the flat positions where ``keys`` equals key."""
    indptr, pos = _csr(keys, n)
    return indptr, pos // group
