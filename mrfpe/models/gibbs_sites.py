"""Single-site Gibbs updates shared by every compiled sampler of a discrete MRF.

The pieces that make a draw, one node at a time, the same in every kernel
(:mod:`mrfpe.models.simulate`'s colour-class sweeps over any graph,
:mod:`mrfpe.models.simulate_batch`'s batches, :mod:`mrfpe.models.lattice_gibbs`'s lattice
stencils): the counter-based uniform ``_uniform(key, k)`` (SplitMix64, Steele, Lea & Flood
2014: output ``k`` of the stream seeded by ``key``, so a draw does not depend on which
thread makes it), inverse-CDF picks from unnormalised weights, a node's update from the
exponentiated tables (``_site``) and its exact fallback in log space with forbidden
(``-inf``) states counted apart (``_log_site``). One copy, so that every kernel's draws are
bit-identical for the same key.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mrfpe.threads import configure_vector_width

configure_vector_width()  # before our first @njit, as mrfpe.models.simulate does

__all__ = ["splitmix64"]

_GAMMA, _MIX1, _MIX2 = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9),
                        np.uint64(0x94D049BB133111EB))


@njit(inline="always", cache=True)
def splitmix64(key: np.uint64, ctr: np.uint64) -> np.uint64:
    """Output ``ctr`` of SplitMix64 seeded ``key``: 64 random bits (Steele, Lea & Flood
    2014), the counter-based stream of every kernel here and of the multi-spin sweeps."""
    z = key + ctr * _GAMMA
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@njit(inline="always", cache=True)
def _uniform(key: np.uint64, k: int) -> float:
    """Output ``k`` of SplitMix64 seeded ``key``, in [0, 1) (53 bits)."""
    return np.int64(splitmix64(key, np.uint64(k)) >> np.uint64(11)) * 1.1102230246251565e-16


@njit(inline="always", cache=True)
def _pick(w: np.ndarray, u: float) -> int:
    """Inverse-CDF draw from weights ``w >= 0``; ``-1`` if they (nearly) underflow."""
    total = w.sum()
    if not total > 1e-280:
        return -1
    target, acc, a = u * total, 0.0, 0
    for b in range(w.size):  # branch-free: a = how many CDF values are <= target
        acc += w[b]
        a += target >= acc
    return a if a < w.size else np.flatnonzero(w)[-1]  # u * total rounded up to total


@njit(inline="always", cache=True)
def _draw(w: np.ndarray, u: float) -> int:
    """Inverse-CDF draw from log-weights ``w`` (overwritten); ``-1`` if all are -inf."""
    m = w.max()  # all -inf: NaN weights, and _pick gives -1
    for a in range(w.size):
        w[a] = np.exp(w[a] - m)
    return _pick(w, u)


@njit(inline="always", cache=True)
def _site(i, x, node, pair, enode, epair, indptr, nbr, ntab, u, w) -> None:
    """Gibbs update of node ``i``: weights as products of exponentiated tables (``epair``
    rows ``t * q + x_j``; no ``exp`` per site, scalars for q = 2); log-weights on
    underflow."""
    q, r, single = w.size, i if node.shape[0] > 1 else np.uint32(0), epair.shape[0] == w.size
    if q == 2:
        w0, w1 = enode[r, 0], enode[r, 1]
        for k in range(indptr[i], indptr[i + 1]):
            row = x[nbr[k]] if single else np.uint32(ntab[k] * 2 + x[nbr[k]])
            w0 *= epair[row, 0]
            w1 *= epair[row, 1]
        if w0 + w1 > 1e-280:
            x[i] = 1 if u * (w0 + w1) >= w0 else 0
            return
    w[:] = enode[r]
    for k in range(indptr[i], indptr[i + 1]):
        row = x[nbr[k]] if single else np.uint32(ntab[k] * q + x[nbr[k]])
        for a in range(q):
            w[a] *= epair[row, a]
    a = _pick(w, u)
    x[i] = a if a >= 0 else _log_site(i, r, x, node, pair, indptr, nbr, ntab, u, w)


@njit(inline="always", cache=True)
def _n_forbidden(i, b, x, pair, indptr, nbr, ntab) -> int:
    """How many of node ``i``'s neighbours forbid (-inf) its state ``b``."""
    c = 0
    for k in range(indptr[i], indptr[i + 1]):
        c += pair[ntab[k], x[nbr[k]], b] == -np.inf
    return c


@njit(cache=True)
def _log_site(i, r, x, node, pair, indptr, nbr, ntab, u, w) -> int:
    """Node ``i``'s state from log-weights, where every product underflowed: among the
    states its node potential allows, those meeting the fewest forbidden (-inf) pairs (a
    chain not yet in the support), drawn by their finite log-potentials. Forbidden entries
    are counted apart, never summed as a large negative number a finite one could meet."""
    q, fewest = w.size, np.int64(indptr[i + 1]) - np.int64(indptr[i]) + 1
    for b in range(q):
        if node[r, b] > -np.inf:
            fewest = min(fewest, _n_forbidden(i, b, x, pair, indptr, nbr, ntab))
    for b in range(q):
        w[b] = -np.inf
        if node[r, b] > -np.inf and _n_forbidden(i, b, x, pair, indptr, nbr, ntab) == fewest:
            w[b] = node[r, b]
            for k in range(indptr[i], indptr[i + 1]):
                p = pair[ntab[k], x[nbr[k]], b]
                w[b] += p if p > -np.inf else 0.0
    a = _draw(w, u)
    if a < 0:  # the finite log-weights overflowed (log-potentials near 1e308): the first
        for b in range(q):
            if node[r, b] > -np.inf and _n_forbidden(i, b, x, pair, indptr, nbr,
                                                     ntab) == fewest:
                return b
    return a
