"""Exact reference for hidden Potts fields on narrow lattices: a transfer matrix over columns.

Written for the tests, independently of mrfpe's code: the Potts model on an ``H x W``
lattice (first-order, or second-order with ``diagonal=True``), free boundary,

    ``log phi(x) = coupling sum_{i ~ j} [x_i = x_j] + sum_i field[x_i] + sum_i L[i, x_i]``,

``L[i, a]`` the emission's log-density of node ``i``'s observation in state ``a`` (node
``r * W + c``). A column of height ``H`` has ``q^H`` states; the forward-backward
recursion over the ``W`` columns gives ``log Z`` (with or without the data) and every
node's marginal ``p(x_i = a | y)`` exactly, so that

    ``log p(y | coupling, field, emission) = log Z(with L) - log Z(without L)``.

:func:`brute_force` enumerates every configuration of a tiny lattice: the check of the
reference itself.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.special import logsumexp


def column_states(H: int, q: int) -> np.ndarray:
    """(q^H, H): every column configuration, row r in digit r."""
    return np.array(list(itertools.product(range(q), repeat=H)))[:, ::-1].copy()


def _intra(cols: np.ndarray, coupling: float, field: np.ndarray) -> np.ndarray:
    """(S,): vertical-edge and field log-potential of each column state."""
    same = (cols[:, 1:] == cols[:, :-1]).sum(axis=1)
    return coupling * same + field[cols].sum(axis=1)


def _inter(cols: np.ndarray, coupling: float, diagonal: bool) -> np.ndarray:
    """(S, S): horizontal (and diagonal) edges between a column and the next."""
    a, b = cols[:, None, :], cols[None, :, :]
    same = (a == b).sum(axis=2)
    if diagonal:  # (r, c)-(r+1, c+1) and (r+1, c)-(r, c+1)
        same = same + (a[:, :, :-1] == b[:, :, 1:]).sum(axis=2) \
            + (a[:, :, 1:] == b[:, :, :-1]).sum(axis=2)
    return coupling * same


def forward_backward(H: int, W: int, q: int, coupling: float, field, L=None,
                     diagonal: bool = False) -> tuple[float, np.ndarray]:
    """``(log Z, marginals (H*W, q))`` of the Potts field with node log-factors ``L``."""
    field = np.zeros(q) if field is None else np.asarray(field, float)
    cols = column_states(H, q)
    S = cols.shape[0]
    L = np.zeros((H * W, q)) if L is None else np.asarray(L, float)
    node = np.empty((W, S))
    base = _intra(cols, coupling, field)
    for c in range(W):
        rows = np.arange(H) * W + c
        node[c] = base + L[rows[None, :], cols].sum(axis=1)
    T = _inter(cols, coupling, diagonal)
    alpha = np.empty((W, S))
    alpha[0] = node[0]
    for c in range(1, W):
        alpha[c] = logsumexp(alpha[c - 1][:, None] + T, axis=0) + node[c]
    beta = np.zeros((W, S))
    for c in range(W - 2, -1, -1):
        beta[c] = logsumexp(T + (node[c + 1] + beta[c + 1])[None, :], axis=1)
    log_z = float(logsumexp(alpha[-1]))
    marg = np.zeros((H * W, q))
    for c in range(W):
        p = np.exp(alpha[c] + beta[c] - log_z)
        for r in range(H):
            marg[r * W + c] = np.bincount(cols[:, r], weights=p, minlength=q)
    return log_z, marg


def log_marginal_likelihood(H: int, W: int, q: int, coupling: float, field, L,
                            diagonal: bool = False) -> float:
    """``log p(y | coupling, field, emission)``: ``log Z`` with the data's factors minus without."""
    with_data, _ = forward_backward(H, W, q, coupling, field, L, diagonal)
    prior, _ = forward_backward(H, W, q, coupling, field, None, diagonal)
    return with_data - prior


def brute_force(H: int, W: int, q: int, coupling: float, field, L=None,
                diagonal: bool = False) -> tuple[float, np.ndarray]:
    """``(log Z, marginals)`` by enumerating all ``q^(H W)`` configurations."""
    field = np.zeros(q) if field is None else np.asarray(field, float)
    n = H * W
    L = np.zeros((n, q)) if L is None else np.asarray(L, float)
    edges = []
    for r in range(H):
        for c in range(W):
            i = r * W + c
            if c + 1 < W:
                edges.append((i, i + 1))
            if r + 1 < H:
                edges.append((i, i + W))
            if diagonal and r + 1 < H and c + 1 < W:
                edges.append((i, i + W + 1))
            if diagonal and r + 1 < H and c >= 1:
                edges.append((i, i + W - 1))
    e = np.array(edges)
    X = np.array(list(itertools.product(range(q), repeat=n)))
    lw = coupling * (X[:, e[:, 0]] == X[:, e[:, 1]]).sum(axis=1) + field[X].sum(axis=1) \
        + L[np.arange(n)[None, :], X].sum(axis=1)
    log_z = float(logsumexp(lw))
    p = np.exp(lw - log_z)
    marg = np.stack([(p[:, None] * (X == a)).sum(axis=0) for a in range(q)], axis=1)
    return log_z, marg


