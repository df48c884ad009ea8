"""The lean pseudolikelihood kernel: one fused particle loop per (node, label), fixed template.

Same per-node terms as :mod:`mrfpe.targets.kernels` (``a * (-E_i(x_i)) + b *
log sum_s exp(-E_i(s))``), with the pixel data term's structure baked in:

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
  four), so the tables do not depend on ``sigma_b`` or the unary energies and are
  cached on the :class:`~mrfpe.targets.energy.DataTables` they come from.
* **exp.** :func:`exp2_32` / :func:`exp2_64`: ``2^x`` by rounding ``x`` with the
  1.5 * 2^23 (2^52) trick and a degree-6 (degree-10) polynomial for ``2^r``,
  ``|r| <= 1/2``; the per-particle exponents are pre-multiplied by log2(e).
  Results below ``2^-100`` (``2^-1000``) are exactly 0: no denormals downstream.

Layout (:class:`LeanTables`): ``rec[i, k, s]`` -- field ``k`` of node ``i`` at label
``s``, labels contiguous so that the labels-as-SIMD kernel loads vectors and the
particles-as-SIMD kernel loads scalars that stay in L1 -- fields ``A_0..A_3``, then
per template triangle ``t = 0..5``: ``wF1, G1`` (and ``wF2, G2`` for the full
form); ``nrec[i, k]``: ``y_0..y_3``, then the two fixed triangles' ``wF1, G1
(, wF2, G2)`` (positions 2 and 3).

Numba compiles these kernels for the host's widest vectors (512-bit with
AVX-512; :func:`mrfpe.threads.configure_vector_width`, called by
:mod:`mrfpe.targets.kernels` before its first ``@njit``, explains the process-wide
setting and its opt-out ``MRFPE_AVX512=0``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

from mrfpe.targets.energy import DataTables
from mrfpe.targets.kernels import _FM, _f32_as_i32, _f64_as_i64, _i32_as_f32, _i64_as_f64, flog

__all__ = ["LOG2E", "LeanTables", "block_size", "exp2_32", "exp2_64", "fexp2", "lean_tables",
           "lean_terms", "lean_terms_labels"]

LOG2E = 1.4426950408889634
_LN2 = 0.6931471805599453
_F32 = np.float32
# 2^r on [-1/2, 1/2], degree 6, near-minimax in relative error (1.9e-9, Lawson's iteration
# on weighted least squares). Degree 5 (7.5e-8) is one FMA cheaper, but its error has a
# sign that persists over the range and so adds up over a lattice: 2.4e-6 relative in
# log_prob at a noise-free maximum, against 1.1e-6 for the classic kernel.
_A0, _A1, _A2 = _F32(1.0000000005541656), _F32(0.6931472057372645), _F32(0.2402264689062739)
_A3, _A4 = _F32(0.055503287769708774), _F32(0.009618488957852861)
_A5, _A6 = _F32(0.001339993121726021), _F32(0.00015345811800001227)
_MAGIC32 = _F32(12582912.0)  # 1.5 * 2^23
_LO32, _HI32, _ZERO32 = _F32(-126.0), _F32(127.0), _F32(-100.0)
# 2^r on [-1/2, 1/2], degree 10: Chebyshev interpolation (near-minimax), relative error 1.1e-15.
_B0, _B1, _B2 = 1.0000000000000004, 0.6931471805599518, 0.24022650695907977
_B3 = 0.055504108664445426
_B4, _B5, _B6 = 0.00961812910829982, 0.0013333558228510879, 0.00015403529656437398
_B7, _B8, _B9, _B10 = (1.5252657855294864e-05, 1.3215796261250824e-06, 1.0208689179691987e-07,
                       7.0180311126213455e-09)
_MAGIC64 = 6755399441055744.0  # 1.5 * 2^52
_LO64, _HI64, _ZERO64 = -1022.0, 1023.0, -1000.0


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def exp2_32(x):
    """``2^x`` for float32, branch-free; exactly 0 below ``2^-100`` (relative error 2e-7)."""
    xc = min(max(x, _LO32), _HI32)
    t = xc + _MAGIC32
    k = t - _MAGIC32  # round(xc); no 'reassoc' flag, so LLVM keeps the trick
    r = xc - k
    p = _A6
    p = p * r + _A5
    p = p * r + _A4
    p = p * r + _A3
    p = p * r + _A2
    p = p * r + _A1
    p = p * r + _A0
    y = p * _i32_as_f32((_f32_as_i32(t) + np.int32(127)) << np.int32(23))
    return y * _F32(x >= _ZERO32)


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def exp2_64(x):
    """``2^x`` for float64, branch-free; exactly 0 below ``2^-1000`` (relative error 1.2e-15)."""
    xc = min(max(x, _LO64), _HI64)
    t = xc + _MAGIC64
    k = t - _MAGIC64
    r = xc - k
    p = _B10
    p = p * r + _B9
    p = p * r + _B8
    p = p * r + _B7
    p = p * r + _B6
    p = p * r + _B5
    p = p * r + _B4
    p = p * r + _B3
    p = p * r + _B2
    p = p * r + _B1
    p = p * r + _B0
    y = p * _i64_as_f64((_f64_as_i64(t) + 1023) << 52)
    return y * np.float64(x >= _ZERO64)


def fexp2(x):  # pragma: no cover - replaced by the overload inside jitted code
    """``2^x`` for the argument's precision (:func:`exp2_32` or :func:`exp2_64`)."""
    return np.exp2(x)



