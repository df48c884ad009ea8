"""The data terms of whole labellings of a BRDF scene, with a memo of triangle radiances.

A data term (a pixel's two triangles, or one triplet clique) is a function of
the labels of its vertices: the vertices' 3-D points fix each triangle's
geometry, the BRDF parameters its radiance (thesis 4.17 in the separable form
of :mod:`mrfpe.brdf.targets.reflectance`). :func:`term_energies` renders the terms
of a batch of labellings; :func:`draw_features` keeps the theta-independent
part of that render for labellings that are reused at many parameter vectors
(the draws of a Monte Carlo MLE).

The memo
--------
A Gibbs chain runs at one ``theta`` and renders each triangle at the same
few label triples over and over: a sweep renders every triangle once for
every label of its coding's vertex (:mod:`mrfpe.brdf.simulate`), and the
other two vertices' labels move little between sweeps. :class:`RadianceMemo`
keeps the radiance of every (triangle, vertex labels) rendered so far at one
coefficient row, in a dense ``(n_triangles, B, B, B)`` array, so that after the
first sweeps a sweep is mostly table look-ups. A memoised radiance is the value
the direct render computes (the same elementwise operations on the same
inputs), so chains and energies with and without the memo agree bit for bit
(tested). The memo holds one parameter vector; it is used when its array fits
in :data:`MEMO_BUDGET_FRACTION` of the memory budget (:mod:`mrfpe.budget`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf.shading import shading_features, triangle_geometry
from mrfpe.brdf.targets import reflectance
from mrfpe.budget import memory_budget

__all__ = ["MEMO_BUDGET_FRACTION", "RadianceMemo", "data_terms", "draw_features", "memo_at",
           "memo_for", "term_energies"]

#: Triangles rendered per numpy batch (bounds the working memory, ~1 kB per triangle).
BATCH_TRIANGLES = 65536
#: Largest share of the memory budget a radiance memo may take.
MEMO_BUDGET_FRACTION = 0.25


def _features(field: Any, nodes: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Separable features (m, 5) of triangles with vertex nodes and labels (m, 3) each."""
    sc = field.scene
    pts = field.points[nodes, labels]  # (m, 3 vertices, 3)
    geom = triangle_geometry(pts[:, 0], pts[:, 1], pts[:, 2], sc.camera, sc.light,
                             sc.tangent_ref)
    feats, weight = shading_features(sc.model, geom)
    return reflectance.features(sc.model, feats, weight)


