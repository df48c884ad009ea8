"""The template's per-slot formulas, shared by the node-major value and Jacobian kernels.

A node's energy at a label is ``u + (1/sigma_b) sum_k |t_k|`` over its four slots,
with the slot residuals ``t_k = y_k - c0 A_k - c1 S1_k - c2 S2_k``
(:mod:`mrfpe.brdf.engine.template`). :func:`mrfpe.brdf.engine.lean_nodes.lean_terms_nodes`
(values) and :func:`mrfpe.brdf.engine.gradient.grad_nodes` (values and derivatives)
take the exponentials and the residuals from here, so the two compute the same
numbers by the same code; being inlined (``inline="always"``, at numba's IR
level), the helpers give the same machine code and bits as the loops they were
written out in.

A label's rows of a node block come as one named tuple (:class:`FullRows`,
:class:`WardRows`) of 1-D views indexed from 0, so that numba's code knows their
unit stride and loads vectors, not gathers.
"""

from __future__ import annotations

from collections import namedtuple

from numba import njit

from mrfpe.fastmath import FASTMATH, fexp2

__all__ = ["FullRows", "WardRows", "energy", "exps_full", "exps_iso", "exps_ward",
           "label_rows_full", "label_rows_ward", "residuals_full", "residuals_ward"]

#: A label's rows of the full-form node-major tables: the unary energy ``u``, the four
#: slots' albedo terms ``a0..a3`` and, per variable triangle ``t = 0..5``, its two
#: terms' feature ``f_tk`` and exponent ``g_tk``.
FullRows = namedtuple("FullRows", [
    "u", "a0", "a1", "a2", "a3",
    "f01", "g01", "f02", "g02", "f11", "g11", "f12", "g12", "f21", "g21", "f22", "g22",
    "f31", "g31", "f32", "g32", "f41", "g41", "f42", "g42", "f51", "g51", "f52", "g52"])
#: As :data:`FullRows` for the Ward/Lambertian tables: one term per variable triangle, its
#: feature ``f_t`` the log2 of its weight (folded into the exponent).
WardRows = namedtuple("WardRows", [
    "u", "a0", "a1", "a2", "a3",
    "f0", "g0", "f1", "g1", "f2", "g2", "f3", "g3", "f4", "g4", "f5", "g5"])


@njit(inline="always", cache=True)
def label_rows_full(recT, unaryT, s, sl):  # pragma: no cover - compiled
    """Label ``s``'s :class:`FullRows` of node block ``sl`` (``recT``: the node-major
    full-form tables, ``unaryT`` the unary energies, (B, n))."""
    return FullRows(unaryT[s, sl], recT[0, s, sl], recT[1, s, sl], recT[2, s, sl],
                    recT[3, s, sl], recT[4, s, sl], recT[5, s, sl], recT[6, s, sl],
                    recT[7, s, sl], recT[8, s, sl], recT[9, s, sl], recT[10, s, sl],
                    recT[11, s, sl], recT[12, s, sl], recT[13, s, sl], recT[14, s, sl],
                    recT[15, s, sl], recT[16, s, sl], recT[17, s, sl], recT[18, s, sl],
                    recT[19, s, sl], recT[20, s, sl], recT[21, s, sl], recT[22, s, sl],
                    recT[23, s, sl], recT[24, s, sl], recT[25, s, sl], recT[26, s, sl],
                    recT[27, s, sl])


