"""The Jacobian kernel: per-node terms and their derivatives in the coefficients, one pass.

For one particle (or K, one after another) the pass gives every node's term
``l_i`` and its derivatives with respect to the five separable-form coefficients
``c = (c0, c1, c2, e1, e2)``:

    ``dl_i/dc = -a dE_i(x_i)/dc - b sum_s p_i(s) dE_i(s)/dc``, ``p_i = softmax(-E_i)``,
    ``dE_i(s)/dc = (1/sigma_b) sum_slots sign(t) dt/dc``, ``t = y - c0 A - c1 S1 - c2 S2``,

with ``dt/dc0 = -A``, ``dt/dc1 = -S1``, ``dt/dc2 = -S2`` and ``dt/de_k = -sum_tri (c1 wF1 +
c2 wF2) X G_k`` (``X`` a triangle's exponential). The L1 data energy has a kink
where ``t = 0``; there the one-sided derivative of the sign taken is used
(forward differences straddle it the same way).

The chain to the unit-cube parameters is :mod:`mrfpe.brdf.targets.jacobian`'s. The
label loops are split so that each has at most four store streams: with five or
more (beside ~20 load streams) LLVM left the loop scalar, 2.6x slower for Ward
(measured on numba 0.68; see docs/targets.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.brdf.engine.lean_nodes import NODE_BLOCK
from mrfpe.brdf.engine.slots import (
    energy,
    exps_ward,
    label_rows_full,
    label_rows_ward,
    residuals_full,
    residuals_ward,
)
from mrfpe.fastmath import FASTMATH, LN2, exp2_64

__all__ = ["grad_nodes"]


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def _sgn(t):
    """The sign of ``t`` as a float (0 at 0)."""
    return (t > 0) * 1.0 - (t < 0) * 1.0


@njit(parallel=True, fastmath=FASTMATH, error_model="numpy", cache=True)
def grad_nodes(coef, full, iso, recT, nrecT, unaryT, obs, inv_sigma, n, a, b,
               out_val, out_grad):  # pragma: no cover - compiled
    """Node terms ``out_val`` (K, n) and ``dl/dc`` ``out_grad`` (K, n, 5) of K particles.

    ``iso``: :attr:`~mrfpe.brdf.engine.template.LeanTables.isotropic` (every ``G2 = 0``), where
    ``dl/de2`` is 0 whatever ``e2`` and the ``G2`` rows are not read (the same numbers, up
    to the sign of that zero).

    Blocks of ``NODE_BLOCK`` nodes are the SIMD lanes, on the node-major tables
    (:class:`~mrfpe.brdf.engine.template.LeanTables`), as in
    :func:`~mrfpe.brdf.engine.lean_nodes.lean_terms_nodes` for the values, so the loops do not
    depend on the label count; ``unaryT`` and ``inv_sigma`` in log2 units, ``coef``
    (5, K) float64 with ``e1, e2`` times log2 e; float64 whatever the tables' precision.
    Each block runs its particles one after another, so a block's tables are read from
    memory once for all K (from L2 after the first), and every particle's numbers are
    the same whatever K.
    Rows are bound as 1-D slices indexed from 0 (unit strides, no negative-index
    wraparound), so numba's code loads vectors, not gathers. The slot residuals and
    energies are :mod:`mrfpe.brdf.engine.slots`', the same code as the values kernel's.
    """
    B = unaryT.shape[0]
    K = coef.shape[1]
    af = float(a)
    bf = float(b)
    isg = float(inv_sigma)
    isn = -isg * LN2  # -1 / sigma_b: derivatives in natural units
    NB = NODE_BLOCK
    for blk in prange(-(-n // NB)):
        i0 = blk * NB
        i1 = min(i0 + NB, n)
        m = i1 - i0
        sl = slice(i0, i1)
        en = np.empty((B, NB))
        g = np.empty((5, B, NB))
        mn = np.empty(NB)
        tot = np.empty(NB)
        acc = np.empty(NB)
        eo = np.empty(NB)
        ha1, ha2, hb1, hb2 = np.empty(NB), np.empty(NB), np.empty(NB), np.empty(NB)
        wa1, wa2, wb1, wb2 = np.empty(NB), np.empty(NB), np.empty(NB), np.empty(NB)
        y0, y1, y2, y3 = nrecT[0, sl], nrecT[1, sl], nrecT[2, sl], nrecT[3, sl]
        # LLVM vectorised these loops only with at most four store streams each (module
        # docstring), so the full form's label loop is split in four:
        # the exponentials in two halves, then the energy with dE/dc0..c2, then dE/de1, e2.
        for q in range(K):  # the block's tables stay in L2 across the particles
            C0, C1, C2, E1, E2 = coef[0, q], coef[1, q], coef[2, q], coef[3, q], coef[4, q]
            if full:
                na1, nga1, na2, nga2 = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
                nb1, ngb1, nb2, ngb2 = nrecT[8, sl], nrecT[9, sl], nrecT[10, sl], nrecT[11, sl]
                for j in range(m):
                    xa = exp2_64(E1 * nga1[j] + E2 * nga2[j])
                    ha1[j], ha2[j] = na1[j] * xa, na2[j] * xa
                for j in range(m):
                    xb = exp2_64(E1 * ngb1[j] + E2 * ngb2[j])
                    hb1[j], hb2[j] = nb1[j] * xb, nb2[j] * xb
                for j in range(m):
                    qa = C1 * ha1[j] + C2 * ha2[j]
                    qb = C1 * hb1[j] + C2 * hb2[j]
                    wa1[j], wa2[j] = qa * nga1[j], qa * nga2[j]
                    wb1[j], wb2[j] = qb * ngb1[j], qb * ngb2[j]
                xs = np.empty((6, NB))  # one label's triangle exponentials
                x0, x1, x2, x3, x4, x5 = xs[0], xs[1], xs[2], xs[3], xs[4], xs[5]
                for s in range(B):
                    r = label_rows_full(recT, unaryT, s, sl)
                    es, g0s, g1s, g2s, g3s, g4s = en[s], g[0, s], g[1, s], g[2, s], g[3, s], g[4, s]
                    if iso:  # E1 G1 + 0 G2 is E1 G1 exactly: the G2 rows stay unread
                        for j in range(m):
                            x0[j] = exp2_64(E1 * r.g01[j])
                            x1[j] = exp2_64(E1 * r.g11[j])
                            x2[j] = exp2_64(E1 * r.g21[j])
                        for j in range(m):
                            x3[j] = exp2_64(E1 * r.g31[j])
                            x4[j] = exp2_64(E1 * r.g41[j])
                            x5[j] = exp2_64(E1 * r.g51[j])
                    else:
                        for j in range(m):
                            x0[j] = exp2_64(E1 * r.g01[j] + E2 * r.g02[j])
                            x1[j] = exp2_64(E1 * r.g11[j] + E2 * r.g12[j])
                            x2[j] = exp2_64(E1 * r.g21[j] + E2 * r.g22[j])
                        for j in range(m):
                            x3[j] = exp2_64(E1 * r.g31[j] + E2 * r.g32[j])
                            x4[j] = exp2_64(E1 * r.g41[j] + E2 * r.g42[j])
                            x5[j] = exp2_64(E1 * r.g51[j] + E2 * r.g52[j])
                    for j in range(m):
                        s10 = r.f01[j] * x0[j] + r.f11[j] * x1[j]
                        s20 = r.f02[j] * x0[j] + r.f12[j] * x1[j]
                        s11 = r.f21[j] * x2[j] + r.f31[j] * x3[j]
                        s21 = r.f22[j] * x2[j] + r.f32[j] * x3[j]
                        s12 = ha1[j] + r.f41[j] * x4[j]
                        s22 = ha2[j] + r.f42[j] * x4[j]
                        s13 = hb1[j] + r.f51[j] * x5[j]
                        s23 = hb2[j] + r.f52[j] * x5[j]
                        t0 = y0[j] - C0 * r.a0[j] - C1 * s10 - C2 * s20
                        t1 = y1[j] - C0 * r.a1[j] - C1 * s11 - C2 * s21
                        t2 = y2[j] - C0 * r.a2[j] - C1 * s12 - C2 * s22
                        t3 = y3[j] - C0 * r.a3[j] - C1 * s13 - C2 * s23
                        k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                        es[j] = energy(r.u[j], isg, (t0, t1, t2, t3))
                        g0s[j] = isn * (k0 * r.a0[j] + k1 * r.a1[j] + k2 * r.a2[j] + k3 * r.a3[j])
                        g1s[j] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                        g2s[j] = isn * (k0 * s20 + k1 * s21 + k2 * s22 + k3 * s23)
                    # dE/de1 without the G2 rows; dE/de2 = 0 (below). Two loops on purpose: one
                    # loop with ``if not iso`` around g4s gives the same bits but LLVM does not
                    # unswitch it, and the isotropic Jacobian is ~1.5x slower (Phong, 60x60).
                    if iso:
                        for j in range(m):
                            q0 = (C1 * r.f01[j] + C2 * r.f02[j]) * x0[j]
                            q1 = (C1 * r.f11[j] + C2 * r.f12[j]) * x1[j]
                            q2 = (C1 * r.f21[j] + C2 * r.f22[j]) * x2[j]
                            q3 = (C1 * r.f31[j] + C2 * r.f32[j]) * x3[j]
                            q4 = (C1 * r.f41[j] + C2 * r.f42[j]) * x4[j]
                            q5 = (C1 * r.f51[j] + C2 * r.f52[j]) * x5[j]
                            t0, t1, t2, t3 = residuals_full(
                                r, j, C0, C1, C2, (x0[j], x1[j], x2[j], x3[j], x4[j], x5[j]),
                                (ha1[j], ha2[j], hb1[j], hb2[j]), (y0[j], y1[j], y2[j], y3[j]))
                            k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                            g3s[j] = isn * (k0 * (q0 * r.g01[j] + q1 * r.g11[j])
                                            + k1 * (q2 * r.g21[j] + q3 * r.g31[j])
                                            + k2 * (wa1[j] + q4 * r.g41[j])
                                            + k3 * (wb1[j] + q5 * r.g51[j]))
                        continue
                    for j in range(m):
                        q0 = (C1 * r.f01[j] + C2 * r.f02[j]) * x0[j]
                        q1 = (C1 * r.f11[j] + C2 * r.f12[j]) * x1[j]
                        q2 = (C1 * r.f21[j] + C2 * r.f22[j]) * x2[j]
                        q3 = (C1 * r.f31[j] + C2 * r.f32[j]) * x3[j]
                        q4 = (C1 * r.f41[j] + C2 * r.f42[j]) * x4[j]
                        q5 = (C1 * r.f51[j] + C2 * r.f52[j]) * x5[j]
                        t0, t1, t2, t3 = residuals_full(
                            r, j, C0, C1, C2, (x0[j], x1[j], x2[j], x3[j], x4[j], x5[j]),
                            (ha1[j], ha2[j], hb1[j], hb2[j]), (y0[j], y1[j], y2[j], y3[j]))
                        k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                        g3s[j] = isn * (k0 * (q0 * r.g01[j] + q1 * r.g11[j])
                                        + k1 * (q2 * r.g21[j] + q3 * r.g31[j])
                                        + k2 * (wa1[j] + q4 * r.g41[j])
                                        + k3 * (wb1[j] + q5 * r.g51[j]))
                        g4s[j] = isn * (k0 * (q0 * r.g02[j] + q1 * r.g12[j])
                                        + k1 * (q2 * r.g22[j] + q3 * r.g32[j])
                                        + k2 * (wa2[j] + q4 * r.g42[j])
                                        + k3 * (wb2[j] + q5 * r.g52[j]))
            else:
                na, nga, nb, ngb = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
                for j in range(m):
                    ha1[j] = exp2_64(E1 * nga[j] + na[j])  # the Ward tables hold log2 wF1
                    hb1[j] = exp2_64(E1 * ngb[j] + nb[j])
                    wa1[j] = ha1[j] * nga[j]
                    wb1[j] = hb1[j] * ngb[j]
                for s in range(B):
                    r = label_rows_ward(recT, unaryT, s, sl)
                    es, g0s, g1s, g3s = en[s], g[0, s], g[1, s], g[3, s]  # dE/dc2, e2 = 0
                    for j in range(m):
                        p0, p1, p2, p3, p4, p5 = exps_ward(r, j, E1)
                        s10 = p0 + p1
                        s11 = p2 + p3
                        s12 = ha1[j] + p4
                        s13 = hb1[j] + p5
                        t0, t1, t2, t3 = residuals_ward(r, j, C0, C1, (p0, p1, p2, p3, p4, p5),
                                                        (ha1[j], hb1[j]),
                                                        (y0[j], y1[j], y2[j], y3[j]))
                        k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                        es[j] = energy(r.u[j], isg, (t0, t1, t2, t3))
                        g0s[j] = isn * (k0 * r.a0[j] + k1 * r.a1[j] + k2 * r.a2[j] + k3 * r.a3[j])
                        g1s[j] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                        g3s[j] = isn * C1 * (k0 * (p0 * r.g0[j] + p1 * r.g1[j])
                                             + k1 * (p2 * r.g2[j] + p3 * r.g3[j])
                                             + k2 * (wa1[j] + p4 * r.g4[j])
                                             + k3 * (wb1[j] + p5 * r.g5[j]))
            for j in range(m):
                mn[j] = en[0, j]
                tot[j] = 0.0
                eo[j] = en[obs[i0 + j], j]  # before en turns into weights
            for s in range(1, B):
                es = en[s]
                for j in range(m):
                    mn[j] = min(mn[j], es[j])
            for s in range(B):  # en becomes the label weights 2^(m - E): the softmax numerators
                es = en[s]
                for j in range(m):
                    es[j] = exp2_64(mn[j] - es[j])
                    tot[j] += es[j]
            for j in range(m):
                out_val[q, i0 + j] = LN2 * (af * -eo[j] - bf * mn[j]) + bf * np.log(tot[j])
            for k in range(5):
                if (not full and k == 2) or ((not full or iso) and k == 4):
                    for j in range(m):
                        out_grad[q, i0 + j, k] = 0.0
                    continue
                for j in range(m):
                    acc[j] = 0.0
                for s in range(B):
                    es = en[s]
                    gk = g[k, s]
                    for j in range(m):
                        acc[j] += es[j] * gk[j]
                for j in range(m):
                    out_grad[q, i0 + j, k] = -af * g[k, obs[i0 + j], j] - bf * acc[j] / tot[j]