def _batched_features(field: Any, nodes: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """:func:`_features` (m, 5) of any number of triangles, :data:`BATCH_TRIANGLES` at a time."""
    out = np.empty((nodes.shape[0], 5))
    for a in range(0, nodes.shape[0], BATCH_TRIANGLES):
        sl = slice(a, a + BATCH_TRIANGLES)
        out[sl] = _features(field, nodes[sl], labels[sl])
    return out


def _render(field: Any, coef: np.ndarray, nodes: np.ndarray,
            labels: np.ndarray) -> np.ndarray:
    """Radiance (N, m) at coefficient rows (N, 5) of triangles given as (m, 3) nodes/labels."""
    return reflectance.radiance(coef, _batched_features(field, nodes, labels))


def _triangles(field: Any, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex nodes and labels (M * n_tri, 3) of every triangle of labellings (M, n_nodes)."""
    tri = field.tri
    nodes = np.broadcast_to(tri, (labels.shape[0], *tri.shape)).reshape(-1, 3)
    return nodes, labels[:, tri].reshape(-1, 3)


class RadianceMemo:
    """Radiances of (triangle, vertex labels) at one coefficient row (module docstring).

    ``NaN`` marks a triple not rendered yet.
    """

    def __init__(self, field: Any, coef: np.ndarray) -> None:
        B = field.n_labels
        self.coef = np.array(coef, dtype=np.float64).reshape(1, 5)
        self.values = np.full(field.tri.shape[0] * B ** 3, np.nan)

    @staticmethod
    def nbytes(field: Any) -> float:
        return 8.0 * field.tri.shape[0] * field.n_labels ** 3

    def radiance(self, field: Any, labels: np.ndarray) -> np.ndarray:
        """Radiance (M, n_tri) of labellings (M, n_nodes), rendering only unseen triples."""
        return self._at(field, _keys(field, labels))

    def coding_radiance(self, field: Any, x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """Radiance (B, n_tri) of labelling ``x`` (n_nodes,) with every node of ``nodes`` (no
        two in one triangle) set to each label in turn; other triangles repeat their value."""
        B, tri = field.n_labels, field.tri
        in_set = np.zeros(field.n_nodes, dtype=bool)
        in_set[nodes] = True
        hit = in_set[tri]  # (n_tri, 3): which vertex, if any, is in the set
        stride = hit @ np.array([B * B, B, 1])
        current = np.sum(hit * x[tri], axis=1)
        key = _keys(field, x[None])[0] + (np.arange(B)[:, None] - current) * stride
        return self._at(field, key)

    def _at(self, field: Any, key: np.ndarray) -> np.ndarray:
        vals = self.values[key]
        miss = np.isnan(vals)
        if miss.any():
            B = field.n_labels
            new_keys, inverse = np.unique(key[miss], return_inverse=True)
            t, rest = np.divmod(new_keys, B ** 3)
            labels = np.stack([rest // (B * B), rest // B % B, rest % B], axis=1)
            new = _render(field, self.coef, field.tri[t], labels)[0]
            self.values[new_keys] = new
            vals[miss] = new[inverse]
        return vals


def _keys(field: Any, labels: np.ndarray) -> np.ndarray:
    """Memo index (M, n_tri) of every triangle of labellings (M, n_nodes)."""
    B, tri = field.n_labels, field.tri
    lab = labels[:, tri]
    return ((np.arange(tri.shape[0]) * B + lab[..., 0]) * B + lab[..., 1]) * B + lab[..., 2]


def memo_at(field: Any, coef: np.ndarray) -> RadianceMemo | None:
    """The field's memo if it holds the radiances of ``coef`` (one row), else None."""
    memo = field.memo.get("radiance")
    if memo is None or coef.shape[0] != 1 or not np.array_equal(memo.coef, coef):
        return None
    return memo


def memo_for(field: Any, coef: np.ndarray) -> RadianceMemo | None:
    """The field's memo for ``coef`` (one row), made or reset as needed; None if too big."""
    if RadianceMemo.nbytes(field) > MEMO_BUDGET_FRACTION * memory_budget():
        return None
    memo = memo_at(field, coef)
    if memo is None:
        memo = field.memo.get("radiance")
        if memo is None:
            memo = field.memo["radiance"] = RadianceMemo(field, coef)
        else:  # the memo of another theta: reset
            memo.coef = np.array(coef, dtype=np.float64).reshape(1, 5)
            memo.values.fill(np.nan)
    return memo


def term_energies(field: Any, coef: np.ndarray, labels: np.ndarray,
                  memo: RadianceMemo | None = None) -> np.ndarray:
    """Data terms ``D_t`` (N, M, n_terms) of labellings (M, n_nodes) at coefficients (N, 5).

    Pixel form ``|y_p - (L(T_2p) + L(T_2p+1)) / 2| / sigma_b`` (4.12), triplet form
    ``|y_c - L(c)| / sigma_b`` (4.20). With ``memo`` (one coefficient row, equal to
    ``coef``) radiances come from it; otherwise each labelling's geometry is computed
    once (:data:`BATCH_TRIANGLES` triangles at a time) and its radiance once per
    coefficient row.
    """
    if memo is not None:
        return data_terms(field, memo.radiance(field, labels)[None])
    rad = _render(field, coef, *_triangles(field, labels))
    return data_terms(field, rad.reshape(coef.shape[0], labels.shape[0], -1))


def data_terms(field: Any, rad: np.ndarray) -> np.ndarray:
    """Data terms (N, M, n_terms) from triangle radiances (N, M, n_tri) (4.12 or 4.20)."""
    rad = rad.reshape(*rad.shape[:2], -1, field.per_term).sum(axis=3)
    return np.abs(field.y - field.w * rad) / field.sigma_b


def draw_features(field: Any, labels: np.ndarray) -> np.ndarray:
    """Separable features (M, n_tri, 5) of labellings (M, n_nodes): their render minus theta.

    ``reflectance.radiance(coef, features[k])`` is labelling ``k``'s radiance at any
    coefficient rows, so energies of fixed labellings at many parameter vectors cost
    one exponential per triangle and vector.
    """
    return _batched_features(field, *_triangles(field, labels)).reshape(labels.shape[0], -1, 5)