def gaussian_loglik(y: np.ndarray, means, sd) -> np.ndarray:
    """(n, q): ``log N(y_i; mean_a, sd_a^2)``, written out."""
    y = np.asarray(y, float).reshape(-1, 1)
    means = np.asarray(means, float)[None]
    sd = np.broadcast_to(np.asarray(sd, float), means.shape)
    return -0.5 * ((y - means) / sd) ** 2 - np.log(sd) - 0.5 * np.log(2 * np.pi)


def forward_backward_batch(H: int, W: int, q: int, coupling: float, field, L: np.ndarray,
                           diagonal: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """:func:`forward_backward` for a batch of node log-factors ``L`` (K, H*W, q):
    ``(log Z (K,), marginals (K, H*W, q))``."""
    field = np.zeros(q) if field is None else np.asarray(field, float)
    cols = column_states(H, q)
    L = np.asarray(L, float)
    K, S = L.shape[0], cols.shape[0]
    base = _intra(cols, coupling, field)
    node = np.empty((W, K, S))
    for c in range(W):
        rows = np.arange(H) * W + c
        node[c] = base[None] + L[:, rows[None, :], cols].sum(axis=2)
    T = _inter(cols, coupling, diagonal)
    alpha = np.empty((W, K, S))
    alpha[0] = node[0]
    for c in range(1, W):
        alpha[c] = logsumexp(alpha[c - 1][:, :, None] + T[None], axis=1) + node[c]
    beta = np.zeros((W, K, S))
    for c in range(W - 2, -1, -1):
        beta[c] = logsumexp(T[None] + (node[c + 1] + beta[c + 1])[:, None, :], axis=2)
    log_z = logsumexp(alpha[-1], axis=1)
    marg = np.zeros((K, H * W, q))
    for c in range(W):
        p = np.exp(alpha[c] + beta[c] - log_z[:, None])  # (K, S)
        for r in range(H):
            marg[:, r * W + c] = p @ (cols[:, r][:, None] == np.arange(q)[None]).astype(float)
    return log_z, marg


def log_z_product(H: int, W: int, q: int, coupling: float, field=None, L=None) -> float:
    """``log Z`` of the first-order Potts field by the transfer matrix in product form.

    The horizontal transfer matrix factorises over rows, ``exp(β Σ_r [a_r = b_r]) = Π_r
    M[a_r, b_r]`` with ``M = 1 + (e^β - 1) I``, so a column vector times it is ``H``
    products with the ``q x q`` matrix ``M`` along the axes of the ``(q,) * H`` array:
    ``O(H q^(H+1))`` per column instead of ``O(q^(2H))``. Scaled at every column.
    """
    field = np.zeros(q) if field is None else np.asarray(field, float)
    cols = column_states(H, q)
    base = _intra(cols, coupling, field)
    M = np.ones((q, q)) + np.expm1(coupling) * np.eye(q)
    total, a = 0.0, None
    for c in range(W):
        node = base.copy()
        if L is not None:
            node += np.asarray(L, float)[(np.arange(H) * W + c)[None, :], cols].sum(axis=1)
        top = node.max()
        e = np.exp(node - top)
        if a is None:
            a = e
        else:
            t = a.reshape((q,) * H)  # one axis per row (M is the same for every row)
            for ax in range(H):
                t = np.moveaxis(np.tensordot(t, M, axes=([ax], [0])), -1, ax)
            a = t.reshape(-1) * e
        s = a.sum()
        a = a / s
        total += np.log(s) + top
    return float(total)


def coupling_posterior(y, H: int, W: int, q: int, means, sd, grid) -> tuple[float, float]:
    """``(mean, sd)`` of the exact posterior of the Potts coupling (fields 0) under a flat
    prior on ``grid``, a Gaussian emission known: ``p(y | β) = Z(β; L) / Z(β)`` by
    :func:`log_z_product` at every grid point."""
    L = gaussian_loglik(np.ravel(y), means, sd)
    grid = np.asarray(grid, float)
    lp = np.array([log_z_product(H, W, q, b, None, L) - log_z_product(H, W, q, b)
                   for b in grid])
    w = np.exp(lp - logsumexp(lp))
    m = float(w @ grid)
    return m, float(np.sqrt(w @ (grid - m) ** 2))