@njit(inline="always", cache=True)
def label_rows_ward(recT, unaryT, s, sl):  # pragma: no cover - compiled
    """As :func:`label_rows_full` for the Ward/Lambertian tables (:class:`WardRows`)."""
    return WardRows(unaryT[s, sl], recT[0, s, sl], recT[1, s, sl], recT[2, s, sl],
                    recT[3, s, sl], recT[4, s, sl], recT[5, s, sl], recT[6, s, sl],
                    recT[7, s, sl], recT[8, s, sl], recT[9, s, sl], recT[10, s, sl],
                    recT[11, s, sl], recT[12, s, sl], recT[13, s, sl], recT[14, s, sl],
                    recT[15, s, sl])


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def exps_full(r, j, E1, E2):  # pragma: no cover - compiled
    """The six variable triangles' ``2^(E1 G1 + E2 G2)`` at node ``j`` of rows ``r``."""
    return (fexp2(E1 * r.g01[j] + E2 * r.g02[j]), fexp2(E1 * r.g11[j] + E2 * r.g12[j]),
            fexp2(E1 * r.g21[j] + E2 * r.g22[j]), fexp2(E1 * r.g31[j] + E2 * r.g32[j]),
            fexp2(E1 * r.g41[j] + E2 * r.g42[j]), fexp2(E1 * r.g51[j] + E2 * r.g52[j]))


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def exps_iso(r, j, E1):  # pragma: no cover - compiled
    """:func:`exps_full` where every ``G2 = 0``: ``2^(E1 G1)``, the G2 rows left unread."""
    return (fexp2(E1 * r.g01[j]), fexp2(E1 * r.g11[j]), fexp2(E1 * r.g21[j]),
            fexp2(E1 * r.g31[j]), fexp2(E1 * r.g41[j]), fexp2(E1 * r.g51[j]))


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def exps_ward(r, j, E1):  # pragma: no cover - compiled
    """The six variable triangles' weighted lobes ``2^(E1 G1 + log2 wF1)`` (Ward form)."""
    return (fexp2(E1 * r.g0[j] + r.f0[j]), fexp2(E1 * r.g1[j] + r.f1[j]),
            fexp2(E1 * r.g2[j] + r.f2[j]), fexp2(E1 * r.g3[j] + r.f3[j]),
            fexp2(E1 * r.g4[j] + r.f4[j]), fexp2(E1 * r.g5[j] + r.f5[j]))


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def residuals_full(r, j, C0, C1, C2, x, h, y):  # pragma: no cover - compiled
    """The four slot residuals ``t_k`` at node ``j`` (full form).

    ``x``: :func:`exps_full`; ``h``: the two fixed triangles' weighted lobes ``(wF1 X,
    wF2 X)`` of slots 2 and 3; ``y``: the four slot intensities.
    """
    x0, x1, x2, x3, x4, x5 = x
    t0 = (y[0] - C0 * r.a0[j] - C1 * (r.f01[j] * x0 + r.f11[j] * x1)
          - C2 * (r.f02[j] * x0 + r.f12[j] * x1))
    t1 = (y[1] - C0 * r.a1[j] - C1 * (r.f21[j] * x2 + r.f31[j] * x3)
          - C2 * (r.f22[j] * x2 + r.f32[j] * x3))
    t2 = y[2] - C0 * r.a2[j] - C1 * (h[0] + r.f41[j] * x4) - C2 * (h[1] + r.f42[j] * x4)
    t3 = y[3] - C0 * r.a3[j] - C1 * (h[2] + r.f51[j] * x5) - C2 * (h[3] + r.f52[j] * x5)
    return t0, t1, t2, t3


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def residuals_ward(r, j, C0, C1, p, h, y):  # pragma: no cover - compiled
    """The four slot residuals at node ``j`` (Ward form; ``p``: :func:`exps_ward`, ``h``:
    the fixed triangles' lobes of slots 2 and 3)."""
    t0 = y[0] - C0 * r.a0[j] - C1 * (p[0] + p[1])
    t1 = y[1] - C0 * r.a1[j] - C1 * (p[2] + p[3])
    t2 = y[2] - C0 * r.a2[j] - C1 * (h[0] + p[4])
    t3 = y[3] - C0 * r.a3[j] - C1 * (h[1] + p[5])
    return t0, t1, t2, t3


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def energy(u, inv_sigma, t):  # pragma: no cover - compiled
    """A label's energy ``u + inv_sigma sum_k |t_k|`` from its slot residuals ``t``."""
    return u + inv_sigma * (abs(t[0]) + abs(t[1]) + abs(t[2]) + abs(t[3]))
