"""The lean kernel for batches: a block of particles as the SIMD lanes, fixed template.

Same per-node terms as :mod:`mrfpe.brdf.engine.classic` (``a * (-E_i(x_i)) + b *
log sum_s exp(-E_i(s))``) on the template tables of :mod:`mrfpe.brdf.engine.template`:
one fused particle loop per (node, label) -- six exponentials, four absolute
values, no per-triangle loops. The kernel works in log2 units: the per-particle
exponents are pre-multiplied by log2(e) and ``2^x`` is
:func:`mrfpe.fastmath.exp2_32` / :func:`~mrfpe.fastmath.exp2_64`,
which skip the overflow clamp, so :func:`mrfpe.brdf.engine.evaluate` sends particles
whose exponents could exceed 127 (1023) to the classic kernel.

Numba compiles these kernels for the host's widest vectors (512-bit with
AVX-512; :func:`mrfpe.threads.configure_vector_width`, called by
:mod:`mrfpe.brdf.engine` before its first ``@njit``, explains the process-wide
setting and its opt-out ``MRFPE_AVX512=0``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.fastmath import FASTMATH, LN2, fexp2, flog

__all__ = ["BLOCK_BYTES", "BLOCK_MAX", "block_size", "lean_terms"]


#: Bytes of one block's (labels x particles) energy buffer, and the block's largest size.
BLOCK_BYTES, BLOCK_MAX = 131072, 1024


def block_size(n: int, n_labels: int, itemsize: int) -> int:
    """Particles per block of the lean kernel: a multiple of 16, blocks of near-equal size.

    Long blocks amortise each label's loop set-up (its table values broadcast to
    vectors, and spilled: the loop body keeps more constants than there are vector
    registers) over more particles. The block's (labels x particles) energies take up
    to :data:`BLOCK_BYTES` (L2, not L1: measured on Zen 4, 100 x 100, N = 1000, one
    process, alternated, medians of 7, float32 Ward 20 labels 0.91x and 40 labels
    0.83x, Phong 20 labels 0.85x the time of a 16 KiB buffer; float64 0.92x).
    The result does not depend on the block size (each particle's node sums run in
    node order whatever the block).
    """
    cap = max(64, min(BLOCK_MAX, (BLOCK_BYTES // max(1, n_labels * itemsize)) // 16 * 16))
    n_blocks = -(-max(int(n), 1) // cap)
    per = -(-max(int(n), 1) // n_blocks)
    return int(-(-per // 16) * 16)


@njit(parallel=True, fastmath=FASTMATH, error_model="numpy", cache=True)
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
    rec, nrec : template tables (:class:`mrfpe.brdf.engine.template.LeanTables`).
    unary : (n, B)
        Theta-independent energies times log2(e): the kernel works in log2 units, so
        the label log-sum-exp needs no multiply and loses no accuracy to one.
    obs : (n,) int64
    inv_sigma : ``log2(e) / sigma_b``.
    chunk_ptr, a, b, do_lse, out_chunk, out_node, per_node
        As :func:`mrfpe.brdf.engine.classic.classic_terms`.
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
                    for p in range(bl):  # h, f: log2 of the weights (folded)
                        fa1[p] = fexp2(e1[p] * ga1 + ha1)
                        fb1[p] = fexp2(e1[p] * gb1 + hb1)
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
                            d = abs(y0 - C0 * a0 - C1 * (fexp2(E1 * g0 + f0) + fexp2(E1 * g1 + f1)))
                            d += abs(y1 - C0 * a1
                                     - C1 * (fexp2(E1 * g2 + f2) + fexp2(E1 * g3 + f3)))
                            d += abs(y2 - C0 * a2 - C1 * (fa1[p] + fexp2(E1 * g4 + f4)))
                            d += abs(y3 - C0 * a3 - C1 * (fb1[p] + fexp2(E1 * g5 + f5)))
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
                            out_node[i, q0 + p] = LN2 * (af * -float(bo[p]) - bf * float(
                                mn[p])) + bf * float(flog(ssum[p]))
                    else:
                        for p in range(bl):
                            acc[p] += LN2 * (af * -float(bo[p]) - bf * float(mn[p])) + bf * float(
                                flog(ssum[p]))
                elif per_node:
                    for p in range(bl):
                        out_node[i, q0 + p] = LN2 * (af * -float(bo[p]))
                else:
                    for p in range(bl):
                        acc[p] += LN2 * (af * -float(bo[p]))
            if not per_node:
                for p in range(bl):
                    out_chunk[c, q0 + p] = acc[p]