@overload(fexp2, inline="always")
def _ol_fexp2(x):
    if x == types.float32:
        return lambda x: exp2_32(x)
    return lambda x: exp2_64(x)


# -- tables ---------------------------------------------------------------------------------

#: Positions (slots) per node and variable triangles of the template.
N_POS, N_TRI = 4, 6
_POS_TRI = ((0, 1), (2, 3), (4,), (5,))  # template triangles of each position


@dataclass(frozen=True)
class LeanTables:
    """Template tables of a set of nodes (module docstring). ``full``: F2/G2 fields present."""

    rec: np.ndarray   # (n, 4 + 6 * nf, B)
    nrec: np.ndarray  # (n, 4 + 2 * nf)
    full: bool

    @property
    def nbytes(self) -> int:
        return int(self.rec.nbytes + self.nrec.nbytes)


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
        return LeanTables(rec.astype(ft), nrec.astype(ft), full)
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
    return LeanTables(np.ascontiguousarray(rec.astype(ft)), np.ascontiguousarray(nrec.astype(ft)),
                      full)


def lean_tables(t: DataTables, full: bool) -> LeanTables | None:
    """The template tables of ``t`` (built once and kept on ``t``), None if they do not fit."""
    key = "_lean_full" if full else "_lean"
    cache = t.__dict__
    if key not in cache:
        object.__setattr__(t, key, _pack(t, full))  # frozen dataclass: tables never change
    return cache[key]


