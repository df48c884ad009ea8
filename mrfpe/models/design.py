"""The compiled form of a discrete pairwise MRF on one graph: designs and conditional rows.

Every discrete model of :mod:`mrfpe.models` reduces, once the graph and the
covariates are known, to a *design*: a feature map ``psi(theta)`` (N, P) and
fixed arrays

* ``node`` ``(n_nodes or 1, q, P)``: ``log phi_i(a) = node[i, a] . psi``;
* ``pair`` ``(n_edge_types or n_edges, q, q, P)``: ``log phi_e(a, b) = pair[e, a, b] . psi``
  (symmetric in ``a, b``).

For a log-linear model ``psi(theta) = theta`` and the arrays are the terms'
features (:mod:`mrfpe.models.terms`); for a general potential ``psi`` is the
vector of its tables and the arrays are indicators. So the unnormalised
log-likelihood is ``S(x) . psi`` with ``S(x) = sum_i node[i, x_i] + sum_e
pair[e, x_i, x_j]`` (:meth:`Design.statistics`), and every conditional the
estimators need is *linear* in ``psi``: node ``i``'s full conditional
(Besag 1974, eq. 4.23-4.24 of the thesis) is

    ``log p(x_i = a | x_N_i) = G_i[a] . psi - log sum_b exp(G_i[b] . psi)``,
    ``G_i[a] = node[i, a] + sum_{e = (i, j)} pair[e, a, x_j]``,

and a block's (Besag 1974 Sec. 6; Asuncion et al. 2010) is the same with
``a`` running over the block's joint states. :meth:`Design.conditional_rows`
and :meth:`Design.block_rows` return these ``G`` matrices with the observed
state, keeping only *distinct* rows and their counts where the features are
shared, so that evaluating a pseudolikelihood is one matrix product whose size
does not grow with the lattice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from mrfpe.budget import check_memory
from mrfpe.models.graph import Graph

__all__ = ["MAX_BLOCK_CONFIGURATIONS", "ConditionalRows", "Design", "allowed_dot",
           "check_design_memory", "softmax_rows_log_prob", "split_forbidden", "unique_rows"]

#: Largest number of joint states of one block that block pseudolikelihood enumerates.
MAX_BLOCK_CONFIGURATIONS = 1 << 12


def check_design_memory(q: int, n_features: int, node_rows: int, pair_rows: int,
                        per_edge: bool = False) -> None:
    """Refuse, before allocating, a design of ``node_rows q + pair_rows q^2`` feature vectors
    over the memory budget (compiling holds about four copies: parts, whole, symmetry check)."""
    nbytes = 4 * 8.0 * (node_rows * q + pair_rows * float(q) ** 2) * n_features
    tables = f"{pair_rows} pair table{'s' if pair_rows > 1 else ''}"
    check_memory(nbytes, f"the model with n_states={q} ({tables}{' (one per edge)' * per_edge} "
                         f"of {q}^2 state pairs, {n_features} feature{'s' * (n_features != 1)})",
                 "use fewer states (n_states)" + (" or a smaller graph (shape)" * per_edge))


def split_forbidden(psi: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``(psi with its -inf entries set to 0, their (N, P) 0/1 mask)``; mask None if none.

    ``-inf`` (a forbidden state or pair) is kept apart from the finite values, not replaced
    by a large negative number, which a finite log-potential could meet or outweigh.
    """
    neg = np.isneginf(psi)
    if not neg.any():
        return psi, None
    return np.where(neg, 0.0, psi), neg.astype(np.float64)


