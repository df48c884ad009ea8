"""Theta-independent precompute of the BRDF data energy ``U^A`` (thesis 4.12, 4.20, 4.27).

For a node ``i`` taking label ``s`` (its 3-D point moved along its ray, every
other node at its observed label), the data energy is a sum over the node's
*slots* -- the image observations its label influences --

    ``U^A_i(s) = sum_slots |y_slot - w_slot * (sum of the slot's triangle radiances)| / sigma_b``.

Two data terms share this form:

``"pixel"`` (default; agrees exactly with :func:`mrfpe.brdf.synthetic.render`)
    One slot per pixel touching the node (up to 4). Each pixel is split into
    the lattice's two triangles (:attr:`mrfpe.brdf.lattice.Lattice.triangles`) and
    rendered as their mean (``w = 1/2``). A triangle containing node ``i`` is
    *variable* (its radiance depends on ``s``; up to 6 per node); the other
    triangle of a pixel whose diagonal does not pass through ``i`` is *fixed*
    (all corners observed) and its radiance is computed once per particle and
    node, not per label. Noise-free data then have zero data energy at the
    true labels and parameters.

``"triplet"`` (the thesis's literal form, 4.12/4.20 with 4.27)
    One slot per triplet clique centred on the node (four for an interior
    node): the clique triangle ``(i, j, k)``'s radiance is compared with the
    whole pixel's intensity (``w = 1``, no fixed triangle). Cheaper (4 BRDF
    evaluations per label instead of 6) but inconsistent with a renderer that
    averages over the pixel, so noise-free data do not give zero energy.

The tables are CSR-like arrays sorted by node (:class:`mrfpe.brdf.engine.tables.DataTables`,
re-exported here; :mod:`mrfpe.brdf.engine.classic` explains the layout) and
:meth:`DataTables.subset` extracts a sub-lattice's rows without touching
any other node's entries. Geometry (3-D points, normals, light and view
directions, irradiance) is computed by :func:`mrfpe.brdf.shading.triangle_geometry`
with vertices in the lattice's order, exactly as the renderer does.
"""

from __future__ import annotations

import numpy as np

from mrfpe.brdf.engine.tables import DataTables, chunk_bounds
from mrfpe.brdf.shading import shading_features, triangle_geometry
from mrfpe.brdf.targets import reflectance

__all__ = ["DATA_TERMS", "DataTables", "build_tables", "chunk_bounds", "energies_reference"]

DATA_TERMS = ("pixel", "triplet")

#: Triangles whose geometry is computed per numpy batch at construction
#: (bounds the construction's peak memory).
_GEOM_BATCH = 131072


def _separable_geometry(model, tri_pts: np.ndarray, scene) -> np.ndarray:
    """Separable features (M, 5) of triangles with vertices ``tri_pts`` (M, 3, 3)."""
    out = np.empty((tri_pts.shape[0], 5))
    for a in range(0, tri_pts.shape[0], _GEOM_BATCH):
        p = tri_pts[a:a + _GEOM_BATCH]
        geom = triangle_geometry(p[:, 0], p[:, 1], p[:, 2], scene.camera, scene.light,
                                 scene.tangent_ref)
        feats, weight = shading_features(model, geom)
        out[a:a + _GEOM_BATCH] = reflectance.features(model, feats, weight)
    return out


def _pixel_slots(scene, Q: np.ndarray) -> tuple:
    """The pixel form's slots: one per pixel touching a node (module docstring).

    Returns ``(slot_node, slot_y, slot_w, slot_nvar, fix_feat, vs, var_nodes, var_pos)``:
    per slot its node, intensity, weight, variable-triangle count and fixed triangle's
    features; per variable triangle its slot ``vs``, vertices and the node's vertex position.
    """
    lat = scene.lattice
    img = scene.image.reshape(-1)
    indptr, pix = lat.node_pixels
    slot_node = np.repeat(np.arange(lat.n_nodes, dtype=np.int64), np.diff(indptr))
    slot_pix = np.asarray(pix, dtype=np.int64)
    n_slots = slot_node.shape[0]
    tris = np.stack([2 * slot_pix, 2 * slot_pix + 1], axis=1)  # (n_slots, 2)
    tri_nodes = lat.triangles[tris]  # (n_slots, 2, 3)
    hit = tri_nodes == slot_node[:, None, None]
    contains = hit.any(axis=2)  # (n_slots, 2)
    slot_nvar = contains.sum(axis=1).astype(np.int64)
    slot_y = img[slot_pix]
    slot_w = np.full(n_slots, 0.5)
    # Fixed triangle: the one of a pixel's two that does not contain the node.
    fixed_slot = np.flatnonzero(slot_nvar == 1)
    fixed_tri = np.where(contains[fixed_slot, 0], 1, 0)
    fix_nodes = tri_nodes[fixed_slot, fixed_tri]  # (n_fixed, 3)
    fix_feat = np.zeros((5, n_slots))
    if fixed_slot.size:
        fix_feat[:, fixed_slot] = _separable_geometry(scene.model, Q[fix_nodes], scene).T
    vs, vt = np.nonzero(contains)  # row-major: sorted by slot, then triangle
    var_nodes = tri_nodes[vs, vt]  # (n_var, 3)
    var_pos = np.argmax(hit[vs, vt], axis=1)
    return slot_node, slot_y, slot_w, slot_nvar, fix_feat, vs, var_nodes, var_pos


