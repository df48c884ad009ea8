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
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from mrfpe.threads import configure_vector_width

configure_vector_width()  # before our first @njit, as mrfpe.models.simulate does

__all__ = ["BLOCK", "conditionals", "gibbs_sweep", "icm_sweep", "log_pseudolikelihood",
           "mean_field_sweep", "swendsen_wang_sweep"]

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


@njit(cache=True, parallel=True)
def gibbs_sweep(x, order, cptr, node, pair, indptr, nbr, ntab, loglik, u, acc,
                accumulate) -> None:
    """One chequerboard Gibbs sweep of labels ``x`` (n,) over the colour classes
    ``order[cptr[c]:cptr[c + 1]]``; node ``i`` draws by inverse CDF at ``u[i]``. With
    ``accumulate``, its conditional probabilities are added to ``acc[i]`` (n, q)."""
    q = loglik.shape[1]
    for c in range(cptr.size - 1):
        lo, hi = cptr[c], cptr[c + 1]
        for b in prange((hi - lo + BLOCK - 1) // BLOCK):
            w = np.empty(q)
            bad = np.empty(q, np.int64)
            for k in range(lo + b * BLOCK, min(hi, lo + (b + 1) * BLOCK)):
                i = order[k]
                _log_weights(i, x, node, pair, indptr, nbr, ntab, loglik, w, bad)
                _normalise(w, bad)
                if accumulate:
                    for a in range(q):
                        acc[i, a] += w[a]
                target, cum, pick = u[i], 0.0, q - 1
                for a in range(q):
                    cum += w[a]
                    if target < cum and w[a] > 0.0:
                        pick = a
                        break
                while w[pick] == 0.0:  # u rounded past the last state of positive weight
                    pick -= 1
                x[i] = pick


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
def log_pseudolikelihood(x, node, pair, indptr, nbr, ntab) -> float:
    """Besag's (1975) log pseudolikelihood ``sum_i log p(x_i | x_N_i)`` of the labels ``x``
    from the MRF's tables (no data term): the value of the MRF's ``"pl"`` estimator, in one
    pass over the nodes (``-inf`` where a label is forbidden given its neighbours)."""
    q = node.shape[1]
    w = np.empty(q)
    total = 0.0
    for i in range(x.size):
        r = i if node.shape[0] > 1 else 0
        m = -np.inf
        for a in range(q):
            v = node[r, a]
            for k in range(indptr[i], indptr[i + 1]):
                v += pair[ntab[k], a, x[nbr[k]]]
            w[a] = v
            if v > m:
                m = v
        if w[x[i]] == -np.inf:
            return -np.inf
        s = 0.0
        for a in range(q):
            s += np.exp(w[a] - m)
        total += w[x[i]] - m - np.log(s)
    return total


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
