"""Single-site Gibbs sweeps specialised to 4- and 8-neighbour lattices: the general kernel's
draws, by stencil arithmetic.

:func:`mrfpe.models.simulate.simulate` (and :func:`~mrfpe.models.simulate_batch.
simulate_batch`) sweep any graph's colour classes by single-site Gibbs updates (Geman &
Geman 1984), walking CSR neighbour lists. On a lattice (:func:`mrfpe.models.graph.lattice`:
4 or 8 neighbours, free or periodic boundary, shared per-type pair tables, node tables
shared or per node, any ``q <= 255``) this kernel runs the *same* chain with the *same*
draws, bit for bit, faster:

* states are ``uint8``; a colour class is swept row by row (``prange`` over rows), the
  classes in the general kernel's order (the lattice's colourings ``(r + c) % 2`` and
  ``2 (r % 2) + c % 2``); within a class the nodes are independent, so the order of visits
  does not matter;
* node ``i = r * W + c`` at sweep ``s`` takes output ``s * n + i`` of the counter-based
  SplitMix64 stream (Steele, Lea & Flood 2014), as in the general kernel;
* an interior node finds its neighbours at fixed offsets of ``i``, listed in increasing
  node id -- the order of the CSR lists -- so its weights are the same products of
  exponentiated table rows, multiplied in the same order (floating-point products depend
  on the order); with node tables shared and at most :data:`TABULATE_MAX` neighbour
  configurations (``q ** degree``), those products are tabulated once per call, by the same
  operations, and looked up;
* boundary nodes (whose neighbours wrap around or are missing) and nodes whose weights
  underflow (``-inf`` tables: forbidden states) take the general update through the CSR
  lists (:mod:`mrfpe.models.gibbs_sites`, the one copy every kernel uses).
"""

from __future__ import annotations

import weakref
from types import SimpleNamespace
from typing import Any

import numpy as np
from numba import njit, prange

from mrfpe.models.design import Design
from mrfpe.models.gibbs_sites import _pick, _site, _uniform
from mrfpe.models.multispin import _lattice_rule
from mrfpe.threads import configure_vector_width

configure_vector_width()  # before our first @njit, as mrfpe.models.simulate does

__all__ = ["TABULATE_MAX", "LatticeStencil", "lattice_stencil", "run_lattice"]

#: Most neighbour configurations (``q ** degree``) whose weights are tabulated per call.
TABULATE_MAX = 8192
_BLOCK = 4096  # nodes (whole rows) per parallel chunk of a colour class
@njit(inline="always", cache=True)
def _tabulated(x, i0, j0, j1, cw, dpos, mult, ubuf, w, fail) -> int:
    """Update the interior nodes ``i0 + 2 j`` (``j0 <= j < j1``; neighbours at ``+ dpos``)
    from the weights tabulated by neighbour states (``cw``, row ``sum x_k mult[k]``); the
    ``j`` whose weights underflow go to ``fail`` (returns their count)."""
    nf = 0
    if w.size == 2:  # the binary update of _site (a loop of its own: ~2x faster)
        for j in range(j0, j1):
            i, idx = i0 + 2 * j, 0
            for k in range(len(dpos)):
                idx += x[np.uint64(i + dpos[k])] * mult[k]
            w0 = cw[np.uint64(idx), 0]
            tot = w0 + cw[np.uint64(idx), 1]
            if tot > 1e-280:
                x[np.uint64(i)] = ubuf[j] * tot >= w0
            else:
                fail[nf] = j
                nf += 1
        return nf
    for j in range(j0, j1):
        i, idx = i0 + 2 * j, 0
        for k in range(len(dpos)):
            idx += x[np.uint64(i + dpos[k])] * mult[k]
        a = _pick(cw[np.uint64(idx)], ubuf[j])
        if a >= 0:
            x[np.uint64(i)] = a
        else:
            fail[nf] = j
            nf += 1
    return nf


@njit(inline="always", cache=True)
def _products(x, i0, j0, j1, enode, epair, dpos, dtyp, ubuf, w, fail) -> int:
    """As :func:`_tabulated`, the weights as products of table rows in the order of
    ``_site`` (node tables per node, or too many neighbour configurations to tabulate)."""
    nf, q, shared = 0, w.size, enode.shape[0] == 1
    for j in range(j0, j1):
        i = i0 + 2 * j
        r = 0 if shared else i
        if q == 2:
            w0, w1 = enode[r, 0], enode[r, 1]
            for k in range(len(dpos)):
                row = dtyp[k] * 2 + x[np.uint64(i + dpos[k])]
                w0 *= epair[row, 0]
                w1 *= epair[row, 1]
            if w0 + w1 > 1e-280:
                x[np.uint64(i)] = 1 if ubuf[j] * (w0 + w1) >= w0 else 0
                continue
        else:
            w[:] = enode[r]
            for k in range(len(dpos)):
                row = dtyp[k] * q + x[np.uint64(i + dpos[k])]
                for a in range(q):
                    w[a] *= epair[row, a]
            a = _pick(w, ubuf[j])
            if a >= 0:
                x[np.uint64(i)] = a
                continue
        fail[nf] = j
        nf += 1
    return nf


