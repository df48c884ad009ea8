"""The lean kernel for a few particles: blocks of nodes as the SIMD lanes.

For one MCMC chain or an optimiser's probe (fewer than
:data:`mrfpe.brdf.engine.plan.LABEL_KERNEL_BELOW` particles), where a block of particles
would be mostly padding: the same terms as :func:`mrfpe.brdf.engine.lean.lean_terms`,
in the same order of operations per (particle, node, label), on the node-major
copy of the template tables (:class:`mrfpe.brdf.engine.template.LeanTables`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.brdf.engine.slots import (
    energy,
    exps_full,
    exps_iso,
    exps_ward,
    label_rows_full,
    label_rows_ward,
    residuals_full,
    residuals_ward,
)
from mrfpe.fastmath import FASTMATH, LN2, fexp2, flog

__all__ = ["NODE_BLOCK", "NODE_BLOCK_MAX", "lean_terms_nodes", "node_block"]


#: Fewest nodes per block of :func:`lean_terms_nodes` (and the block of
#: :mod:`mrfpe.brdf.engine.gradient`'s node-major loops).
NODE_BLOCK = 256
#: Most nodes per block of :func:`lean_terms_nodes` (:func:`node_block`).
NODE_BLOCK_MAX = 1024


def node_block(n_nodes: int, n_threads: int) -> int:
    """Nodes per block of :func:`lean_terms_nodes` for ``n_nodes`` nodes on ``n_threads``.

    Each (block, label) pair runs one vector loop over the block's nodes, whose
    set-up (29-45 row pointers, the alias checks) is paid once per pair: at
    100x100 nodes and 20 labels, blocks of 1024 take 0.80x the time of blocks of
    256 with one particle (Ward; 0.81x at 40 labels, 0.94x Phong at 20; medians
    of 15 alternations in one process, Zen 4). The block is the largest power of
    two from :data:`NODE_BLOCK` to :data:`NODE_BLOCK_MAX` that still leaves two
    blocks per thread, so threads stay balanced. Results do not depend on it
    (the per-node terms and their chunk sums are the same).
    """
    nb = NODE_BLOCK_MAX
    while nb > NODE_BLOCK and -(-int(n_nodes) // nb) < 2 * max(int(n_threads), 1):
        nb //= 2
    return nb


@njit(parallel=True, fastmath=FASTMATH, error_model="numpy", cache=True)
def lean_terms_nodes(coef, nb, full, iso, recT, nrecT, unaryT, obs, inv_sigma, chunk_ptr, a,
                     b, do_lse, out_chunk, out_node, per_node):  # pragma: no cover - compiled
    """As :func:`mrfpe.brdf.engine.lean.lean_terms` for a few particles, with blocks of ``nb`` nodes
    (:func:`node_block`) as the SIMD lanes, whatever the label count; ``iso``:
    :attr:`mrfpe.brdf.engine.template.LeanTables.isotropic`.

    ``coef`` is (5, N) without padding; ``recT``, ``nrecT``: the node-major tables
    (:class:`mrfpe.brdf.engine.template.LeanTables`);
    ``unaryT``: (B, n) in log2 units. Same formula and order of operations per
    (particle, node, label) as :func:`~mrfpe.brdf.engine.lean.lean_terms`; the node terms are
    then summed per chunk in node order, as there, so the sums do not depend on the block size. The
    fields are bound to 1-D rows (``recT[k, s]``) so that numba's code knows their unit
    stride and loads vectors, not gathers, and indexed from 0 so that no
    negative-index wraparound is compiled in; the per-slot formulas are
    :mod:`mrfpe.brdf.engine.slots`', shared with the Jacobian kernel.

    The particles loop inside each (block, label), so a label's rows are read once
    for all N: at 100x100 nodes and 20 labels one particle's pass streams the whole
    table (13 MB for Ward, 23 MB for Phong) and runs at 1.6x (Ward) to 2.2x (Phong)
    its in-cache time per node. Two particles then cost 1.9x one (Ward) and
    1.2-1.5x (Phong), four 3.4x and 1.8x (one core, medians of 8). With the particles
    outside the label loop, as before, the same bits took 0.93-1.05x this time at
    N = 1 and 1.08-1.20x at N = 4.
    """
    N = coef.shape[1]
    af = float(a)  # the node terms are combined in float64
    bf = float(b)
    B = unaryT.shape[0]
    NB = nb
    lo, hi = chunk_ptr[0], chunk_ptr[-1]
    vals = out_node if per_node else np.empty((hi, N))
    for blk in prange(-(-(hi - lo) // NB)):
        i0 = lo + blk * NB
        i1 = min(i0 + NB, hi)
        en = np.empty((N, B, NB), dtype=coef.dtype)
        fa1 = np.empty((N, NB), dtype=coef.dtype)
        fa2 = np.empty((N, NB), dtype=coef.dtype)
        fb1 = np.empty((N, NB), dtype=coef.dtype)
        fb2 = np.empty((N, NB), dtype=coef.dtype)
        mn = np.empty(NB, dtype=coef.dtype)
        ssum = np.empty(NB, dtype=coef.dtype)
        m = i1 - i0
        sl = slice(i0, i1)
        y0, y1, y2, y3 = nrecT[0, sl], nrecT[1, sl], nrecT[2, sl], nrecT[3, sl]
        if full:
            ha1, ga1, ha2, ga2 = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
            hb1, gb1, hb2, gb2 = nrecT[8, sl], nrecT[9, sl], nrecT[10, sl], nrecT[11, sl]
            for q in range(N):  # fixed triangles: once per node, not per label
                E1 = coef[3, q]
                E2 = coef[4, q]
                qa1, qa2, qb1, qb2 = fa1[q], fa2[q], fb1[q], fb2[q]
                for j in range(m):
                    xa = fexp2(E1 * ga1[j] + E2 * ga2[j])
                    xb = fexp2(E1 * gb1[j] + E2 * gb2[j])
                    qa1[j] = ha1[j] * xa
                    qa2[j] = ha2[j] * xa
                    qb1[j] = hb1[j] * xb
                    qb2[j] = hb2[j] * xb
            for s in range(B):
                r = label_rows_full(recT, unaryT, s, sl)
                for q in range(N):
                    C0 = coef[0, q]
                    C1 = coef[1, q]
                    C2 = coef[2, q]
                    E1 = coef[3, q]
                    E2 = coef[4, q]
                    qa1, qa2, qb1, qb2 = fa1[q], fa2[q], fb1[q], fb2[q]
                    es = en[q, s]
                    # G2 = 0: E1 G1 + E2 0 is E1 G1 exactly, and the G2 rows stay unread. A loop
                    # of its own: one loop with the branch inside changed LLVM's FMAs (the bits)
                    if iso:
                        for j in range(m):
                            t = residuals_full(r, j, C0, C1, C2, exps_iso(r, j, E1),
                                               (qa1[j], qa2[j], qb1[j], qb2[j]),
                                               (y0[j], y1[j], y2[j], y3[j]))
                            es[j] = energy(r.u[j], inv_sigma, t)
                        continue
                    for j in range(m):
                        t = residuals_full(r, j, C0, C1, C2, exps_full(r, j, E1, E2),
                                           (qa1[j], qa2[j], qb1[j], qb2[j]),
                                           (y0[j], y1[j], y2[j], y3[j]))
                        es[j] = energy(r.u[j], inv_sigma, t)
        else:
            ha1, ga1, hb1, gb1 = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
            for q in range(N):  # h, f: log2 of the weights (folded)
                E1 = coef[3, q]
                qa1, qb1 = fa1[q], fb1[q]
                for j in range(m):
                    qa1[j] = fexp2(E1 * ga1[j] + ha1[j])
                    qb1[j] = fexp2(E1 * gb1[j] + hb1[j])
            for s in range(B):
                r = label_rows_ward(recT, unaryT, s, sl)
                for q in range(N):
                    C0 = coef[0, q]
                    C1 = coef[1, q]
                    E1 = coef[3, q]
                    qa1, qb1 = fa1[q], fb1[q]
                    es = en[q, s]
                    for j in range(m):
                        t = residuals_ward(r, j, C0, C1, exps_ward(r, j, E1), (qa1[j], qb1[j]),
                                           (y0[j], y1[j], y2[j], y3[j]))
                        es[j] = energy(r.u[j], inv_sigma, t)
        for q in range(N):
            enq = en[q]
            if do_lse:
                for j in range(m):
                    mn[j] = enq[0, j]
                    ssum[j] = 0
                for s in range(1, B):
                    es = enq[s]
                    for j in range(m):
                        mn[j] = min(mn[j], es[j])
                for s in range(B):
                    es = enq[s]
                    for j in range(m):
                        ssum[j] += fexp2(mn[j] - es[j])  # energies in log2 units
            for j in range(m):
                eo = enq[obs[i0 + j], j]
                if do_lse:
                    vals[i0 + j, q] = LN2 * (af * -float(eo) - bf * float(mn[j])) + bf * float(
                        flog(ssum[j]))
                else:
                    vals[i0 + j, q] = LN2 * (af * -float(eo))
    if not per_node:
        for c in prange(chunk_ptr.shape[0] - 1):
            for q in range(N):
                acc = 0.0
                for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                    acc += vals[i, q]
                out_chunk[c, q] = acc
