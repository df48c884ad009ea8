"""The auto-normal pseudolikelihoods: Besag's PL, its codings, and the block pseudolikelihood.

* ``"pl"`` -- Besag's pseudolikelihood ``sum_i log N(x_i; E[x_i | x_-i], 1/tau)``.
  With ``u = x - mu`` the conditional residual is ``e = (I - sum_t beta_t W_t) u``,
  which is linear in the vector ``b(theta) = (a, -beta_1 a, ..., -beta_T a)`` where
  ``u = C a``, ``C = [x - x0, 1, Z - z0]``. So ``sum_i e_i^2 = b' S b`` with ``S =
  G'G``, ``G = [C, W_1 C, ..., W_T C]`` precomputed once (neighbour sums per
  coupling type): a batch costs ``O(N P^2)``, independent of the lattice size.
* ``"coding"`` -- the same over one colour class of the graph's proper
  colouring (Besag 1974, Sec. 6.1); the codings sum to the PL.
* ``"block"`` -- ``sum_B log N(x_B; mu_B - Q_BB^{-1} Q_B,rest (x_rest - mu_rest), Q_BB^{-1})``
  over tiles ``(bh, bw)`` (lattice) or a node partition (graph). The residual of
  block ``B`` is ``x_B - E[x_B | rest] = A_BB^{-1} e_B`` (``A = I - sum beta_t W_t``),
  so each block adds ``m/2 log tau + 1/2 log det A_BB - tau/2 e_B' A_BB^{-1} e_B``.
  Blocks with the same internal structure (all interior tiles) share one
  ``m x m`` factorisation per theta, and their second moments are summed once.

Positive definiteness is decided first, by
:class:`~mrfpe.models.gaussian.structure.CARStructure` (see there for what it costs).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mrfpe.models.gaussian.base import LOG_2PI, GaussianTarget
from mrfpe.models.gaussian.structure import CARStructure
from mrfpe.targets.base import as_theta_batch

__all__ = ["GaussianBlockTarget", "GaussianPLTarget"]


class GaussianPLTarget(GaussianTarget):
    """Pseudolikelihood (all nodes) or a coding likelihood (one colour class ``nodes``).

    ``sum_obs sum_{i in nodes} [1/2 log(tau / 2 pi) - tau/2 e_i^2]`` with
    ``sum e_i^2 = b' S b`` (see the module docstring): one small quadratic form per theta.
    """

    calibrated = False

    def __init__(self, *, nodes: np.ndarray | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        G = self._G()
        if nodes is not None:
            G = G[:, np.asarray(nodes, dtype=np.int64)]
        self.n_terms = int(G.shape[0] * G.shape[1])
        Gf = G.reshape(-1, G.shape[2])
        self._S = Gf.T @ Gf

    def _row_bytes(self) -> float:
        return 8.0 * 4 * self._S.shape[0]

    def residual_sum_of_squares(self, theta: Any) -> np.ndarray:
        """``sum e_i^2`` (N,): the conditional residuals' sum of squares (no PD check)."""
        b = self._b(as_theta_batch(theta, self.ndim))
        return np.einsum("np,pq,nq->n", b, self._S, b)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        tau = self.split(theta)[2]
        b = self._b(theta)
        rss = np.maximum(np.einsum("np,pq,nq->n", b, self._S, b), 0.0)
        return 0.5 * self.n_terms * (np.log(tau) - LOG_2PI) - 0.5 * tau * rss