def block_size(n: int, n_labels: int, itemsize: int) -> int:
    """Particles per block of the lean kernel: longer than the classic kernel's (fewer loop
    set-ups per vector), with the block's (labels x particles) energies within 16 KiB of L1."""
    cap = max(64, min(256, (16384 // max(1, n_labels * itemsize)) // 16 * 16))
    n_blocks = -(-max(int(n), 1) // cap)
    per = -(-max(int(n), 1) // n_blocks)
    return int(-(-per // 16) * 16)


# -- kernels --------------------------------------------------------------------------------


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def lean_terms(coef, bl, full, rec, nrec, unary, obs, inv_sigma, chunk_ptr, a, b,
               do_lse, out_chunk, out_node, per_node):  # pragma: no cover - compiled
    """Per-node terms with a block of ``bl`` particles as the SIMD lanes.

    Parameters
    ----------
    coef : (5, Npad) float32 or float64
        ``(c0, c1, c2, e1 log2e, e2 log2e)`` per particle; its dtype is the
        kernel's precision (``rec``, ``nrec``, ``unary``, ``inv_sigma``, ``a``,
        ``b`` share it). Node terms are accumulated in float64.
    bl : int
        Particles per block; ``Npad`` is a multiple of it.
    full : bool
        Whether the F2/G2 fields are present (not Lambertian or Ward).
    rec, nrec : template tables (:class:`LeanTables`).
    unary : (n, B)
        Theta-independent energies times log2(e): the kernel works in log2 units, so
        the label log-sum-exp needs no multiply and loses no accuracy to one.
    obs : (n,) int64
    inv_sigma : ``log2(e) / sigma_b``.
    chunk_ptr, a, b, do_lse, out_chunk, out_node, per_node
        As :func:`mrfpe.targets.kernels.pl_terms`.
    """
    n_chunks = chunk_ptr.shape[0] - 1
    npad = coef.shape[1]
    af = float(a)  # the node terms are combined in float64
    bf = float(b)
    nblk = npad // bl
    B = unary.shape[1]
    for c in prange(n_chunks):
        buf = np.empty((B, bl), dtype=coef.dtype)
        fa1 = np.empty(bl, dtype=coef.dtype)
        fa2 = np.empty(bl, dtype=coef.dtype)
        fb1 = np.empty(bl, dtype=coef.dtype)
        fb2 = np.empty(bl, dtype=coef.dtype)
        mn = np.empty(bl, dtype=coef.dtype)
        ssum = np.empty(bl, dtype=coef.dtype)
        acc = np.empty(bl)
        for blk in range(nblk):
            q0 = blk * bl
            c0 = coef[0, q0:q0 + bl]
            c1 = coef[1, q0:q0 + bl]
            c2 = coef[2, q0:q0 + bl]
            e1 = coef[3, q0:q0 + bl]
            e2 = coef[4, q0:q0 + bl]
            for p in range(bl):
                acc[p] = 0.0
            for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                y0 = nrec[i, 0]
                y1 = nrec[i, 1]
                y2 = nrec[i, 2]
                y3 = nrec[i, 3]
                r = rec[i]
                if full:
                    ha1 = nrec[i, 4]
                    ga1 = nrec[i, 5]
                    ha2 = nrec[i, 6]
                    ga2 = nrec[i, 7]
                    hb1 = nrec[i, 8]
                    gb1 = nrec[i, 9]
                    hb2 = nrec[i, 10]
                    gb2 = nrec[i, 11]
                    for p in range(bl):  # fixed triangles: once per node, not per label
                        xa = fexp2(e1[p] * ga1 + e2[p] * ga2)
                        xb = fexp2(e1[p] * gb1 + e2[p] * gb2)
                        fa1[p] = ha1 * xa
                        fa2[p] = ha2 * xa
                        fb1[p] = hb1 * xb
                        fb2[p] = hb2 * xb
                    for s in range(B):
                        u = unary[i, s]
                        a0 = r[0, s]
                        a1 = r[1, s]
                        a2 = r[2, s]
                        a3 = r[3, s]
                        f01, g01, f02, g02 = r[4, s], r[5, s], r[6, s], r[7, s]
                        f11, g11, f12, g12 = r[8, s], r[9, s], r[10, s], r[11, s]
                        f21, g21, f22, g22 = r[12, s], r[13, s], r[14, s], r[15, s]
                        f31, g31, f32, g32 = r[16, s], r[17, s], r[18, s], r[19, s]
                        f41, g41, f42, g42 = r[20, s], r[21, s], r[22, s], r[23, s]
                        f51, g51, f52, g52 = r[24, s], r[25, s], r[26, s], r[27, s]
                        bs = buf[s]
                        for p in range(bl):
                            E1 = e1[p]
                            E2 = e2[p]
                            x0 = fexp2(E1 * g01 + E2 * g02)
                            x1 = fexp2(E1 * g11 + E2 * g12)
                            x2 = fexp2(E1 * g21 + E2 * g22)
                            x3 = fexp2(E1 * g31 + E2 * g32)
                            x4 = fexp2(E1 * g41 + E2 * g42)
                            x5 = fexp2(E1 * g51 + E2 * g52)
                            C0 = c0[p]
                            C1 = c1[p]
                            C2 = c2[p]
                            d = abs(y0 - C0 * a0 - C1 * (f01 * x0 + f11 * x1)
                                    - C2 * (f02 * x0 + f12 * x1))
                            d += abs(y1 - C0 * a1 - C1 * (f21 * x2 + f31 * x3)
                                     - C2 * (f22 * x2 + f32 * x3))
                            d += abs(y2 - C0 * a2 - C1 * (fa1[p] + f41 * x4)
                                     - C2 * (fa2[p] + f42 * x4))
                            d += abs(y3 - C0 * a3 - C1 * (fb1[p] + f51 * x5)
                                     - C2 * (fb2[p] + f52 * x5))
                            bs[p] = u + inv_sigma * d
                else:
                    ha1 = nrec[i, 4]
                    ga1 = nrec[i, 5]
                    hb1 = nrec[i, 6]
                    gb1 = nrec[i, 7]
                    for p in range(bl):
                        fa1[p] = ha1 * fexp2(e1[p] * ga1)
                        fb1[p] = hb1 * fexp2(e1[p] * gb1)
                    for s in range(B):
                        u = unary[i, s]
                        a0 = r[0, s]
                        a1 = r[1, s]
                        a2 = r[2, s]
                        a3 = r[3, s]
                        f0, g0, f1, g1 = r[4, s], r[5, s], r[6, s], r[7, s]
                        f2, g2, f3, g3 = r[8, s], r[9, s], r[10, s], r[11, s]
                        f4, g4, f5, g5 = r[12, s], r[13, s], r[14, s], r[15, s]
                        bs = buf[s]
                        for p in range(bl):
                            E1 = e1[p]
                            C0 = c0[p]
                            C1 = c1[p]
                            d = abs(y0 - C0 * a0 - C1 * (f0 * fexp2(E1 * g0) + f1 * fexp2(E1 * g1)))
                            d += abs(y1 - C0 * a1
                                     - C1 * (f2 * fexp2(E1 * g2) + f3 * fexp2(E1 * g3)))
                            d += abs(y2 - C0 * a2 - C1 * (fa1[p] + f4 * fexp2(E1 * g4)))
                            d += abs(y3 - C0 * a3 - C1 * (fb1[p] + f5 * fexp2(E1 * g5)))
                            bs[p] = u + inv_sigma * d
                bo = buf[obs[i]]
                if do_lse:
                    for p in range(bl):
                        mn[p] = buf[0, p]
                        ssum[p] = 0
                    for s in range(1, B):
                        bs = buf[s]
                        for p in range(bl):
                            mn[p] = min(mn[p], bs[p])
                    for s in range(B):
                        bs = buf[s]
                        for p in range(bl):
                            ssum[p] += fexp2(mn[p] - bs[p])  # energies in log2 units
                    if per_node:
                        for p in range(bl):
                            out_node[i, q0 + p] = _LN2 * (af * -float(bo[p]) - bf * float(
                                mn[p])) + bf * float(flog(ssum[p]))
                    else:
                        for p in range(bl):
                            acc[p] += _LN2 * (af * -float(bo[p]) - bf * float(mn[p])) + bf * float(
                                flog(ssum[p]))
                elif per_node:
                    for p in range(bl):
                        out_node[i, q0 + p] = _LN2 * (af * -float(bo[p]))
                else:
                    for p in range(bl):
                        acc[p] += _LN2 * (af * -float(bo[p]))
            if not per_node:
                for p in range(bl):
                    out_chunk[c, q0 + p] = acc[p]


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def lean_terms_labels(coef, full, rec, nrec, unary, obs, inv_sigma, chunk_ptr, a, b,
                      do_lse, out_chunk, out_node, per_node):  # pragma: no cover - compiled
    """As :func:`lean_terms` with a node's labels as the SIMD lanes (a few particles).

    ``coef`` is (5, N) without padding. Same formula and order of operations per
    (particle, node, label) as :func:`lean_terms`.
    """
    n_chunks = chunk_ptr.shape[0] - 1
    N = coef.shape[1]
    af = float(a)  # the node terms are combined in float64
    bf = float(b)
    B = unary.shape[1]
    zero = coef[0, 0] * 0
    for c in prange(n_chunks):
        en = np.empty(B, dtype=coef.dtype)
        tmp = np.empty(B, dtype=coef.dtype)
        for q in range(N):
            C0 = coef[0, q]
            C1 = coef[1, q]
            C2 = coef[2, q]
            E1 = coef[3, q]
            E2 = coef[4, q]
            acc = 0.0
            for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                y0 = nrec[i, 0]
                y1 = nrec[i, 1]
                y2 = nrec[i, 2]
                y3 = nrec[i, 3]
                r = rec[i]
                ui = unary[i]
                if full:
                    xa = fexp2(E1 * nrec[i, 5] + E2 * nrec[i, 7])
                    xb = fexp2(E1 * nrec[i, 9] + E2 * nrec[i, 11])
                    fa1 = nrec[i, 4] * xa
                    fa2 = nrec[i, 6] * xa
                    fb1 = nrec[i, 8] * xb
                    fb2 = nrec[i, 10] * xb
                    for s in range(B):
                        x0 = fexp2(E1 * r[5, s] + E2 * r[7, s])
                        x1 = fexp2(E1 * r[9, s] + E2 * r[11, s])
                        x2 = fexp2(E1 * r[13, s] + E2 * r[15, s])
                        x3 = fexp2(E1 * r[17, s] + E2 * r[19, s])
                        x4 = fexp2(E1 * r[21, s] + E2 * r[23, s])
                        x5 = fexp2(E1 * r[25, s] + E2 * r[27, s])
                        d = abs(y0 - C0 * r[0, s] - C1 * (r[4, s] * x0 + r[8, s] * x1)
                                - C2 * (r[6, s] * x0 + r[10, s] * x1))
                        d += abs(y1 - C0 * r[1, s] - C1 * (r[12, s] * x2 + r[16, s] * x3)
                                 - C2 * (r[14, s] * x2 + r[18, s] * x3))
                        d += abs(y2 - C0 * r[2, s] - C1 * (fa1 + r[20, s] * x4)
                                 - C2 * (fa2 + r[22, s] * x4))
                        d += abs(y3 - C0 * r[3, s] - C1 * (fb1 + r[24, s] * x5)
                                 - C2 * (fb2 + r[26, s] * x5))
                        en[s] = ui[s] + inv_sigma * d
                else:
                    fa1 = nrec[i, 4] * fexp2(E1 * nrec[i, 5])
                    fb1 = nrec[i, 6] * fexp2(E1 * nrec[i, 7])
                    for s in range(B):
                        d = abs(y0 - C0 * r[0, s] - C1 * (r[4, s] * fexp2(E1 * r[5, s])
                                                          + r[6, s] * fexp2(E1 * r[7, s])))
                        d += abs(y1 - C0 * r[1, s] - C1 * (r[8, s] * fexp2(E1 * r[9, s])
                                                           + r[10, s] * fexp2(E1 * r[11, s])))
                        d += abs(y2 - C0 * r[2, s] - C1 * (fa1 + r[12, s] * fexp2(E1 * r[13, s])))
                        d += abs(y3 - C0 * r[3, s] - C1 * (fb1 + r[14, s] * fexp2(E1 * r[15, s])))
                        en[s] = ui[s] + inv_sigma * d
                eo = en[obs[i]]
                if do_lse:
                    m = en[0]
                    for s in range(1, B):
                        m = min(m, en[s])
                    for s in range(B):
                        tmp[s] = fexp2(m - en[s])
                    ssum = zero
                    for s in range(B):
                        ssum += tmp[s]
                    val = _LN2 * (af * -float(eo) - bf * float(m)) + bf * float(flog(ssum))
                else:
                    val = _LN2 * (af * -float(eo))
                if per_node:
                    out_node[i, q] = val
                else:
                    acc += val
            if not per_node:
                out_chunk[c, q] = acc
