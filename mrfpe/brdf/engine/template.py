"""The lean kernels' template tables: every node's data term in a fixed four-slot layout.

The lean kernels (:mod:`mrfpe.brdf.engine.lean`, :mod:`mrfpe.brdf.engine.lean_nodes`,
:mod:`mrfpe.brdf.engine.gradient`) compute the same per-node terms as the classic ones
(:mod:`mrfpe.brdf.engine.classic`) with the pixel data term's structure baked in:

* **Template.** Every node has four *positions* (slots): positions 0 and 1 hold
  two variable triangles each (the pixels whose TL-BR diagonal passes through
  the node), positions 2 and 3 one variable and one fixed triangle (the other two
  pixels). Boundary nodes get zero-weight positions, whose term is ``|0 - 0|``;
  a slot that does not fit (the triplet form's four single slots) goes to a
  free two-triangle position with its fixed triangle repeated for every label.
  The inner loop over a block of particles is then straight-line code: six
  exponentials, four absolute values, no per-triangle loops, no aliasing checks.
* **Precomputed, once per table.** Per (node, position, label) ``A = w * sum F0``
  of the position's triangles (variable and fixed), per triangle ``w * F1``
  (``w * F2``), so that a slot's prediction is ``c0 A + c1 S1 + c2 S2`` with
  ``S = sum w F exp(...)``: ``c0`` and ``c1`` are factored out of the triangle sums.
  ``1/sigma_b`` multiplies the sum of a label's four slot terms (one FMA, not
  four), so the tables do not depend on ``sigma_b`` or the unary energies: every
  target on one scene shares them (:func:`mrfpe.brdf.targets.tables.lean_tables_for`).
* **Ward form: weights in the exponent.** Where there is no second lobe term
  (Lambertian, Ward) the tables hold ``log2(w F1)`` in place of ``w F1``, so that
  ``w F1 2^(e1 G1) = 2^(e1 G1 + log2(w F1))``: the exponent's multiply becomes an
  FMA and a multiply per triangle goes (a zero weight is ``-inf``, whose ``exp2`` is
  the floor below; a negative one, which no built-in model has, sends the table to
  the classic kernel). :func:`exponent_bound` includes the largest of them.

Layout (:class:`LeanTables`): ``rec[i, k, s]`` -- field ``k`` of node ``i`` at label
``s``, labels contiguous so that the particles-as-SIMD kernel loads scalars that
stay in L1 (``recT``, ``nrecT``: the node-major copies, for a few particles) --
fields ``A_0..A_3``, then per template triangle ``t = 0..5``: ``wF1, G1`` (and
``wF2, G2`` for the full form; ``log2 wF1, G1`` for the Ward form); ``nrec[i, k]``:
``y_0..y_3``, then the two fixed triangles' ``wF1, G1 (, wF2, G2)`` (positions 2 and 3;
``log2 wF1`` likewise).

Both layouts are built once, when a target is built (:func:`lean_tables`), and
are read-only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrfpe.brdf.engine.tables import DataTables, read_only

__all__ = ["N_POS", "N_TRI", "LeanTables", "exponent_bound", "lean_tables"]

#: Positions (slots) per node and variable triangles of the template.
N_POS, N_TRI = 4, 6
_POS_TRI = ((0, 1), (2, 3), (4,), (5,))  # template triangles of each position


@dataclass(frozen=True, eq=False)
class LeanTables:
    """Template tables of a set of nodes (module docstring), read-only.

    Attributes
    ----------
    rec : (n, 4 + 6 nf, B)
        Per (node, field, label), labels contiguous (the particles-as-SIMD kernel).
    nrec : (n, 4 + 2 nf)
        Per (node, field): the slot intensities and the fixed triangles' fields.
    recT, nrecT : (4 + 6 nf, B, n), (4 + 2 nf, n)
        The node-major copies (nodes last), so that a node block's field loads are
        contiguous vectors (:mod:`mrfpe.brdf.engine.lean_nodes`, :mod:`mrfpe.brdf.engine.gradient`).
    full : bool
        F2/G2 fields present (``nf = 4``; else ``nf = 2``).
    g_range : (2, 2)
        Min and max of G1 and G2 over every triangle (0 if absent).
    log_f_max : float
        Ward form: the largest ``log2(wF1)`` in the tables (``-inf`` if none).
    isotropic : bool
        The full form with every ``G2 = 0`` (isotropic Phong): ``E1 G1 + E2 G2`` is
        ``E1 G1`` exactly, so the kernels leave the ``G2`` rows unread.
    """

    rec: np.ndarray
    nrec: np.ndarray
    recT: np.ndarray
    nrecT: np.ndarray
    full: bool
    g_range: np.ndarray
    log_f_max: float
    isotropic: bool

    @property
    def nbytes(self) -> int:
        return int(self.rec.nbytes + self.nrec.nbytes + self.recT.nbytes + self.nrecT.nbytes)


def _lean_tables(rec: np.ndarray, nrec: np.ndarray, full: bool, g_range: np.ndarray,
                 log_f_max: float) -> LeanTables:
    """The read-only :class:`LeanTables` of the packed ``rec``, ``nrec`` and their copies."""
    recT = np.ascontiguousarray(rec.transpose(1, 2, 0))
    nrecT = np.ascontiguousarray(nrec.T)
    return LeanTables(*read_only(rec, nrec, recT, nrecT), full=full, g_range=read_only(g_range)[0],
                      log_f_max=log_f_max, isotropic=bool(full and not np.any(g_range[1])))


def lean_tables(t: DataTables, full: bool) -> LeanTables | None:
    """The template tables of ``t``, or None if a node's slots do not fit the template
    (more than four slots, a slot without a variable triangle or with more than two,
    a negative lobe weight in the Ward form): such tables run the classic kernels."""
    return _pack(t, full)


def _pack(t: DataTables, full: bool) -> LeanTables | None:
    """Template tables of ``t``, or None if a node's slots do not fit the template."""
    n, B = t.n_nodes, t.n_labels
    nf = 4 if full else 2
    ft = t.var_feat.dtype
    rec = np.zeros((n, N_POS + N_TRI * nf, B))
    nrec = np.zeros((n, N_POS + 2 * nf))
    nslot = np.diff(t.slot_ptr)
    nvar = t.slot_nvar
    if nvar.size == 0:
        return _lean_tables(rec.astype(ft), nrec.astype(ft), full, np.zeros((2, 2)), 0.0)
    if nslot.max() > N_POS or nvar.min() < 1 or nvar.max() > 2:
        return None
    node = np.repeat(np.arange(n, dtype=np.int64), nslot)
    start = t.slot_ptr[node]
    dbl = nvar == 2
    cd = np.concatenate([[0], np.cumsum(dbl)])
    cs = np.concatenate([[0], np.cumsum(~dbl)])
    j = np.arange(nvar.size)
    rank_d = cd[j] - cd[start]
    rank_s = cs[j] - cs[start]
    n_d = cd[t.slot_ptr[1:]] - cd[t.slot_ptr[:-1]]
    pos = np.where(dbl, rank_d, np.where(rank_s < 2, 2 + rank_s, n_d[node] + rank_s - 2))
    if np.any(dbl & (rank_d >= 2)) or np.any(pos >= N_POS):
        return None
    cv = np.concatenate([[0], np.cumsum(nvar)])
    tstart = cv[j] - cv[start]
    w = t.slot_w.astype(np.float64)
    labels = np.arange(B)
    feat = t.var_feat.astype(np.float64)
    fix = t.fix_feat.astype(np.float64)
    nrec[node, pos] = t.slot_y
    fields = (1, 3, 2, 4)[:nf]  # wF1, G1, wF2, G2
    scaled = (True, False, True, False)[:nf]
    for k in range(2):
        sel = np.flatnonzero(nvar > k)
        e = t.var_ptr[node[sel]][:, None] + (tstart[sel] + k)[:, None] * B + labels  # (m, B)
        rec[node[sel], pos[sel]] += w[sel, None] * feat[0, e]
        tri = np.where(pos[sel] < 2, 2 * pos[sel] + k, pos[sel] + 2)
        for q, (fld, sc) in enumerate(zip(fields, scaled)):
            v = feat[fld, e]
            rec[node[sel], N_POS + nf * tri + q] = w[sel, None] * v if sc else v
    one = np.flatnonzero(nvar == 1)  # slots with a fixed triangle (zero features if none)
    rec[node[one], pos[one]] += (w[one] * fix[0, one])[:, None]
    in_fixed = one[pos[one] >= 2]
    in_double = one[pos[one] < 2]
    for q, (fld, sc) in enumerate(zip(fields, scaled)):
        v = w * fix[fld] if sc else fix[fld]
        nrec[node[in_fixed], N_POS + nf * (pos[in_fixed] - 2) + q] = v[in_fixed]
        # a single slot in a two-triangle position: its fixed triangle repeated per label
        rec[node[in_double], N_POS + nf * (2 * pos[in_double] + 1) + q] = v[in_double, None]
    log_f_max = 0.0
    if not full:  # fold wF1 into the exponent: wF1 2^(e1 G1) = 2^(e1 G1 + log2 wF1)
        f_rec = rec[:, N_POS:N_POS + N_TRI * nf:nf]  # views: written in place below
        f_nrec = nrec[:, N_POS:N_POS + 2 * nf:nf]
        if min(f_rec.min(initial=0.0), f_nrec.min(initial=0.0)) < 0:
            return None  # a negative lobe weight has no logarithm: the classic kernel
        with np.errstate(divide="ignore"):  # zero weights (padding, Lambertian): -inf
            log_f_max = float(np.log2(max(f_rec.max(initial=0.0), f_nrec.max(initial=0.0))))
            np.log2(f_rec, out=f_rec)
            np.log2(f_nrec, out=f_nrec)
    rec, nrec = rec.astype(ft), nrec.astype(ft)
    g_range = np.zeros((2, 2))
    for q in range(nf // 2):  # the G fields: N_POS + nf * triangle + 2 q + 1 in rec and nrec
        k = N_POS + 2 * q + 1
        g = np.concatenate([rec[:, k::nf].ravel(), nrec[:, k::nf].ravel()])
        g_range[q] = g.min(), g.max()
    return _lean_tables(np.ascontiguousarray(rec), np.ascontiguousarray(nrec), full, g_range,
                        log_f_max)


def exponent_bound(lt: LeanTables, e: np.ndarray) -> float:
    """Largest exponent ``E1 G1 + E2 G2`` (plus ``log2 wF1`` in the Ward form) the kernels
    can meet for the particles' exponent coefficients ``e`` ((N, 2), log2 units):
    :func:`~mrfpe.fastmath.exp2_32` and :func:`~mrfpe.fastmath.exp2_64`
    need it below :data:`~mrfpe.fastmath.HI32` / :data:`~mrfpe.fastmath.HI64`."""
    e = np.asarray(e, dtype=np.float64)
    lo, hi = lt.g_range[:, 0], lt.g_range[:, 1]
    bound = np.max(np.maximum(e * lo, e * hi).sum(axis=1), initial=-np.inf)
    return float(bound if lt.full else bound + lt.log_f_max)