class GaussianBlockTarget(GaussianTarget):
    """Block pseudolikelihood: ``sum_B log p(x_B | x_rest)`` (see the module docstring)."""

    calibrated = False

    def __init__(self, *, blocks: Sequence[np.ndarray], **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
        G = self._G()
        M, _, Pp = G.shape
        self._groups = []
        for nodes, Wloc in _block_groups(self.structure, self.blocks):
            m = nodes.shape[1]
            GB = G[:, nodes].reshape(-1, m, Pp)  # (R, m, P')
            R = GB.shape[0]
            if m * Pp <= R:  # summed second moments: cost independent of the number of blocks
                F = GB.reshape(R, m * Pp)
                S = (F.T @ F).reshape(m, Pp, m, Pp)
                self._groups.append(("moment", Wloc, R, S))
            else:
                self._groups.append(("direct", Wloc, R, np.ascontiguousarray(GB)))
        self.n_terms = M * self.structure.n

    @property
    def n_groups(self) -> int:
        """Distinct block structures (one ``m x m`` factorisation each per theta)."""
        return len(self._groups)

    def _row_bytes(self) -> float:
        total = 0.0
        for kind, Wloc, R, data in self._groups:
            m = Wloc.shape[1]
            total += 8.0 * (4 * m * m + (m * m * data.shape[1] if kind == "moment" else 2 * R * m))
        return total

    def _value(self, theta: np.ndarray) -> np.ndarray:
        tau = self.split(theta)[2]
        beta = self.split(theta)[1]
        b = self._b(theta)
        N = theta.shape[0]
        logdet = np.zeros(N)
        quad = np.zeros(N)
        for kind, Wloc, R, data in self._groups:
            m = Wloc.shape[1]
            A = np.eye(m)[None] - np.einsum("nt,tij->nij", beta, Wloc)
            sign, ld = np.linalg.slogdet(A)
            ld = np.where(sign > 0, ld, -np.inf)
            Ainv = np.linalg.inv(A)
            logdet += R * ld
            if kind == "moment":
                X = np.tensordot(data, b, axes=([3], [1]))  # (m, P', m, N)
                Y = np.einsum("ipjn,np->nij", X, b)
                quad += np.einsum("nij,nij->n", Ainv, Y)
            else:
                E = np.tensordot(data, b, axes=([2], [1]))  # (R, m, N)
                Y = np.einsum("nij,rjn->rin", Ainv, E)
                quad += np.einsum("rin,rin->n", E, Y)
        quad = np.maximum(quad, 0.0)
        return (0.5 * self.n_terms * (np.log(tau) - LOG_2PI) + 0.5 * logdet
                - 0.5 * tau * quad)

    def describe(self) -> dict:
        return {**super().describe(), "n_block_structures": self.n_groups}


def _block_groups(st: CARStructure, blocks: Sequence[np.ndarray]
                  ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Blocks grouped by size and internal structure: ``[(nodes (nb, m), W_BB (T, m, m))]``."""
    n = st.n
    block_of = np.full(n, -1, dtype=np.int64)
    pos_of = np.zeros(n, dtype=np.int64)
    for b, nodes in enumerate(blocks):
        block_of[nodes] = b
        pos_of[nodes] = np.arange(nodes.size)
    e = st.graph.edges
    internal = np.flatnonzero(block_of[e[:, 0]] == block_of[e[:, 1]])
    p, q = pos_of[e[internal, 0]], pos_of[e[internal, 1]]
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    tt = st.edge_coupling[internal]
    bb = block_of[e[internal, 0]]
    order = np.lexsort((tt, hi, lo, bb))
    rows = np.stack([lo, hi, tt], axis=1)[order]
    parts = np.split(rows, np.cumsum(np.bincount(bb[order], minlength=len(blocks)))[:-1])
    groups: dict[tuple[int, bytes], list[int]] = {}
    for b, nodes in enumerate(blocks):
        groups.setdefault((nodes.size, parts[b].tobytes()), []).append(b)
    out = []
    for (m, _), ids in groups.items():
        Wloc = np.zeros((st.T, m, m))
        r = parts[ids[0]]
        Wloc[r[:, 2], r[:, 0], r[:, 1]] = 1.0
        Wloc[r[:, 2], r[:, 1], r[:, 0]] = 1.0
        out.append((np.stack([blocks[b] for b in ids]), Wloc))
    return out
