"""Kernel dispatch of the BRDF pseudolikelihood family: the ONE place that calls the kernels.

:func:`pl_terms` takes the per-particle BRDF coefficients and a target's
tables and returns the summed (or per-node) terms of the per-node formula of
:mod:`mrfpe.targets.pseudolikelihood`. It picks the kernel
(:mod:`mrfpe.targets.kernels`): for a handful of particles (no padding) the
nodes-as-SIMD kernel (lean) or the labels-as-SIMD one (classic), the
particles-as-SIMD block kernel otherwise, and
pads the batch to whole blocks. A new kernel is wired in here and nowhere else.

Two kernel families compute the same terms: ``"lean"`` (default,
:mod:`mrfpe.targets.lean`: fused template loop; 1.4-1.8x faster in float32,
1.15-1.35x in float64 on a Zen 4 host, ``python -m benchmarks --only kernel``) and ``"classic"``
(:mod:`mrfpe.targets.kernels`, the general CSR loops). The lean kernel needs the
pixel template (at most 4 slots per node, 2 with two variable triangles); tables
that do not fit fall back to the classic one. :data:`KERNEL` (or the
:func:`use_kernel` context) picks the family, so a benchmark can time both in
one process.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from mrfpe.targets.energy import DataTables
from mrfpe.threads import thread_budget

LOG2E = 1.4426950408889634

__all__ = ["KERNEL", "KERNELS", "LABEL_KERNEL_BELOW", "kernel_for", "pl_terms", "use_kernel"]

#: Kernel families (module docstring).
KERNELS = ("lean", "classic")
#: The family :func:`pl_terms` uses; change with :func:`use_kernel`.
KERNEL = "lean"


_LOG2_UNARY: dict[tuple[int, bool], np.ndarray] = {}


def _log2_units(unary: np.ndarray, transposed: bool = False) -> np.ndarray:
    """``unary * log2(e)`` (its (B, n) transpose if ``transposed``), rounded once from
    float64 and kept while ``unary`` lives."""
    key = (id(unary), transposed)
    hit = _LOG2_UNARY.get(key)
    if hit is None:
        hit = (unary.astype(np.float64) * LOG2E).astype(unary.dtype)
        hit = np.ascontiguousarray(hit.T) if transposed else hit
        _LOG2_UNARY[key] = hit
        weakref.finalize(unary, _LOG2_UNARY.pop, key, None)
    return hit


@contextmanager
def use_kernel(name: str) -> Iterator[str]:
    """Run the enclosed block with kernel family ``name`` (``"lean"`` or ``"classic"``)."""
    global KERNEL
    if name not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}; got {name!r}")
    old, KERNEL = KERNEL, name
    try:
        yield name
    finally:
        KERNEL = old


def kernel_for(tables: DataTables, full: bool) -> str:
    """The family :func:`pl_terms` would run for ``tables`` now (lean falls back to classic)."""
    from mrfpe.targets.lean import lean_tables

    if KERNEL == "lean" and lean_tables(tables, full) is not None:
        return "lean"
    return "classic"

#: Batches smaller than this run the small-batch kernels (no padding of particles).
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
    lean = kernel_for(t, full) == "lean"
    if lean:  # the lean kernels take the exponent coefficients in log2 units
        from mrfpe.targets.lean import HI32, HI64, exponent_bound, lean_tables

        log2_coef = coef.copy()
        log2_coef[:, 3:] *= LOG2E
        # their exp2 skips the overflow clamp: an exponent that could exceed it (a model
        # whose lobes grow, not decay) goes to the classic kernel
        hi = HI32 if np.dtype(dtype) == np.float32 else HI64
        lean = exponent_bound(lean_tables(t, full), log2_coef[:, 3:]) <= hi
        coef = log2_coef if lean else coef
    if labels_simd:  # a few particles: no padding (the small-batch kernels)
        npad = N
        bl = 0
        coef_t = np.ascontiguousarray(coef.T, dtype=ft)
    else:
        if lean:
            from mrfpe.targets.lean import block_size

            bl = block_size(N, t.n_labels, np.dtype(dtype).itemsize)
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
    if lean:
        from mrfpe.targets.lean import lean_tables_t, lean_terms, lean_terms_nodes, node_block

        lt = lean_tables(t, full)
        rest = (obs, ft(inv_sigma * LOG2E), chunks, ft(a), ft(b), b != 0, out_chunk, out_node,
                per_node)
        with thread_budget(N * t.brdf_evals_per_particle) as n_threads:
            if labels_simd:  # the node-major tables: nodes are the SIMD lanes
                ltt = lean_tables_t(lt)
                lean_terms_nodes(coef_t, node_block(t.n_nodes, n_threads), full, lt.isotropic,
                                 ltt.recT, ltt.nrecT, _log2_units(unary, transposed=True), *rest)
            else:
                lean_terms(coef_t, bl, full, lt.rec, lt.nrec, _log2_units(unary), *rest)
        return out_node[:, :N].T if per_node else out_chunk[:, :N].sum(axis=0)
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