@njit(cache=True)
def _boundary(i, x, node, pair, enode, epair, indptr, nbr, ntab, u, w) -> None:
    """The general update of node ``i`` (not inlined: it keeps the stencil loop small)."""
    _site(np.uint32(i), x, node, pair, enode, epair, indptr, nbr, ntab, u, w)


@njit(inline="always", cache=True)
def _row(x, r, k, K, H, W, s, key, node, pair, enode, epair, cw, indptr, nbr, ntab, dpos,
         dtyp, mult, w, ubuf, fail) -> None:
    """Update the nodes of colour ``k`` (of ``K``: 2 or 4) in row ``r``: the interior ones by
    the stencil, the rest (and underflows, after: a class's nodes are independent) by CSR."""
    if K == 4 and r % 2 != k // 2:
        return
    c0 = (k + r) % 2 if K == 2 else k % 2
    i0, m = r * W + c0, (W - c0 + 1) // 2
    first = np.uint64(s * H * W + i0)
    for j in range(m):  # the row's uniforms apart: a loop the compiler vectorises
        ubuf[j] = _uniform(key, first + np.uint64(2 * j))
    j0, j1, nf = 0, 0, 0  # the interior nodes: j0 <= j < j1
    if 0 < r < H - 1:
        j0, j1 = (1 if c0 == 0 else 0), (m - 1 if c0 + 2 * (m - 1) == W - 1 else m)
        if cw.shape[0] > 0:
            nf = _tabulated(x, i0, j0, max(j0, j1), cw, dpos, mult, ubuf, w, fail)
        else:
            nf = _products(x, i0, j0, max(j0, j1), enode, epair, dpos, dtyp, ubuf, w, fail)
        j1 = max(j0, j1)
    for j in range(m):
        if j < j0 or j >= j1:
            _boundary(i0 + 2 * j, x, node, pair, enode, epair, indptr, nbr, ntab, ubuf[j], w)
    for f in range(nf):
        j = fail[f]
        _boundary(i0 + 2 * j, x, node, pair, enode, epair, indptr, nbr, ntab, ubuf[j], w)


