"""Numba kernels of the pseudolikelihood hot path.

One pass computes, for every node and every particle, the node's energy at
each of its B labels (BRDF + data energy + theta-independent unary), the
energy at the observed label and the log-sum-exp over labels -- fused, without
ever materialising a (particles x nodes x labels x triangles) array.

Layout (prepared by :mod:`mrfpe.targets.energy`):

* per node ``i``: slots ``slot_ptr[i]:slot_ptr[i+1]`` -- one per data-term
  observation (a pixel for the pixel form, a clique for the triplet form) with
  intensity ``slot_y``, weight ``slot_w``, number of label-dependent
  ("variable") triangles ``slot_nvar`` and the features of its fixed triangle
  ``fix_feat[:, slot]`` (all zero if it has none);
* the variable triangles' features, structure-of-arrays ``var_feat[k, e]``,
  for node ``i``, its ``t``-th variable triangle and label ``s`` at
  ``e = var_ptr[i] + t * B + s`` (``nv_i = (var_ptr[i+1] - var_ptr[i]) / B``
  variable triangles per node).

Every triangle's radiance has the separable form (:mod:`mrfpe.targets.reflectance`)

    ``L = c0 F0 + (c1 F1 + c2 F2) exp(e1 G1 + e2 G2)``

with the features ``(F0, F1, F2, G1, G2)`` fixed per triangle and the
coefficients ``(c0, c1, c2, e1, e2)`` fixed per particle.

Two kernels, one formula:

* :func:`pl_terms` (batches): a block of up to ``BLOCK`` particles is the
  innermost, SIMD dimension, so one triangle's features are loaded once and
  reused across the block;
* :func:`pl_terms_labels` (a handful of particles, e.g. one MCMC chain or an
  optimiser's probe): the B labels of a node are the SIMD dimension, so a single
  particle costs no padding.

The exp and log are written so that LLVM vectorises them (numba's libm calls
do not); :func:`fexp` / :func:`flog` pick the float64 or float32 version from
the argument, so each kernel compiles for either precision (float32 is about
twice as fast; per-node terms are still summed in float64).

Node chunks are the parallel (``prange``) dimension; each chunk writes its own
partial sums, added in a fixed order afterwards, so results do not depend on
the number of threads.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic, overload

from mrfpe.threads import configure_vector_width

# numba builds its LLVM target machine at the first @njit decoration of the process:
# choose the vector width before ours (mrfpe.threads explains the choice and opt-out)
configure_vector_width()

__all__ = ["BLOCK", "N_FEATURES", "block_size", "fexp", "flog", "pl_terms", "pl_terms_labels",
           "vexp", "vexp32", "vlog", "vlog32"]

#: Largest number of particles per block (the SIMD dimension of the kernel).
BLOCK = 64
#: Columns of the separable radiance form (F0, F1, F2, G1, G2).
N_FEATURES = 5

# Only value-safe fast-math flags: FMA contraction and ignoring the sign of
# zero. No 'nnan'/'ninf': +inf energies (forbidden labels) must survive.
_FM = {"contract", "nsz"}


def _unary_intrinsic(sig: Any, emit: Any) -> Any:
    """A one-argument numba intrinsic of signature ``sig`` whose LLVM code is
    ``emit(builder, x)`` (bit casts, conversions, LLVM's math intrinsics)."""

    def typer(typingctx: Any, x: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            return emit(builder, args[0])

        return sig, codegen

    return intrinsic(typer)


def _bitcast(ty: Any) -> Any:
    return lambda builder, x: builder.bitcast(x, ty)


# the float bits as an integer and back: the exp/log kernels' exponent arithmetic
_f64_as_i64 = _unary_intrinsic(types.int64(types.float64), _bitcast(ir.IntType(64)))
_i64_as_f64 = _unary_intrinsic(types.float64(types.int64), _bitcast(ir.DoubleType()))
_f32_as_i32 = _unary_intrinsic(types.int32(types.float32), _bitcast(ir.IntType(32)))
_i32_as_f32 = _unary_intrinsic(types.float32(types.int32), _bitcast(ir.FloatType()))


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_MAGIC = 6755399441055744.0  # 1.5 * 2**52: adding it rounds to an integer kept in the low bits
_EXP_LO = -708.0
_EXP_HI = 709.0
# exp(r) = 1 + r + r^2 q(r) on |r| <= ln2/2, q a degree-8 Chebyshev fit of
# (exp(r) - 1 - r) / r^2: relative error 1.3e-15, and exp(0) = 1 exactly.
_Q0 = 0.5000000000000006
_Q1 = 0.16666666666648275
_Q2 = 0.04166666666661234
_Q3 = 0.008333333353731515
_Q4 = 0.001388888892257133
_Q5 = 0.00019841208731181392
_Q6 = 2.4801513441820437e-05
_Q7 = 2.762511659244919e-06
_Q8 = 2.762366872962597e-07


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def vexp(x):
    """``exp(x)`` for float64, branch-free so that loops over it vectorise.

    Cody-Waite reduction ``x = k ln2 + r`` (|r| <= ln2/2) with ``k`` rounded by
    the 1.5*2^52 trick (which also leaves ``k`` in the low bits, from which
    ``2^k`` is assembled), and a degree-10 polynomial for ``exp(r)``. Relative
    error <= 1.5e-15; returns 0 for ``x < -708`` (including ``-inf``) and
    saturates at ``exp(709)``.
    """
    xc = min(max(x, _EXP_LO), _EXP_HI)
    t = xc * _LOG2E + _MAGIC
    k = t - _MAGIC
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = _Q8
    p = p * r + _Q7
    p = p * r + _Q6
    p = p * r + _Q5
    p = p * r + _Q4
    p = p * r + _Q3
    p = p * r + _Q2
    p = p * r + _Q1
    p = p * r + _Q0
    p = p * r + 1.0
    p = p * r + 1.0
    y = p * _i64_as_f64((_f64_as_i64(t) + 1023) << 52)
    return y * np.float64(x >= _EXP_LO)  # arithmetic select: y is finite


_SQRT2 = 1.4142135623730951


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def vlog(x):
    """``log(x)`` for positive normal float64, branch-free (vectorises).

    ``x = m 2^e`` with ``m`` in [sqrt(1/2), sqrt(2)), ``log m = 2 atanh(s)``,
    ``s = (m-1)/(m+1)``, |s| <= 0.172, series to ``s^23`` (< 1e-17).
    Only called on sums of exponentials that are >= 1.
    """
    bits = _f64_as_i64(x)
    e = (bits >> 52) - 1023
    m = _i64_as_f64((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000)
    big = np.float64(m > _SQRT2)  # arithmetic, not a branch: keeps the loop vectorised
    m = m * (1.0 - 0.5 * big)
    ef = np.float64(e) + big
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    q = 1.0 / 23.0
    q = q * s2 + 1.0 / 21.0
    q = q * s2 + 1.0 / 19.0
    q = q * s2 + 1.0 / 17.0
    q = q * s2 + 1.0 / 15.0
    q = q * s2 + 1.0 / 13.0
    q = q * s2 + 1.0 / 11.0
    q = q * s2 + 1.0 / 9.0
    q = q * s2 + 1.0 / 7.0
    q = q * s2 + 1.0 / 5.0
    q = q * s2 + 1.0 / 3.0
    q = q * s2 + 1.0
    return ef * _LN2_HI + (2.0 * s * q + ef * _LN2_LO)


_F32 = np.float32
_LOG2E_32 = _F32(1.4426950408889634)
_LN2_HI_32 = _F32(0.693359375)  # ln 2 = HI + LO, HI with 8 significant bits (Cephes)
_LN2_LO_32 = _F32(-2.12194440e-4)
_MAGIC_32 = _F32(12582912.0)  # 1.5 * 2**23
_EXP_LO_32 = _F32(-87.0)
_EXP_HI_32 = _F32(88.0)
_P0_32, _P1_32, _P2_32 = _F32(1.9875691500e-4), _F32(1.3981999507e-3), _F32(8.3334519073e-3)
_P3_32, _P4_32, _P5_32 = _F32(4.1665795894e-2), _F32(1.6666665459e-1), _F32(5.0000001201e-1)
_ONE_32 = _F32(1.0)
_HALF_32 = _F32(0.5)
_ZERO_32 = _F32(0.0)
_SQRT2_32 = _F32(1.4142135623730951)
_LN2_32 = _F32(0.6931471805599453)


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def vexp32(x):
    """``exp(x)`` for float32 (Cephes ``expf`` polynomial), branch-free; 0 below -87."""
    xc = min(max(x, _EXP_LO_32), _EXP_HI_32)
    t = xc * _LOG2E_32 + _MAGIC_32
    k = t - _MAGIC_32
    r = (xc - k * _LN2_HI_32) - k * _LN2_LO_32
    p = _P0_32
    p = p * r + _P1_32
    p = p * r + _P2_32
    p = p * r + _P3_32
    p = p * r + _P4_32
    p = p * r + _P5_32
    p = p * (r * r) + r + _ONE_32
    y = p * _i32_as_f32((_f32_as_i32(t) + np.int32(127)) << np.int32(23))
    return y * _F32(x >= _EXP_LO_32)  # arithmetic select: y is finite


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def vlog32(x):
    """``log(x)`` for positive normal float32, branch-free (series of 2 atanh(s) to s^11)."""
    bits = _f32_as_i32(x)
    e = (bits >> np.int32(23)) - np.int32(127)
    m = _i32_as_f32((bits & np.int32(0x007FFFFF)) | np.int32(0x3F800000))
    big = _F32(m > _SQRT2_32)
    m = m * (_ONE_32 - _HALF_32 * big)
    ef = _F32(e) + big
    s = (m - _ONE_32) / (m + _ONE_32)
    s2 = s * s
    q = _F32(1.0 / 11.0)
    q = q * s2 + _F32(1.0 / 9.0)
    q = q * s2 + _F32(1.0 / 7.0)
    q = q * s2 + _F32(1.0 / 5.0)
    q = q * s2 + _F32(1.0 / 3.0)
    q = q * s2 + _ONE_32
    return ef * _LN2_32 + _F32(2.0) * s * q


def fexp(x):  # pragma: no cover - replaced by the overload inside jitted code
    """Vectorisable exp for the argument's precision (:func:`vexp` or :func:`vexp32`)."""
    return np.exp(x)


def flog(x):  # pragma: no cover - replaced by the overload inside jitted code
    """Vectorisable log for the argument's precision (:func:`vlog` or :func:`vlog32`)."""
    return np.log(x)


@overload(fexp, inline="always")
def _ol_fexp(x):
    if x == types.float32:
        return lambda x: vexp32(x)
    return lambda x: vexp(x)


@overload(flog, inline="always")
def _ol_flog(x):
    if x == types.float32:
        return lambda x: vlog32(x)
    return lambda x: vlog(x)


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def _add_radiance(out, feat, e, c0, c1, c2, e1, e2, bl, full):
    """``out[p] += L(particle p, triangle e)`` for a block of particles."""
    f0 = feat[0, e]
    f1 = feat[1, e]
    g1 = feat[3, e]
    if full:
        f2 = feat[2, e]
        g2 = feat[4, e]
        for p in range(bl):
            out[p] += c0[p] * f0 + (c1[p] * f1 + c2[p] * f2) * fexp(e1[p] * g1 + e2[p] * g2)
    else:  # lambertian / ward: F2 = G2 = 0
        for p in range(bl):
            out[p] += c0[p] * f0 + c1[p] * f1 * fexp(e1[p] * g1)


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def pl_terms(coef, bl, full, slot_ptr, slot_y, slot_w, slot_nvar, fix_feat, var_ptr, var_feat,
             unary, obs, inv_sigma, chunk_ptr, a, b, do_lse, out_chunk, out_node, per_node):
    """Per-node terms ``a * (-E_i(x_i)) + b * log sum_s exp(-E_i(s))``, particles as SIMD lanes.

    ``E_i(s) = unary[i, s] + sum_slots |y - w * (fixed + variable radiances)| * inv_sigma``.

    Parameters
    ----------
    coef : (5, Npad) float64 or float32
        Separable-form coefficients (c0, c1, c2, e1, e2) per particle. Its dtype
        is the kernel's precision: the tables, ``unary``, ``inv_sigma``, ``a``
        and ``b`` must share it; node sums are accumulated in float64.
    bl : int
        Particles per block (the SIMD dimension); ``Npad`` is a multiple of it.
    full : bool
        Whether the features F2, G2 are used (False for lambertian and ward).
    slot_ptr, slot_y, slot_w, slot_nvar, fix_feat, var_ptr, var_feat
        Data-term tables (module docstring).
    unary : (n_nodes, B) float64
        Theta-independent energies (range prior, beliefs, ...); +inf forbids a label.
    obs : (n_nodes,) int64
        Observed label of each node.
    inv_sigma : float
        ``1 / sigma_b`` of the data energy ``|y - w * prediction| / sigma_b`` (4.12).
    chunk_ptr : (n_chunks + 1,) int64
        Node ranges of the parallel chunks.
    a, b : float
        Weights of ``-E_i(x_i)`` and of the log-sum-exp.
    do_lse : bool
        Whether to compute the log-sum-exp (False when ``b == 0``).
    out_chunk : (n_chunks, Npad) float64
        Sum over each chunk's nodes (written when ``per_node`` is False).
    out_node : (n_nodes, Npad) float64
        Per-node terms (written when ``per_node`` is True).
    """
    n_chunks = chunk_ptr.shape[0] - 1
    npad = coef.shape[1]
    nblk = npad // bl
    B = unary.shape[1]
    for c in prange(n_chunks):
        buf = np.empty((B, bl), dtype=coef.dtype)
        fix = np.empty((8, bl), dtype=coef.dtype)
        pred = np.empty(bl, dtype=coef.dtype)
        mx = np.empty(bl, dtype=coef.dtype)
        ssum = np.empty(bl, dtype=coef.dtype)
        acc = np.empty(bl)
        c0 = np.empty(bl, dtype=coef.dtype)
        c1 = np.empty(bl, dtype=coef.dtype)
        c2 = np.empty(bl, dtype=coef.dtype)
        e1 = np.empty(bl, dtype=coef.dtype)
        e2 = np.empty(bl, dtype=coef.dtype)
        for blk in range(nblk):
            q0 = blk * bl
            for p in range(bl):
                c0[p] = coef[0, q0 + p]
                c1[p] = coef[1, q0 + p]
                c2[p] = coef[2, q0 + p]
                e1[p] = coef[3, q0 + p]
                e2[p] = coef[4, q0 + p]
                acc[p] = 0.0
            for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                s0 = slot_ptr[i]
                ns = slot_ptr[i + 1] - s0
                # Fixed triangles (all corners at observed labels): once per node, not per label.
                for j in range(ns):
                    fj = fix[j]
                    fj[:] = 0
                    _add_radiance(fj, fix_feat, s0 + j, c0, c1, c2, e1, e2, bl, full)
                v0 = var_ptr[i]
                for s in range(B):
                    u = unary[i, s]
                    bs = buf[s]
                    for p in range(bl):
                        bs[p] = u
                    e = v0 + s
                    for j in range(ns):
                        y = slot_y[s0 + j]
                        w = slot_w[s0 + j]
                        fj = fix[j]
                        for p in range(bl):
                            pred[p] = fj[p]
                        for _t in range(slot_nvar[s0 + j]):
                            _add_radiance(pred, var_feat, e, c0, c1, c2, e1, e2, bl, full)
                            e += B
                        for p in range(bl):
                            bs[p] += abs(y - w * pred[p]) * inv_sigma
                bo = buf[obs[i]]
                if do_lse:
                    for p in range(bl):
                        mx[p] = -buf[0, p]
                    ssum[:] = 0
                    for s in range(1, B):
                        bs = buf[s]
                        for p in range(bl):
                            mx[p] = max(mx[p], -bs[p])
                    for s in range(B):
                        bs = buf[s]
                        for p in range(bl):
                            ssum[p] += fexp(-bs[p] - mx[p])
                    for p in range(bl):
                        pred[p] = a * (-bo[p]) + b * (mx[p] + flog(ssum[p]))
                else:
                    for p in range(bl):
                        pred[p] = a * (-bo[p])
                if per_node:
                    for p in range(bl):
                        out_node[i, q0 + p] = pred[p]
                else:
                    for p in range(bl):
                        acc[p] += pred[p]
            if not per_node:
                for p in range(bl):
                    out_chunk[c, q0 + p] = acc[p]


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def pl_terms_labels(coef, full, slot_ptr, slot_y, slot_w, slot_nvar, fix_feat, var_ptr, var_feat,
                    unary, obs, inv_sigma, chunk_ptr, a, b, do_lse, out_chunk, out_node,
                    per_node):
    """As :func:`pl_terms` with a node's labels as SIMD lanes (for a few particles).

    ``coef`` is (5, N) without padding; outputs are (n_chunks, N) / (n_nodes, N).
    Same formula and the same order of operations per (particle, node, label).
    """
    n_chunks = chunk_ptr.shape[0] - 1
    N = coef.shape[1]
    B = unary.shape[1]
    zero = coef[0, 0] * 0
    for c in prange(n_chunks):
        en = np.empty(B, dtype=coef.dtype)
        pred = np.empty(B)
        tmp = np.empty(B, dtype=coef.dtype)
        fix = np.empty(8, dtype=coef.dtype)
        for q in range(N):
            c0 = coef[0, q]
            c1 = coef[1, q]
            c2 = coef[2, q]
            e1 = coef[3, q]
            e2 = coef[4, q]
            acc = 0.0  # float64 whatever the kernel's precision
            for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                s0 = slot_ptr[i]
                ns = slot_ptr[i + 1] - s0
                for j in range(ns):
                    k = s0 + j
                    if full:
                        fix[j] = zero + (c0 * fix_feat[0, k] + (
                            c1 * fix_feat[1, k] + c2 * fix_feat[2, k]) * fexp(
                            e1 * fix_feat[3, k] + e2 * fix_feat[4, k]))
                    else:
                        fix[j] = zero + (c0 * fix_feat[0, k] + c1 * fix_feat[1, k] * fexp(
                            e1 * fix_feat[3, k]))
                for s in range(B):
                    en[s] = unary[i, s]
                e = var_ptr[i]
                for j in range(ns):
                    y = slot_y[s0 + j]
                    w = slot_w[s0 + j]
                    fj = fix[j]
                    for s in range(B):
                        pred[s] = fj
                    for _t in range(slot_nvar[s0 + j]):
                        if full:
                            for s in range(B):
                                pred[s] += c0 * var_feat[0, e + s] + (
                                    c1 * var_feat[1, e + s] + c2 * var_feat[2, e + s]) * fexp(
                                    e1 * var_feat[3, e + s] + e2 * var_feat[4, e + s])
                        else:
                            for s in range(B):
                                pred[s] += c0 * var_feat[0, e + s] + c1 * var_feat[1, e + s] * fexp(
                                    e1 * var_feat[3, e + s])
                        e += B
                    for s in range(B):
                        en[s] += abs(y - w * pred[s]) * inv_sigma
                val = a * (-en[obs[i]])
                if do_lse:
                    mx = -en[0]
                    for s in range(1, B):
                        mx = max(mx, -en[s])
                    for s in range(B):
                        tmp[s] = fexp(-en[s] - mx)
                    ssum = zero
                    for s in range(B):
                        ssum += tmp[s]
                    val = a * (-en[obs[i]]) + b * (mx + flog(ssum))
                if per_node:
                    out_node[i, q] = val
                else:
                    acc += val
            if not per_node:
                out_chunk[c, q] = acc


def block_size(n: int) -> int:
    """Particles per block for a batch of ``n``: a multiple of 8, at most :data:`BLOCK`."""
    n_blocks = -(-max(int(n), 1) // BLOCK)
    per = -(-max(int(n), 1) // n_blocks)
    return int(-(-per // 8) * 8)
