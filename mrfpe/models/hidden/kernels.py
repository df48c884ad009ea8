"""Compiled label updates of a hidden MRF: every one adds the data term to the MRF's conditionals.

Node ``i``'s full conditional given its neighbours and its observation is (Geman &
Geman 1984; Besag 1986, the conditional that ICM maximises)

    ``log p(x_i = a | x_N_i, y_i) = node[i, a] + sum_{j ~ i} pair[e_ij, a, x_j] + L[i, a] + c``,

the MRF's log-potential tables at the current parameters (:meth:`Design.tables
<mrfpe.models.design.Design.tables>`) plus the emission's log-density ``L[i, a] =
log p(y_i | x_i = a)`` (0 at a missing node). Nodes of one colour class share no edge,
so a class is updated in parallel: :func:`gibbs_sweep` (the chequerboard Gibbs
sampler, with the Rao-Blackwellised conditional probabilities added up for the label
posterior), :func:`icm_sweep` (Besag's 1986 iterated conditional modes) and
:func:`mean_field_sweep` (the mean-field fixed point of Celeux, Forbes & Peyrard
2003, updated sequentially: neighbours enter through their probabilities, ``sum_b P_j(b)
pair[e, a, b]``). :func:`swendsen_wang_sweep` is Swendsen and Wang's (1987) cluster update
with an external field (Higdon 1998): bonds join equal neighbours with probability
``1 - exp(-J_e)`` and each cluster takes state ``a`` with probability ``∝ exp(sum_{i in
C} h[i, a])``, ``h`` the node tables, the per-state parts of the pair tables and the
data term together.

``-inf`` (a forbidden state or pair, or an impossible observation) is counted apart,
never summed as a large negative number: a site takes one of the states meeting the
fewest ``-inf`` terms, by the finite log-weights of those (the exact conditional as soon
as the chain is in the support). Uniforms come from the caller, one per node per sweep,
so the draws do not depend on the number of threads.

The Gibbs sweep, which the sampler runs every step, weighs a site by products instead
(as :mod:`mrfpe.models.simulate` does): the tables exponentiated once per parameter
vector, each row scaled to a largest entry of 1, and the data term ``exp(L)`` once per
sweep in one vectorised pass (:func:`data_factors`), so no ``exp`` per site. A ``-inf``
term is a factor 0; where the products' sum is below 1e-280 (every state forbidden,
or an underflow) or not finite, the site takes the log-space path above, so the
conditional is the same (``tests/models/hidden/test_fast_kernels.py``). The serial
kernel (:func:`gibbs_sweep_serial`) runs where one thread is budgeted: numba's
parallel loop on one thread measured twice as slow. :func:`row_counts` gives each
node's conditional row (its label and its neighbours per edge type and state) as one
integer, for the MRF's pseudolikelihood (:meth:`LabelField.conditional_rows
<mrfpe.models.hidden.field.LabelField.conditional_rows>`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.threads import configure_vector_width

configure_vector_width()  # before our first @njit, as mrfpe.models.simulate does

__all__ = ["BLOCK", "conditionals", "data_factors", "gibbs_sweep", "gibbs_sweep_serial",
           "icm_sweep", "mean_field_sweep", "row_counts", "swendsen_wang_sweep"]

#: Nodes per parallel chunk of a colour class.
BLOCK = 2048


@njit(inline="always", cache=True)
def _log_weights(i, x, node, pair, indptr, nbr, ntab, loglik, w, bad) -> None:
    """``w[a]``: the finite part of node ``i``'s log conditional weight of state ``a``;
    ``bad[a]``: how many of its terms are ``-inf``."""
    q = w.size
    r = i if node.shape[0] > 1 else 0
    for a in range(q):
        v, nb = node[r, a], 0
        if v == -np.inf:
            v, nb = 0.0, 1
        d = loglik[i, a]
        if d == -np.inf:
            nb += 1
        else:
            v += d
        for k in range(indptr[i], indptr[i + 1]):
            p = pair[ntab[k], a, x[nbr[k]]]
            if p == -np.inf:
                nb += 1
            else:
                v += p
        w[a], bad[a] = v, nb


@njit(inline="always", cache=True)
def _normalise(w, bad) -> None:
    """``w`` made the probabilities of the states with the fewest ``-inf`` terms."""
    q = w.size
    fewest = bad.min()
    m = -np.inf
    for a in range(q):
        if bad[a] == fewest and w[a] > m:
            m = w[a]
    total = 0.0
    for a in range(q):
        w[a] = np.exp(w[a] - m) if bad[a] == fewest else 0.0
        total += w[a]
    for a in range(q):
        w[a] /= total


@njit(inline="always", cache=True)
def _two_weights(i, x, enode, epair, indptr, nbr, ntab, edata) -> tuple[float, float]:
    """Node ``i``'s two conditional weights as products of exponentiated tables (``epair``
    rows ``t * q + x_j``, no ``exp`` per site), in scalars."""
    r = i if enode.shape[0] > 1 else 0
    single = epair.shape[0] == 2  # one pair table: no table index to read
    w0, w1 = enode[r, 0] * edata[i, 0], enode[r, 1] * edata[i, 1]
    for k in range(indptr[i], indptr[i + 1]):
        row = np.uint32(x[nbr[k]]) if single else np.uint32(ntab[k] * 2 + x[nbr[k]])
        w0 *= epair[row, 0]
        w1 *= epair[row, 1]
    return w0, w1


@njit(inline="always", cache=True)
def _product_weights(i, x, enode, epair, indptr, nbr, ntab, edata, w) -> float:
    """:func:`_two_weights` for any number of states, into ``w``; returns their sum."""
    q = w.size
    r = i if enode.shape[0] > 1 else 0
    single = epair.shape[0] == q
    for a in range(q):
        w[a] = enode[r, a] * edata[i, a]
    for k in range(indptr[i], indptr[i + 1]):
        row = np.uint32(x[nbr[k]]) if single else np.uint32(ntab[k] * q + x[nbr[k]])
        for a in range(q):
            w[a] *= epair[row, a]
    total = 0.0
    for a in range(q):
        total += w[a]
    return total


@njit(cache=True)
def _log_space_site(i, x, node, pair, indptr, nbr, ntab, loglik, ui, acc, accumulate) -> None:
    """Node ``i``'s draw at ``ui`` from its conditional in log space, ``-inf`` terms
    counted apart (:func:`conditionals`): where the products fail (not inlined: rare)."""
    q = loglik.shape[1]
    w, bad = np.empty(q), np.empty(q, np.int64)
    _log_weights(i, x, node, pair, indptr, nbr, ntab, loglik, w, bad)
    _normalise(w, bad)
    if accumulate:
        for a in range(q):
            acc[i, a] += w[a]
    x[i] = _inverse_cdf(w, ui)


@njit(inline="always", cache=True)
def _inverse_cdf(w, target) -> int:
    """The state whose cumulative weight ``w`` first passes ``target`` (how many
    cumulative weights are at most ``target``: branch-free, and never a state of weight
    0); the last state of positive weight where ``target`` rounded past them all."""
    q, cum, pick = w.size, 0.0, 0
    for a in range(q):
        cum += w[a]
        pick += target >= cum
    if pick < q:
        return pick
    pick = q - 1
    while w[pick] == 0.0:
        pick -= 1
    return pick


@njit(inline="always", cache=True)
def _sites_two(lo, hi, x, order, node, pair, enode, epair, indptr, nbr, ntab, loglik, edata,
               u, acc, accumulate) -> None:
    """The Gibbs updates of nodes ``order[lo:hi]`` (of one colour class) in turn, for two
    states: the weights in scalars."""
    for k in range(lo, hi):
        i = order[k]
        ui = u[i]
        w0, w1 = _two_weights(i, x, enode, epair, indptr, nbr, ntab, edata)
        total = w0 + w1
        if 1e-280 < total < np.inf:
            if accumulate:
                acc[i, 0] += w0 / total
                acc[i, 1] += w1 / total
            x[i] = 1 if ui * total >= w0 and w1 > 0.0 else 0  # as _inverse_cdf
        else:
            _log_space_site(i, x, node, pair, indptr, nbr, ntab, loglik, ui, acc, accumulate)


@njit(inline="always", cache=True)
def _sites_many(lo, hi, x, order, node, pair, enode, epair, indptr, nbr, ntab, loglik, edata,
                u, acc, accumulate, w) -> None:
    """:func:`_sites_two` for any number of states (``w`` the work array). Kept apart: in
    one loop with it, the two-state path compiles about 5 x slower."""
    q = w.size
    for k in range(lo, hi):
        i = order[k]
        ui = u[i]
        total = _product_weights(i, x, enode, epair, indptr, nbr, ntab, edata, w)
        if 1e-280 < total < np.inf:
            if accumulate:
                for a in range(q):
                    acc[i, a] += w[a] / total
            x[i] = _inverse_cdf(w, ui * total)
        else:
            _log_space_site(i, x, node, pair, indptr, nbr, ntab, loglik, ui, acc, accumulate)


@njit(cache=True, parallel=True)
def gibbs_sweep(x, order, cptr, node, pair, enode, epair, indptr, nbr, ntab, loglik, edata, u,
                acc, accumulate) -> None:
    """One chequerboard Gibbs sweep of labels ``x`` (n,) over the colour classes
    ``order[cptr[c]:cptr[c + 1]]``; node ``i`` draws by inverse CDF at ``u[i]``. With
    ``accumulate``, its conditional probabilities are added to ``acc[i]`` (n, q).

    The weights are products of the exponentiated tables ``enode``, ``epair`` and data
    factors ``edata`` (:func:`data_factors`). Where their sum is below 1e-280 (every
    state meets a ``-inf`` term, or the finite weights underflow) or not finite, the
    site takes the log-space path of :func:`conditionals` instead; otherwise some state
    meets no ``-inf`` term and the products are that same conditional."""
    q = loglik.shape[1]
    for c in range(cptr.size - 1):
        lo, hi = cptr[c], cptr[c + 1]
        for b in prange((hi - lo + BLOCK - 1) // BLOCK):
            s, e = lo + b * BLOCK, min(hi, lo + (b + 1) * BLOCK)
            if q == 2:
                _sites_two(s, e, x, order, node, pair, enode, epair, indptr, nbr, ntab, loglik,
                           edata, u, acc, accumulate)
            else:
                _sites_many(s, e, x, order, node, pair, enode, epair, indptr, nbr, ntab,
                            loglik, edata, u, acc, accumulate, np.empty(q))


@njit(cache=True)
def gibbs_sweep_serial(x, order, cptr, node, pair, enode, epair, indptr, nbr, ntab, loglik,
                       edata, u, acc, accumulate) -> None:
    """:func:`gibbs_sweep` on one thread: the same draws, about twice as fast as the
    parallel kernel on one thread (measured)."""
    q = loglik.shape[1]
    w = np.empty(q)
    for c in range(cptr.size - 1):
        if q == 2:
            _sites_two(cptr[c], cptr[c + 1], x, order, node, pair, enode, epair, indptr, nbr,
                       ntab, loglik, edata, u, acc, accumulate)
        else:
            _sites_many(cptr[c], cptr[c + 1], x, order, node, pair, enode, epair, indptr, nbr,
                        ntab, loglik, edata, u, acc, accumulate, w)


def data_factors(loglik: np.ndarray) -> np.ndarray:
    """``exp(L)`` (n, q), the data term as factors (0 where ``L`` is ``-inf``): one
    vectorised ``exp`` per sweep. Not scaled per node: where a node's products underflow
    (say an outlier every state explains badly), :func:`gibbs_sweep` takes the
    log-space path there."""
    with np.errstate(over="ignore", under="ignore"):
        return np.exp(loglik)


@njit(cache=True, parallel=True)
def icm_sweep(x, order, cptr, node, pair, indptr, nbr, ntab, loglik) -> int:
    """One sweep of iterated conditional modes (Besag 1986): each node takes its most
    probable state given its neighbours (the current one on a tie). Returns how many
    nodes changed."""
    q = loglik.shape[1]
    changed = 0
    for c in range(cptr.size - 1):
        lo, hi = cptr[c], cptr[c + 1]
        for b in prange((hi - lo + BLOCK - 1) // BLOCK):
            w = np.empty(q)
            bad = np.empty(q, np.int64)
            for k in range(lo + b * BLOCK, min(hi, lo + (b + 1) * BLOCK)):
                i = order[k]
                _log_weights(i, x, node, pair, indptr, nbr, ntab, loglik, w, bad)
                _normalise(w, bad)
                best = x[i]
                for a in range(q):
                    if w[a] > w[best]:
                        best = a
                if best != x[i]:
                    x[i] = best
                    changed += 1
    return changed


@njit(cache=True)
def conditionals(x, node, pair, indptr, nbr, ntab, loglik, out) -> None:
    """``out[i]`` (n, q): node ``i``'s full conditional given its neighbours in ``x``."""
    q = loglik.shape[1]
    w = np.empty(q)
    bad = np.empty(q, np.int64)
    for i in range(x.size):
        _log_weights(i, x, node, pair, indptr, nbr, ntab, loglik, w, bad)
        _normalise(w, bad)
        out[i] = w


