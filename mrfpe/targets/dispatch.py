"""Kernel dispatch of the BRDF pseudolikelihood family: the ONE place that calls the kernels.

:func:`pl_terms` takes the per-particle BRDF coefficients and a target's
tables and returns the summed (or per-node) terms of the per-node formula of
:mod:`mrfpe.targets.pseudolikelihood`. It picks the kernel
(:mod:`mrfpe.targets.kernels`): the labels-as-SIMD kernel for a handful of
particles (no padding), the particles-as-SIMD block kernel otherwise, and
pads the batch to whole blocks. A new kernel is wired in here and nowhere else.
"""

from __future__ import annotations

import numpy as np

from mrfpe.targets.energy import DataTables
from mrfpe.threads import thread_budget

__all__ = ["LABEL_KERNEL_BELOW", "pl_terms"]

#: Batches smaller than this run the labels-as-SIMD kernel (no padding of particles).
LABEL_KERNEL_BELOW = 5


def pl_terms(tables: DataTables, coef: np.ndarray, *, full: bool, unary: np.ndarray,
             obs: np.ndarray, inv_sigma: float, chunks: np.ndarray, a: float, b: float,
             dtype: str, per_node: bool) -> np.ndarray:
    """Kernel terms of a batch (before the per-node constants are added).

    Parameters
    ----------
    tables : the target's data tables.
    coef : (N, 5) float64
        Separable radiance coefficients of each particle
        (:func:`mrfpe.targets.reflectance.coefficients`), all finite in ``dtype``.
    full : bool
        Whether the model has the third (non-Lambertian/Ward) radiance term.
    unary, obs : (n, B) theta-independent energies and (n,) observed labels.
    inv_sigma : ``1 / sigma_b``.
    chunks : node-chunk bounds (:func:`mrfpe.targets.energy.chunk_bounds`).
    a, b : weights of ``-E_i(x_i)`` and ``log sum_s exp(-E_i(s))``.
    dtype : "float64" | "float32"
    per_node : bool

    Returns
    -------
    (N,) sum over nodes, or (N, n) per-node terms if ``per_node``.
    """
    from mrfpe.targets import kernels

    t = tables
    N = coef.shape[0]
    ft = np.dtype(dtype).type
    labels_simd = N < LABEL_KERNEL_BELOW
    if labels_simd:  # a few particles: the labels are the SIMD lanes, no padding
        npad = N
        bl = 0
        coef_t = np.ascontiguousarray(coef.T, dtype=ft)
    else:
        bl = kernels.block_size(N)
        npad = -(-N // bl) * bl
        coef_t = np.empty((5, npad), dtype=ft)
        coef_t[:, :N] = coef.T
        coef_t[:, N:] = coef[:1].T  # padding particles: copies of the first, discarded
    n_chunks = chunks.shape[0] - 1
    if per_node:
        out_chunk = np.zeros((1, 1))
        out_node = np.zeros((t.n_nodes, npad))
    else:
        out_chunk = np.zeros((n_chunks, npad))
        out_node = np.zeros((1, 1))
    args = (t.slot_ptr, t.slot_y, t.slot_w, t.slot_nvar, t.fix_feat, t.var_ptr, t.var_feat,
            unary, obs, ft(inv_sigma), chunks, ft(a), ft(b), b != 0, out_chunk, out_node,
            per_node)
    with thread_budget(N * t.brdf_evals_per_particle):
        if labels_simd:
            kernels.pl_terms_labels(coef_t, full, *args)
        else:
            kernels.pl_terms(coef_t, bl, full, *args)
    if per_node:
        return out_node[:, :N].T
    return out_chunk[:, :N].sum(axis=0)