def allowed_dot(psi: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``S_u @ psi_n`` (N, U) for feature counts ``S`` (U, P): ``-inf`` where ``S_u`` uses a
    ``-inf`` (forbidden) entry of ``psi_n``, never ``0 * -inf = NaN``."""
    psi = np.atleast_2d(np.asarray(psi, dtype=np.float64))
    S = np.atleast_2d(np.asarray(S, dtype=np.float64))
    fin, forbid = split_forbidden(psi)
    out = fin @ S.T
    if forbid is not None:
        out[forbid @ (S != 0).T > 0] = -np.inf
    return out


def unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct rows of a 2-D array: ``(first index of each, counts, inverse)``.

    Compares raw bytes (a void view), which is several times faster than
    ``np.unique(axis=0)`` on wide rows.
    """
    rows = np.ascontiguousarray(rows)
    if rows.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    view = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel()
    _, first, inverse, counts = np.unique(view, return_index=True, return_inverse=True,
                                          return_counts=True)
    return first.astype(np.int64), counts.astype(np.int64), inverse.reshape(-1).astype(np.int64)


class ConditionalRows:
    """Rows of a composite likelihood ``sum_r w_r log softmax(G_r psi)[obs_r]``.

    Kept as the differences ``D_r = G_r[k] - G_r[obs_r]`` over the ``K - 1``
    alternatives other than the observed one, so that a row's term is
    ``-log(1 + sum_k exp(D_rk . psi))``: one GEMM of ``(R (K-1), P) @ (P, N)``
    and no gather (a softplus for ``K = 2``).

    Parameters
    ----------
    G : ndarray (R, K, P)
        Per row, the design of each of its ``K`` alternatives (states of a node,
        or joint states of a block).
    obs : ndarray (R,) int64
        The observed alternative.
    weight : ndarray (R,) float64
        How many times the row occurs.
    keep_observed : bool
        Keep ``G_obs`` (R, P), the observed alternative's design, where ``psi`` may hold
        ``-inf``: a row whose observed alternative is forbidden is then ``-inf``.
    """

    def __init__(self, G: np.ndarray, obs: np.ndarray, weight: np.ndarray,
                 keep_observed: bool = False) -> None:
        G = np.asarray(G, dtype=np.float64)
        R, K, P = G.shape
        obs = np.asarray(obs, dtype=np.int64)
        others = np.arange(K)[None, :] != obs[:, None]  # (R, K)
        D = G[others].reshape(R, K - 1, P) - G[np.arange(R), obs][:, None, :]
        self.D = np.ascontiguousarray(D)
        self.obs = obs
        self.weight = np.asarray(weight, dtype=np.float64)
        self.n_alternatives = K
        self.G_obs = np.ascontiguousarray(G[np.arange(R), obs]) if keep_observed else None
        for arr in (self.D, self.obs, self.weight, self.G_obs):
            if arr is not None:
                arr.setflags(write=False)

    @property
    def n_rows(self) -> int:
        return int(self.D.shape[0])


def softmax_rows_log_prob(groups: Sequence[ConditionalRows], psi: np.ndarray,
                          chunk: int = 1 << 15) -> np.ndarray:
    """``sum_groups sum_r w_r log softmax(G_r psi)[obs_r]`` (N,), from the differences ``D``.

    ``log softmax(G psi)[obs] = -log(1 + sum_k exp(D_k . psi))``, evaluated stably
    (``m = max(0, max_k D_k . psi)``) with one GEMM per chunk of rows. ``-inf`` entries
    of ``psi`` (forbidden) are handled apart (:func:`split_forbidden`): a forbidden
    alternative has weight 0 and a row whose observed alternative is forbidden is ``-inf``.
    """
    psi, forbid = split_forbidden(np.asarray(psi, dtype=np.float64))
    out = np.zeros(psi.shape[0])
    psiT = np.ascontiguousarray(psi.T)
    fT = None if forbid is None else np.ascontiguousarray(forbid.T)
    for g in groups:
        K1 = g.D.shape[1]
        if K1 == 0:
            continue
        if fT is not None and g.G_obs is None:
            raise ValueError("psi holds -inf (forbidden) entries, but these conditional rows "
                             "were built without their observed designs (keep_observed=True)")
        step = max(1, chunk // K1)
        for a in range(0, g.n_rows, step):
            out -= g.weight[a:a + step] @ _rows_lse(g, slice(a, a + step), psiT, fT)
    return out


def _rows_lse(g: ConditionalRows, sl: slice, psiT: np.ndarray,
              fT: np.ndarray | None) -> np.ndarray:
    """``log(1 + sum_k exp(D_k @ psi))`` (r, N) of the rows ``sl``: forbidden alternatives
    left out, ``+inf`` where the observed alternative is forbidden."""
    D = g.D[sl]
    r, K1, P = D.shape
    n = psiT.shape[1]
    d = (D.reshape(r * K1, P) @ psiT).reshape(r, K1, n)
    obs_bad = None
    if fT is not None:  # which alternatives use a forbidden entry: G_k = D_k + G_obs != 0
        G_obs = g.G_obs[sl]
        obs_bad = (G_obs != 0) @ fT > 0
        uses = ((D + G_obs[:, None, :]) != 0).reshape(r * K1, P)
        d[(uses @ fT).reshape(r, K1, n) > 0] = -np.inf
    if K1 == 1:
        lse = np.logaddexp(0.0, d[:, 0])
    else:
        m = np.maximum(d.max(axis=1), 0.0)
        lse = m + np.log(np.exp(-m) + np.exp(d - m[:, None, :]).sum(axis=1))
    if obs_bad is not None:
        lse[obs_bad] = np.inf
    return lse


class Design:
    """A discrete pairwise MRF compiled on one graph (see the module docstring).

    Parameters
    ----------
    graph : Graph
    n_states : int
    node : (n_nodes or 1, q, P)
    pair : (n_edge_types or n_edges, q, q, P)
    psi : callable (N, d) -> (N, P)
        The feature map; ``None`` for the identity (log-linear models).
    pair_per_edge : bool
        ``pair`` has one row per edge (edge covariates) rather than per edge type;
        said explicitly, since the two lengths can coincide.
    """

    def __init__(self, graph: Graph, n_states: int, node: np.ndarray, pair: np.ndarray,
                 psi: Callable[[np.ndarray], np.ndarray] | None = None, *,
                 pair_per_edge: bool = False) -> None:
        self.graph = graph
        self.q = int(n_states)
        node = np.ascontiguousarray(node, dtype=np.float64)
        pair = np.ascontiguousarray(pair, dtype=np.float64)
        if node.ndim != 3 or node.shape[0] not in (1, graph.n_nodes) or node.shape[1] != self.q:
            raise ValueError(f"node design must be (1 or {graph.n_nodes}, {self.q}, P); got "
                             f"{node.shape}")
        rows = graph.n_edges if pair_per_edge else graph.n_edge_types
        if (pair.ndim != 4 or pair.shape[0] != rows
                or pair.shape[1:3] != (self.q, self.q) or pair.shape[3] != node.shape[2]):
            raise ValueError(f"pair design must be ({rows}, {self.q}, {self.q}, "
                             f"{node.shape[2]}); got {pair.shape}")
        if not np.allclose(pair, pair.transpose(0, 2, 1, 3)):
            raise ValueError("pair features must be symmetric in the two states (an undirected "
                             "edge has no order)")
        for a in (node, pair):
            a.setflags(write=False)
        self.node, self.pair = node, pair
        self.node_shared = node.shape[0] == 1 and graph.n_nodes > 1
        self.pair_per_edge = bool(pair_per_edge)
        self._psi = psi

    @property
    def n_features(self) -> int:
        return int(self.node.shape[2])

    @property
    def may_forbid(self) -> bool:
        """``psi`` may hold ``-inf`` (forbidden) entries: a general potential's tables."""
        return self._psi is not None

    def psi(self, theta: np.ndarray) -> np.ndarray:
        """The feature map ``psi(theta)`` (N, P)."""
        theta = np.asarray(theta, dtype=np.float64)
        return theta if self._psi is None else np.asarray(self._psi(theta), dtype=np.float64)

    # -- per-edge views --------------------------------------------------------------------------
    def edge_pair(self) -> np.ndarray:
        """``(n_edges, q, q, P)`` pair features of every edge (a view where shared)."""
        if self.pair_per_edge:
            return self.pair
        return self.pair[self.graph.edge_type]

    def node_rows(self) -> np.ndarray:
        """``(n_nodes, q, P)`` node features of every node (a broadcast view where shared)."""
        return np.broadcast_to(self.node, (self.graph.n_nodes, *self.node.shape[1:]))

    # -- statistics and tables -------------------------------------------------------------------
    def statistics(self, x: np.ndarray) -> np.ndarray:
        """``S(x)`` of each configuration (M, n_nodes) -> (M, P)."""
        x = np.asarray(x, dtype=np.int64).reshape(-1, self.graph.n_nodes)
        e = self.graph.edges
        out = np.empty((x.shape[0], self.n_features))
        for m, xm in enumerate(x):
            if self.node_shared:
                s = np.bincount(xm, minlength=self.q) @ self.node[0]
            else:
                s = self.node[np.arange(self.graph.n_nodes), xm].sum(axis=0)
            a, b = xm[e[:, 0]], xm[e[:, 1]]
            if self.pair_per_edge:
                s = s + self.pair[np.arange(e.shape[0]), a, b].sum(axis=0)
            else:
                key = (self.graph.edge_type * self.q + a) * self.q + b
                cnt = np.bincount(key, minlength=self.graph.n_edge_types * self.q * self.q)
                s = s + cnt @ self.pair.reshape(-1, self.n_features)
            out[m] = s
        return out

    def tables(self, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Log-potential tables at each ``psi`` row: node (N, n|1, q), pair (N, T|E, q, q).

        An entry with a nonzero feature on a ``-inf`` (forbidden) entry of ``psi`` is
        ``-inf``; the finite entries of ``psi`` make the rest.
        """
        psi = np.atleast_2d(np.asarray(psi, dtype=np.float64))
        fin, forbid = split_forbidden(psi)
        node = np.einsum("iap,np->nia", self.node, fin)
        pair = np.einsum("tabp,np->ntab", self.pair, fin)
        if forbid is not None:
            node[np.einsum("iap,np->nia", (self.node != 0) * 1.0, forbid) > 0] = -np.inf
            pair[np.einsum("tabp,np->ntab", (self.pair != 0) * 1.0, forbid) > 0] = -np.inf
        return node, pair

    # -- conditional rows ------------------------------------------------------------------------
    def _neighbour_counts(self, x: np.ndarray, edge_mask: np.ndarray | None = None) -> np.ndarray:
        """``(M, n, T, q)`` int32: neighbours of each node per edge type and state."""
        M, n = x.shape
        T, q = self.graph.n_edge_types, self.q
        e, t = self.graph.edges, self.graph.edge_type
        if edge_mask is not None:
            e, t = e[edge_mask], t[edge_mask]
        out = np.empty((M, n, T, q), dtype=np.int32)
        for m, xm in enumerate(x):
            idx = np.concatenate([(e[:, 0] * T + t) * q + xm[e[:, 1]],
                                  (e[:, 1] * T + t) * q + xm[e[:, 0]]])
            out[m] = np.bincount(idx, minlength=n * T * q).reshape(n, T, q)
        return out

    def _per_node_G(self, x: np.ndarray, edge_mask: np.ndarray | None = None) -> np.ndarray:
        """``(M, n, q, P)``: every node's conditional design (only edges in ``edge_mask``)."""
        M, n = x.shape
        check_memory(16.0 * M * n * self.q * self.n_features, f"the conditional designs of "
                     f"{M} configuration(s) of {n} nodes ({self.q} states, {self.n_features} "
                     f"features)", "use fewer or smaller configurations")
        e = self.graph.edges
        eid = np.arange(e.shape[0]) if edge_mask is None else np.flatnonzero(edge_mask)
        pair = self.edge_pair()
        out = np.empty((M, n, self.q, self.n_features))
        for m, xm in enumerate(x):
            G = np.array(self.node_rows(), dtype=np.float64)
            i, j = e[eid, 0], e[eid, 1]
            np.add.at(G, i, pair[eid, :, xm[j]])  # (E', q, P): pair[e, a, x_j]
            np.add.at(G, j, pair[eid, xm[i], :])  # symmetric: pair[e, x_i, a]
            out[m] = G
        return out

    def conditional_rows(self, x: np.ndarray, nodes: np.ndarray | None = None) -> ConditionalRows:
        """Full conditionals of ``nodes`` (default all) in configurations ``x`` (M, n).

        Distinct ``(G_i, x_i)`` rows are kept once, with their counts, whenever
        the node and pair features are shared (no covariates).
        """
        x = np.asarray(x, dtype=np.int64).reshape(-1, self.graph.n_nodes)
        nodes = np.arange(self.graph.n_nodes) if nodes is None else np.asarray(nodes, np.int64)
        M = x.shape[0]
        obs = x[:, nodes].reshape(-1)
        if self.node_shared and not self.pair_per_edge:
            cnt = self._neighbour_counts(x)[:, nodes].reshape(M * nodes.size, -1)
            key = np.concatenate([cnt, obs[:, None].astype(np.int32)], axis=1)
            first, counts, _ = unique_rows(key)
            c = cnt[first].astype(np.float64).reshape(first.size, self.graph.n_edge_types,
                                                       self.q)
            G = self.node[0][None] + np.einsum("rtb,tabp->rap", c, self.pair)
            return ConditionalRows(np.ascontiguousarray(G), obs[first], counts.astype(float),
                                   self.may_forbid)
        G = self._per_node_G(x)[:, nodes].reshape(M * nodes.size, self.q, self.n_features)
        return ConditionalRows(G, obs, np.ones(obs.size), self.may_forbid)

    def block_rows(self, x: np.ndarray, blocks: Sequence[np.ndarray]) -> list[ConditionalRows]:
        """Block conditionals ``log p(x_B | x_rest)`` of each block (one group per block size).

        Parameters
        ----------
        x : (M, n) int
        blocks : sequence of node-id arrays, disjoint.
        """
        x = np.asarray(x, dtype=np.int64).reshape(-1, self.graph.n_nodes)
        n, q = self.graph.n_nodes, self.q
        block_of = np.full(n, -1, dtype=np.int64)
        pos_of = np.zeros(n, dtype=np.int64)
        for b, nodes in enumerate(blocks):
            block_of[nodes] = b
            pos_of[nodes] = np.arange(len(nodes))
        e = self.graph.edges
        internal = (block_of[e[:, 0]] == block_of[e[:, 1]]) & (block_of[e[:, 0]] >= 0)
        ext_G = self._per_node_G(x, ~internal)  # (M, n, q, P): node + crossing edges only
        pair = self.edge_pair()
        # group blocks by size and internal structure (local endpoints and edge type)
        ie_all = np.flatnonzero(internal)
        ie_all = ie_all[np.lexsort((pos_of[e[ie_all, 1]], pos_of[e[ie_all, 0]]))]
        by_block: dict[int, list[int]] = {}
        for k in ie_all[np.argsort(block_of[e[ie_all, 0]], kind="stable")]:
            by_block.setdefault(int(block_of[e[k, 0]]), []).append(int(k))
        signatures: dict[tuple, list[int]] = {}
        for b, nodes in enumerate(blocks):
            ie = by_block.get(b, [])
            sig = (len(nodes), *((int(pos_of[e[k, 0]]), int(pos_of[e[k, 1]]),
                                  int(self.graph.edge_type[k])) for k in ie))
            signatures.setdefault(sig, []).append(b)
        groups: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for sig, ids in signatures.items():
            m_size = sig[0]
            Y = _all_configurations(q, m_size)  # (K, m)
            nodes = np.stack([np.asarray(blocks[b], dtype=np.int64) for b in ids])  # (nb, m)
            Gext = ext_G[:, nodes]  # (M, nb, m, q, P)
            G = np.zeros((x.shape[0], len(ids), Y.shape[0], self.n_features))
            for p in range(m_size):
                G += Gext[:, :, p, Y[:, p], :]
            local = sig[1:]
            if local:
                p1 = np.array([t[0] for t in local])
                p2 = np.array([t[1] for t in local])
                if self.pair_per_edge:
                    ie = np.array([by_block[b] for b in ids])  # (nb, n_int)
                    for k in range(len(local)):
                        G += pair[ie[:, k]][:, Y[:, p1[k]], Y[:, p2[k]]][None]
                else:
                    tt = np.array([t[2] for t in local])  # edge types: rows of self.pair
                    G += self.pair[tt[:, None], Y[:, p1].T, Y[:, p2].T].sum(axis=0)[None, None]
            codes = np.ravel_multi_index(tuple(np.moveaxis(x[:, nodes], -1, 0)), (q,) * m_size)
            groups.setdefault(m_size, []).append(
                (G.reshape(-1, *G.shape[2:]), codes.reshape(-1).astype(np.int64)))
        out = []
        for m_size in sorted(groups):
            G = np.concatenate([g for g, _ in groups[m_size]])
            obs = np.concatenate([o for _, o in groups[m_size]])
            flat = np.concatenate([G.reshape(G.shape[0], -1), obs[:, None].astype(float)], 1)
            first, counts, _ = unique_rows(flat)
            out.append(ConditionalRows(np.ascontiguousarray(G[first]), obs[first],
                                       counts.astype(float), self.may_forbid))
        return out


def _all_configurations(q: int, m: int) -> np.ndarray:
    """All ``q^m`` joint states of ``m`` nodes, (q^m, m), in ``ravel_multi_index`` order."""
    return np.stack(np.unravel_index(np.arange(q ** m), (q,) * m), axis=1).astype(np.int64)


def check_configurations(x: Any, n_states: int, graph_shape: tuple[int, ...],
                         name: str = "data") -> np.ndarray:
    """Validate observed states: ``graph_shape`` or ``(M, *graph_shape)`` ints in ``[0, q)``.

    Returns (M, n_nodes) int64.
    """
    arr = np.asarray(x)
    if arr.dtype.kind == "b":
        arr = arr.astype(np.int64)
    if arr.dtype.kind == "f":
        if not (np.all(np.isfinite(arr)) and np.all(arr == np.round(arr))):
            raise ValueError(f"{name} must hold integer states 0 .. {n_states - 1}; got "
                             f"non-integer values")
        if np.abs(arr).max(initial=0) > 2 ** 31:
            raise ValueError(f"{name} must lie in [0, {n_states - 1}]; got values up to "
                             f"{np.abs(arr).max():.3g}")
        arr = arr.astype(np.int64)
    if arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integer states 0 .. {n_states - 1}; got dtype "
                         f"{arr.dtype}")
    k = len(graph_shape)
    if arr.shape == tuple(graph_shape):
        arr = arr[None]
    if arr.ndim != k + 1 or arr.shape[1:] != tuple(graph_shape) or arr.shape[0] < 1:
        raise ValueError(f"{name} must have shape {tuple(graph_shape)} or (M, "
                         f"{', '.join(map(str, graph_shape))}); got {np.shape(x)}")
    lo, hi = int(arr.min()), int(arr.max())
    if lo < 0 or hi >= n_states:
        raise ValueError(f"{name} must lie in [0, {n_states - 1}] for n_states={n_states}; got "
                         f"[{lo}, {hi}]")
    return arr.reshape(arr.shape[0], -1).astype(np.int64)