@njit(cache=True)
def row_counts(x, indptr, nbr, ntab, stride, q, keys, counts) -> None:
    """``keys[i] = x_i + sum_{j ~ i} stride[t_ij q + x_j]``: node ``i``'s label and its
    neighbours per edge type and state as one integer (``stride`` a mixed radix, already
    times ``q``); or, where ``counts`` holds every key, how many nodes have each in
    ``counts[key]`` (``keys`` left alone)."""
    single = stride.size == q  # one edge type: no table index to read
    for i in range(x.size):
        key = x[i]
        if single:
            for k in range(indptr[i], indptr[i + 1]):
                key += stride[np.uint32(x[nbr[k]])]
        else:
            for k in range(indptr[i], indptr[i + 1]):
                key += stride[np.uint32(ntab[k] * q + x[nbr[k]])]
        if counts.size:
            counts[key] += 1
        else:
            keys[i] = key


@njit(cache=True, parallel=True)
def mean_field_sweep(P, order, cptr, node, pair, indptr, nbr, ntab, loglik) -> float:
    """One sweep of the mean-field fixed point over the colour classes: ``P[i, a] ∝
    exp(node[i, a] + L[i, a] + sum_{j ~ i} sum_b P[j, b] pair[e, a, b])`` (the mean-field
    self-consistency condition, Celeux, Forbes & Peyrard 2003). A ``-inf`` pair entry met
    with positive probability counts as a forbidden term. Returns the largest change of a
    probability."""
    n, q = P.shape
    change = np.zeros(n)
    for c in range(cptr.size - 1):
        lo, hi = cptr[c], cptr[c + 1]
        for b in prange((hi - lo + BLOCK - 1) // BLOCK):
            w = np.empty(q)
            bad = np.empty(q, np.int64)
            for k in range(lo + b * BLOCK, min(hi, lo + (b + 1) * BLOCK)):
                i = order[k]
                r = i if node.shape[0] > 1 else 0
                for a in range(q):
                    v, nb = node[r, a], 0
                    if v == -np.inf:
                        v, nb = 0.0, 1
                    if loglik[i, a] == -np.inf:
                        nb += 1
                    else:
                        v += loglik[i, a]
                    for kk in range(indptr[i], indptr[i + 1]):
                        j, t = nbr[kk], ntab[kk]
                        for s in range(q):
                            p = pair[t, a, s]
                            if p == -np.inf:
                                nb += P[j, s] > 0.0
                            else:
                                v += P[j, s] * p
                    w[a], bad[a] = v, nb
                _normalise(w, bad)
                d = 0.0
                for a in range(q):
                    d = max(d, abs(w[a] - P[i, a]))
                    P[i, a] = w[a]
                change[i] = d
    return change.max()


@njit(inline="always", cache=True)
def _find(parent, i) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True)
def swendsen_wang_sweep(x, field, edges, etab, p_bond, u_bond, u_cluster) -> None:
    """One Swendsen-Wang sweep with an external field (Higdon 1998): bond ``e`` joins equal
    neighbours when ``u_bond[e] < p_bond[etab[e]]``; each cluster (rooted at its least
    node ``r``) draws its state from ``exp(sum_{i in C} field[i, a])`` at ``u_cluster[r]``.
    ``field`` (n, q) holds every per-node term, the data's included."""
    n, q = field.shape
    parent = np.arange(n)
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        if x[i] == x[j] and u_bond[e] < p_bond[etab[e]]:
            ri, rj = _find(parent, i), _find(parent, j)
            parent[max(ri, rj)] = min(ri, rj)
    W = np.zeros((n, q))
    bad = np.zeros((n, q), np.int64)
    for i in range(n):
        r = _find(parent, i)
        parent[i] = r
        for a in range(q):
            if field[i, a] == -np.inf:
                bad[r, a] += 1
            else:
                W[r, a] += field[i, a]
    w = np.empty(q)
    new = np.zeros(n, np.int64)
    for r in range(n):
        if parent[r] != r:
            continue
        for a in range(q):
            w[a] = W[r, a]
        _normalise(w, bad[r])
        target, cum, pick = u_cluster[r], 0.0, q - 1
        for a in range(q):
            cum += w[a]
            if target < cum and w[a] > 0.0:
                pick = a
                break
        while w[pick] == 0.0:
            pick -= 1
        new[r] = pick
    for i in range(n):
        x[i] = new[parent[i]]
