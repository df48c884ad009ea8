"""The engine's one door: :func:`evaluate` runs the plan's kernel on a batch of coefficients.

It picks the kernel (:func:`mrfpe.brdf.engine.plan.kernel_family`): for a handful of
particles (no padding) the nodes-as-SIMD kernel (lean,
:mod:`mrfpe.brdf.engine.lean_nodes`) or the labels-as-SIMD one (classic), the
particles-as-SIMD block kernel otherwise (:mod:`mrfpe.brdf.engine.lean`,
:mod:`mrfpe.brdf.engine.classic`), and pads the batch to whole blocks. A new kernel is
wired in here and nowhere else.

The two families compute the same terms: ``"lean"`` (default; fused template loop,
1.4-1.8x faster in float32, 1.15-1.35x in float64 on a Zen 4 host, ``python -m
benchmarks --only kernel``) and ``"classic"`` (general CSR loops, any data-term
layout). Results do not depend on the number of threads (the kernels' chunk sums
are added in a fixed order).
"""

from __future__ import annotations

import numpy as np

from mrfpe.brdf.engine import classic, lean, lean_nodes
from mrfpe.brdf.engine.plan import LABEL_KERNEL_BELOW, Plan, Tables, kernel_family, log2_units
from mrfpe.threads import thread_budget

__all__ = ["evaluate"]


def evaluate(plan: Plan, tables: Tables, coef: np.ndarray, *, per_node: bool = False
             ) -> np.ndarray:
    """Kernel terms of a batch, before the per-node constants are added.

    ``l_i = a (-E_i(x_i)) + b log sum_s exp(-E_i(s))`` with
    ``E_i(s) = unary_i(s) + sum_slots |y - w * prediction| / sigma_b`` (thesis 4.12).

    Parameters
    ----------
    plan : Plan
        The target's choices (:func:`mrfpe.brdf.engine.make_plan`).
    tables : Tables
        The target's tables (:func:`mrfpe.brdf.engine.make_tables`).
    coef : (N, 5) float64
        Separable radiance coefficients ``(c0, c1, c2, e1, e2)`` of each particle
        (:func:`mrfpe.brdf.targets.reflectance.coefficients`), all finite in ``plan.dtype``.
    per_node : bool
        Return the per-node terms instead of their sums.

    Returns
    -------
    (N,) sum over nodes, or (N, n) per-node terms if ``per_node``.
    """
    family = kernel_family(plan, tables, coef)
    if family == "lean":  # the lean kernels take the exponent coefficients in log2 units
        coef = log2_units(coef)
    N = coef.shape[0]
    few = N < LABEL_KERNEL_BELOW
    if few:  # a few particles: no padding (the small-batch kernels)
        bl = 0
        coef_t = np.ascontiguousarray(coef.T, dtype=plan.dtype)
    else:
        if family == "lean":
            bl = lean.block_size(N, tables.n_labels, np.dtype(plan.dtype).itemsize)
        else:
            bl = classic.block_size(N)
        npad = -(-N // bl) * bl
        coef_t = np.empty((5, npad), dtype=plan.dtype)
        coef_t[:, :N] = coef.T
        coef_t[:, N:] = coef[:1].T  # padding particles: copies of the first, discarded
    npad = coef_t.shape[1]
    if per_node:
        out_chunk = np.zeros((1, 1))
        out_node = np.zeros((tables.n_nodes, npad))
    else:
        out_chunk = np.zeros((tables.chunks.shape[0] - 1, npad))
        out_node = np.zeros((1, 1))
    run = _run_lean if family == "lean" else _run_classic
    with thread_budget(N * tables.data.brdf_evals_per_particle) as n_threads:
        run(plan, tables, coef_t, bl, n_threads if few else 0, out_chunk, out_node, per_node)
    return out_node[:, :N].T if per_node else out_chunk[:, :N].sum(axis=0)


def _run_lean(plan: Plan, tables: Tables, coef_t: np.ndarray, bl: int, n_threads: int,
              out_chunk: np.ndarray, out_node: np.ndarray, per_node: bool) -> None:
    """The lean kernels; ``n_threads`` > 0 for a few particles (the nodes-as-SIMD one)."""
    lt = tables.lean
    rest = (tables.obs, plan.inv_sigma_log2, tables.chunks, plan.a, plan.b, plan.do_lse,
            out_chunk, out_node, per_node)
    if n_threads:  # the node-major tables: nodes are the SIMD lanes
        lean_nodes.lean_terms_nodes(coef_t, lean_nodes.node_block(tables.n_nodes, n_threads),
                                    plan.full, plan.isotropic, lt.recT, lt.nrecT,
                                    tables.unary_log2_t, *rest)
    else:
        lean.lean_terms(coef_t, bl, plan.full, lt.rec, lt.nrec, tables.unary_log2, *rest)


def _run_classic(plan: Plan, tables: Tables, coef_t: np.ndarray, bl: int, n_threads: int,
                 out_chunk: np.ndarray, out_node: np.ndarray, per_node: bool) -> None:
    """The classic kernels; ``n_threads`` > 0 for a few particles (labels as SIMD lanes)."""
    t = tables.data
    args = (t.slot_ptr, t.slot_y, t.slot_w, t.slot_nvar, t.fix_feat, t.var_ptr, t.var_feat,
            tables.unary, tables.obs, plan.inv_sigma, tables.chunks, plan.a, plan.b,
            plan.do_lse, out_chunk, out_node, per_node)
    if n_threads:
        classic.classic_terms_labels(coef_t, plan.full, *args)
    else:
        classic.classic_terms(coef_t, bl, plan.full, *args)