@njit(cache=True, parallel=True)
def _lattice_chains(X, H, W, K, node, pair, enode, epair, cw, indptr, nbr, ntab, dpos, dtyp,
                    mult, keys, slot, out) -> None:
    """One chain per thread: ``slot.size`` sweeps of chain ``b``; after sweep ``s`` its state
    goes to ``out[b, slot[s]]`` (if ``>= 0``)."""
    for b in prange(X.shape[0]):
        x, w, key = X[b], np.empty(pair.shape[-1]), keys[b]
        ubuf, fail = np.empty((W + 1) // 2), np.empty((W + 1) // 2, np.int64)
        nd, pr, en, ep, t = node[b], pair[b], enode[b], epair[b], cw[b]
        for s in range(slot.size):
            for k in range(K):
                for r in range(H):
                    _row(x, r, k, K, H, W, s, key, nd, pr, en, ep, t, indptr, nbr, ntab, dpos,
                         dtyp, mult, w, ubuf, fail)
            if slot[s] >= 0:
                out[b, slot[s]] = x


@njit(cache=True, parallel=True)
def _lattice_rows(X, H, W, K, node, pair, enode, epair, cw, indptr, nbr, ntab, dpos, dtyp,
                  mult, keys, slot, out) -> None:
    """Blocks of rows of one colour class of every chain shared among the threads (one
    chain, or fewer chains than threads)."""
    B, R = X.shape[0], max(1, _BLOCK // W)  # rows a block
    nb = (H + R - 1) // R
    for s in range(slot.size):
        for k in range(K):
            for t in prange(B * nb):
                b, lo = t // nb, t % nb * R
                w, ubuf = np.empty(pair.shape[-1]), np.empty((W + 1) // 2)
                fail = np.empty((W + 1) // 2, np.int64)
                for r in range(lo, min(H, lo + R)):
                    _row(X[b], r, k, K, H, W, s, keys[b], node[b], pair[b], enode[b],
                         epair[b], cw[b], indptr, nbr, ntab, dpos, dtyp, mult, w, ubuf, fail)
        if slot[s] >= 0:
            for b in range(B):
                out[b, slot[s]] = X[b]


@njit(cache=True)
def _tabulate(enode, epair, dtyp, cw) -> None:
    """``cw[b, idx]``: the products of :func:`_products` for shared node tables, neighbour
    ``k`` in state digit ``k`` of ``idx`` (base q, most significant first)."""
    q, D = cw.shape[2], len(dtyp)
    digits = np.empty(D, np.int64)
    for b in range(cw.shape[0]):
        for idx in range(cw.shape[1]):
            rest = idx
            for k in range(D - 1, -1, -1):
                digits[k], rest = rest % q, rest // q
            for a in range(q):
                cw[b, idx, a] = enode[b, 0, a]
            for k in range(D):
                row = dtyp[k] * q + digits[k]
                for a in range(q):
                    cw[b, idx, a] *= epair[b, row, a]


class LatticeStencil:
    """A lattice design's shape, colour classes and interior stencil (:func:`lattice_stencil`)."""

    def __init__(self, H: int, W: int, K: int, offsets: tuple, types: tuple) -> None:
        self.H, self.W, self.K = H, W, K
        self.dpos = tuple(int(dr * W + dc) for dr, dc in offsets)  # increasing: CSR order
        self.dtyp = tuple(int(t) for t in types)

    def __repr__(self) -> str:
        return f"LatticeStencil(H={self.H}, W={self.W}, colours={self.K}, degree={len(self.dpos)})"


_STENCILS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # per (immutable) graph


def lattice_stencil(design: Design) -> LatticeStencil | None:
    """The stencil :func:`run_lattice` sweeps ``design`` with, or None where only the general
    kernel applies: not a 4- or 8-neighbour lattice coloured by its periodic colouring
    (a periodic lattice of odd size is coloured greedily), pair tables per edge, ``q > 255``."""
    if design.pair_per_edge or design.q > 255:
        return None
    g = design.graph
    if g not in _STENCILS:
        _STENCILS[g] = _stencil_of(g)
    return _STENCILS[g]


def _stencil_of(g: Any) -> LatticeStencil | None:
    spec = _lattice_rule_of(g)
    if spec is None:
        return None
    H, W = g.shape
    r, c = np.divmod(np.arange(H * W, dtype=np.int64), W)
    eight = len(spec.offsets) == 4
    if not np.array_equal(g.colouring(), 2 * (r % 2) + c % 2 if eight else (r + c) % 2):
        return None
    # the neighbours of an interior node in increasing id, and the type of the joining edge
    offsets = sorted({o for dr, dc in spec.offsets for o in ((dr, dc), (-dr, -dc))})
    kind = {o: t for t, (dr, dc) in enumerate(spec.offsets) for o in ((dr, dc), (-dr, -dc))}
    types = [kind[o] if spec.directional else 0 for o in offsets]
    return LatticeStencil(H, W, 4 if eight else 2, tuple(offsets), tuple(types))


def _lattice_rule_of(g: Any) -> Any:
    """The 4- or 8-neighbour lattice rule ``g`` was built by, else None."""
    spec = _lattice_rule(SimpleNamespace(graph=g))  # it reads only the design's graph
    return None if isinstance(spec, str) else spec


def run_lattice(st: LatticeStencil, X: np.ndarray, node: np.ndarray, pair: np.ndarray,
                enode: np.ndarray, epair: np.ndarray, indptr: np.ndarray, nbr: np.ndarray,
                ntab: np.ndarray, keys: Any, slot: np.ndarray, out: np.ndarray,
                chains: bool = False) -> None:
    """Sweep ``B`` chains (``X`` (B, n): their starts) as the general kernel
    does, filling ``out`` (B, n_draws, n); tables as the general kernel's, batched (``node``
    (B, n|1, q), ``pair`` (B, T, q, q), ``enode``, ``epair`` (B, T * q, q)); the CSR lists
    serve the boundary. ``chains``: one chain per thread, else the rows of a colour class
    shared among the threads. One chain (``X`` (n,)) without the batch axis: its tables,
    ``keys`` (a scalar) and ``out`` (n_draws, n)."""
    if X.ndim == 1:
        X, node, pair, enode, epair, keys, out = (np.asarray(a)[None] for a in (
            X, node, pair, enode, epair, keys, out))
    B, q = X.shape[0], pair.shape[-1]
    configs = q ** len(st.dpos)
    cw = np.empty((B, configs if node.shape[1] == 1 and configs <= TABULATE_MAX else 0, q))
    _tabulate(enode, epair, st.dtyp, cw)
    X8 = X.astype(np.uint8)
    kernel = _lattice_chains if chains else _lattice_rows
    mult = tuple(q ** (len(st.dpos) - 1 - k) for k in range(len(st.dpos)))  # digits of a row
    kernel(X8, st.H, st.W, st.K, node, pair, enode, epair, cw, indptr, nbr, ntab, st.dpos,
           st.dtyp, mult, keys, slot, out)