def _triplet_slots(scene) -> tuple:
    """The triplet form's slots: one per clique centred on a node; as :func:`_pixel_slots`."""
    lat = scene.lattice
    img = scene.image.reshape(-1)
    order = lat.node_cliques[1]
    cl = lat.cliques[order]
    slot_node = cl[:, 0].astype(np.int64)
    n_slots = slot_node.shape[0]
    slot_y = img[lat.clique_pixel[order]]
    slot_w = np.ones(n_slots)
    slot_nvar = np.ones(n_slots, dtype=np.int64)
    fix_feat = np.zeros((5, n_slots))
    vs = np.arange(n_slots, dtype=np.int64)
    var_nodes = cl.astype(np.int64)
    var_pos = np.zeros(n_slots, dtype=np.int64)
    return slot_node, slot_y, slot_w, slot_nvar, fix_feat, vs, var_nodes, var_pos


def _variable_features(scene, Q: np.ndarray, var_node: np.ndarray, var_nodes: np.ndarray,
                       var_pos: np.ndarray, progress: bool) -> tuple[np.ndarray, np.ndarray]:
    """``var_ptr`` and ``var_feat`` of the variable triangles (vertices at observed points,
    the node's own vertex at each label), in node order."""
    n_nodes = scene.lattice.n_nodes
    B = scene.n_labels
    P = np.asarray(scene.label_points()).reshape(n_nodes, B, 3)
    n_var = var_node.shape[0]
    nv = np.bincount(var_node, minlength=n_nodes).astype(np.int64)
    first = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(nv, out=first[1:])
    t_in_node = np.arange(n_var, dtype=np.int64) - first[var_node]
    var_ptr = first * B
    var_feat = np.empty((5, n_var * B))
    labels = np.arange(B, dtype=np.int64)
    # Entry of (variable triangle v, label s): var_ptr[node] + t * B + s.
    dest = var_ptr[var_node][:, None] + t_in_node[:, None] * B + labels[None, :]  # (n_var, B)
    step = max(1, _GEOM_BATCH // B)
    from tqdm.auto import tqdm

    for a in tqdm(range(0, n_var, step), disable=not progress, leave=False,
                  desc="data tables", unit="batch"):
        sl = slice(a, a + step)
        pts = np.repeat(Q[var_nodes[sl]][:, None], B, axis=1)  # (m, B, 3, 3)
        m = pts.shape[0]
        pts[np.arange(m)[:, None], labels[None, :], var_pos[sl][:, None]] = P[var_node[sl]]
        feats = _separable_geometry(scene.model, pts.reshape(m * B, 3, 3), scene)
        var_feat[:, dest[sl].reshape(-1)] = feats.T
    return var_ptr, var_feat


def build_tables(scene, data_term: str = "pixel", *, progress: bool = False) -> DataTables:
    """Data-energy tables of every node of ``scene`` for ``scene.brdf``.

    Parameters
    ----------
    scene : mrfpe.brdf.scene.Scene
    data_term : "pixel" | "triplet"
        See the module docstring.
    progress : bool
        Show a tqdm bar over the variable triangles' geometry batches.
    """
    if data_term not in DATA_TERMS:
        raise ValueError(f"data_term must be one of {DATA_TERMS}; got {data_term!r}")
    n_nodes = scene.lattice.n_nodes
    Q = np.asarray(scene.observed_points()).reshape(n_nodes, 3)
    slots = _pixel_slots(scene, Q) if data_term == "pixel" else _triplet_slots(scene)
    slot_node, slot_y, slot_w, slot_nvar, fix_feat, vs, var_nodes, var_pos = slots

    slot_ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(np.bincount(slot_node, minlength=n_nodes), out=slot_ptr[1:])
    if np.any(np.diff(slot_ptr) > 8):
        raise ValueError("a node has more than 8 data-term slots; the kernel supports 8")
    var_ptr, var_feat = _variable_features(scene, Q, slot_node[vs], var_nodes, var_pos,
                                           progress)
    return DataTables(
        nodes=np.arange(n_nodes, dtype=np.int64), slot_ptr=slot_ptr, slot_y=slot_y,
        slot_w=slot_w, slot_nvar=slot_nvar, fix_feat=fix_feat, var_ptr=var_ptr,
        var_feat=var_feat, n_labels=scene.n_labels, data_term=data_term)


def energies_reference(tables: DataTables, coef: np.ndarray, sigma_b: float) -> np.ndarray:
    """Data energies ``U^A`` (N, n, B) by plain numpy, for tests on tiny lattices."""
    coef = np.asarray(coef, dtype=np.float64)
    N, n, B = coef.shape[0], tables.n_nodes, tables.n_labels
    fix = reflectance.radiance(coef, tables.fix_feat.T)  # (N, n_slots)
    var = reflectance.radiance(coef, tables.var_feat.T)  # (N, n_entries)
    out = np.zeros((N, n, B))
    for i in range(n):
        s0, s1 = tables.slot_ptr[i], tables.slot_ptr[i + 1]
        for s in range(B):
            e = tables.var_ptr[i] + s
            for j in range(s0, s1):
                pred = fix[:, j].copy()
                for _ in range(tables.slot_nvar[j]):
                    pred += var[:, e]
                    e += B
                out[:, i, s] += np.abs(tables.slot_y[j] - tables.slot_w[j] * pred) / sigma_b
    return out
