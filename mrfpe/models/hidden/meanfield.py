"""Mean-field-like approximations of a hidden MRF (Celeux, Forbes & Peyrard 2003).

Fixing every node's neighbours at a configuration ``x̃`` -- hard labels, or label
probabilities ``P̃`` (n, q) for the mean field -- makes the labels independent, each
with the conditional

    ``log p(x_i = a | x̃_N_i; θ) = G̃_i[a] . psi(θ) - log sum_b exp(G̃_i[b] . psi(θ))``,
    ``G̃_i[a] = node[i, a] + sum_{e = (i, j)} sum_b P̃_j(b) pair[e, a, b]``

(the design's conditional rows with neighbours' states replaced by their
probabilities; one-hot ``P̃`` gives Besag's pseudolikelihood rows exactly). Then
(the "mean field-like approximations" of Celeux et al. 2003)

    ``log p(y | θ, φ) ≈ sum_i log sum_a p(y_i | a, φ) p(x_i = a | x̃_N_i; θ)``,

the mean-field-like approximation of the marginal likelihood, whose EM steps are
closed in form for the emission and a weighted pseudolikelihood for the MRF.
:func:`soft_design` builds ``G̃``; :func:`approx_log_lik` evaluates the approximation,
batched over parameter vectors.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from mrfpe.models.design import Design, allowed_dot

__all__ = ["approx_log_lik", "log_conditionals", "soft_design", "weighted_pl"]


def soft_design(design: Design, P: np.ndarray) -> np.ndarray:
    """``G̃`` (n, q, P): every node's conditional design with its neighbours' states
    replaced by their probabilities ``P`` (n, q)."""
    g = design.graph
    P = np.asarray(P, dtype=np.float64)
    G = np.array(design.node_rows(), dtype=np.float64)
    e = g.edges
    if design.pair_per_edge:
        pair = design.pair  # (E, q, q, F)
        np.add.at(G, e[:, 0], np.einsum("eb,eabf->eaf", P[e[:, 1]], pair))
        np.add.at(G, e[:, 1], np.einsum("eb,ebaf->eaf", P[e[:, 0]], pair))
        return G
    for t in range(g.n_edge_types):  # soft neighbour counts per edge type, then the tables
        on = g.edge_type == t
        i, j = e[on, 0], e[on, 1]
        C = np.zeros((g.n_nodes, design.q))
        np.add.at(C, i, P[j])
        np.add.at(C, j, P[i])
        G += np.einsum("ib,abf->iaf", C, design.pair[t])
    return G


def log_conditionals(G: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """``log p(x_i = a | x̃_N_i)`` (N, n, q) for feature vectors ``psi`` (N, P)."""
    n, q, F = G.shape
    psi = np.atleast_2d(psi)
    logits = allowed_dot(psi, G.reshape(n * q, F)).reshape(psi.shape[0], n, q)
    with np.errstate(invalid="ignore"):
        out = logits - logsumexp(logits, axis=2, keepdims=True)
    return np.where(np.isnan(out), -np.inf, out)


def approx_log_lik(G: np.ndarray, psi: np.ndarray, loglik: np.ndarray,
                   observed: np.ndarray) -> np.ndarray:
    """``sum_{i observed} log sum_a exp(L[., i, a] + log p(x_i = a | x̃_N_i))`` (N,).

    ``loglik`` (N, n, q) are the emission's log-densities (row ``k`` at the ``k``-th
    parameter vector; one row broadcasts); missing nodes add nothing.
    """
    lc = log_conditionals(G, psi)
    with np.errstate(invalid="ignore"):
        per_node = logsumexp(lc + loglik, axis=2)  # (N, n)
    per_node = np.where(np.isnan(per_node), -np.inf, per_node)
    return per_node[:, observed].sum(axis=1)


def weighted_pl(G: np.ndarray, psi: np.ndarray, resp: np.ndarray) -> np.ndarray:
    """``sum_i sum_a resp[i, a] log p(x_i = a | x̃_N_i)`` (N,): the MRF part of EM's
    expected complete log-likelihood under the approximation (Celeux et al. 2003's M-step);
    with one-hot ``resp`` and ``G̃`` of the same labels, Besag's log pseudolikelihood."""
    lc = log_conditionals(G, psi)
    with np.errstate(invalid="ignore"):
        terms = np.where(resp[None] > 0, resp[None] * lc, 0.0)
    return terms.sum(axis=(1, 2))
