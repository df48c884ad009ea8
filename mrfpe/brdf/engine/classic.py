"""The classic pseudolikelihood kernels: general CSR loops over any data-term layout.

One pass computes, for every node and every particle, the node's energy at
each of its B labels (BRDF + data energy + theta-independent unary), the
energy at the observed label and the log-sum-exp over labels -- fused, without
ever materialising a (particles x nodes x labels x triangles) array.

Layout (:class:`mrfpe.brdf.engine.tables.DataTables`, built by :mod:`mrfpe.brdf.targets.energy`):

* per node ``i``: slots ``slot_ptr[i]:slot_ptr[i+1]`` -- one per data-term
  observation (a pixel for the pixel form, a clique for the triplet form) with
  intensity ``slot_y``, weight ``slot_w``, number of label-dependent
  ("variable") triangles ``slot_nvar`` and the features of its fixed triangle
  ``fix_feat[:, slot]`` (all zero if it has none);
* the variable triangles' features, structure-of-arrays ``var_feat[k, e]``,
  for node ``i``, its ``t``-th variable triangle and label ``s`` at
  ``e = var_ptr[i] + t * B + s`` (``nv_i = (var_ptr[i+1] - var_ptr[i]) / B``
  variable triangles per node).

Every triangle's radiance has the separable form (:mod:`mrfpe.brdf.targets.reflectance`)

    ``L = c0 F0 + (c1 F1 + c2 F2) exp(e1 G1 + e2 G2)``

with the features ``(F0, F1, F2, G1, G2)`` fixed per triangle and the
coefficients ``(c0, c1, c2, e1, e2)`` fixed per particle.

Two kernels, one formula:

* :func:`classic_terms` (batches): a block of up to ``BLOCK`` particles is the
  innermost, SIMD dimension, so one triangle's features are loaded once and
  reused across the block;
* :func:`classic_terms_labels` (a handful of particles, e.g. one MCMC chain or an
  optimiser's probe): the B labels of a node are the SIMD dimension, so a single
  particle costs no padding.

The exp and log are :mod:`mrfpe.fastmath`'s vectorising ones
(:func:`~mrfpe.fastmath.fexp` / :func:`~mrfpe.fastmath.flog` pick
the float64 or float32 version from the argument, so each kernel compiles for
either precision; float32 is about twice as fast, per-node terms are still
summed in float64).

Node chunks are the parallel (``prange``) dimension; each chunk writes its own
partial sums, added in a fixed order afterwards, so results do not depend on
the number of threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.fastmath import FASTMATH, fexp, flog

__all__ = ["BLOCK", "N_FEATURES", "block_size", "classic_terms", "classic_terms_labels"]

#: Largest number of particles per block (the SIMD dimension of the kernel).
BLOCK = 64
#: Columns of the separable radiance form (F0, F1, F2, G1, G2).
N_FEATURES = 5


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
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


@njit(parallel=True, fastmath=FASTMATH, error_model="numpy", cache=True)
def classic_terms(coef, bl, full, slot_ptr, slot_y, slot_w, slot_nvar, fix_feat, var_ptr,
                  var_feat, unary, obs, inv_sigma, chunk_ptr, a, b, do_lse, out_chunk, out_node,
                  per_node):
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


@njit(parallel=True, fastmath=FASTMATH, error_model="numpy", cache=True)
def classic_terms_labels(coef, full, slot_ptr, slot_y, slot_w, slot_nvar, fix_feat, var_ptr,
                         var_feat, unary, obs, inv_sigma, chunk_ptr, a, b, do_lse, out_chunk,
                         out_node, per_node):
    """As :func:`classic_terms` with a node's labels as SIMD lanes (for a few particles).

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
