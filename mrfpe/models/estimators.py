"""The estimators a declared discrete MRF generates, each a batched :class:`Target`.

* :class:`ConditionalTarget` -- composite likelihoods of full conditionals:
  Besag's pseudolikelihood ``"pl"`` (Besag 1975; thesis 4.23-4.24), the coding
  estimator ``"coding"`` (Besag 1974 Sec. 6.1: the conditionals of one colour
  class, which are independent given the rest, so the coding likelihood is a
  true conditional likelihood) and block pseudolikelihood ``"block"`` (the
  conditionals of tiles given their Markov blankets; the generic form of the
  thesis's PL2/PL3 idea of richer local terms, and of Asuncion et al. 2010).
  The codings' log-likelihoods sum to the PL.
* :class:`ExactTarget` -- ``sum_m S(x_m) . psi - M log Z(psi)`` with ``log Z``
  from :mod:`mrfpe.models.exact`.
* :class:`LikelihoodTarget` -- the unnormalised log-likelihood ``S(x) . psi``
  with the model's simulator: the input of doubly-intractable samplers
  (exchange algorithm, Murray, Ghahramani & MacKay 2006), whose auxiliary draws at
  many parameter vectors come from one compiled call (:meth:`LikelihoodTarget.simulate_aux`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mrfpe.models.design import (
    MAX_BLOCK_CONFIGURATIONS,
    ConditionalRows,
    Design,
    allowed_dot,
    softmax_rows_log_prob,
    split_forbidden,
)
from mrfpe.models.graph import Graph
from mrfpe.models.options import largest_block, node_blocks
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.validation import check_seed

__all__ = ["ConditionalTarget", "ExactTarget", "LikelihoodTarget", "ModelTarget",
           "make_blocks"]


class ModelTarget(Target):
    """What every target of a declared model shares: parameters, data, description."""

    data_kind = "configurations"

    def __init__(self, *, model: Any, design: Design, x: np.ndarray,
                 param_names: Sequence[str], bounds: np.ndarray, estimator: str,
                 cost: float = 1.0, extra: dict | None = None) -> None:
        self.model = model
        self.design = design
        self.x = x
        self.param_names = tuple(param_names)
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.estimator = estimator
        self.name = f"{model.name}:{estimator}"
        self.cost = float(cost)
        self._extra = dict(extra or {})

    def sufficient_statistics(self, x: Any = None) -> np.ndarray:
        """``S(x)`` (M, P) of configurations ``x`` (default: the data)."""
        x = self.x if x is None else np.asarray(x).reshape(-1, self.design.graph.n_nodes)
        return self.design.statistics(x)

    def describe(self) -> dict:
        g = self.design.graph
        return {"name": self.name, "class": type(self).__name__, "model": self.model.name,
                "estimator": self.estimator, "param_names": list(self.param_names),
                "bounds": self.bounds.tolist(), "n_states": self.design.q,
                "graph": g.describe(), "n_configurations": int(self.x.shape[0]),
                "cost": self.cost, **self._extra}


class ConditionalTarget(ModelTarget):
    """``sum_r w_r log p(alternative_r | blanket_r)`` over distinct conditional rows."""

    calibrated = False

    def __init__(self, *, rows: Sequence[ConditionalRows], nodes: np.ndarray | None = None,
                 blocks: Sequence[np.ndarray] | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.rows = tuple(rows)
        #: The nodes whose full conditionals the target sums (pl, coding) ...
        self.nodes = None if nodes is None else np.asarray(nodes, dtype=np.int64)
        #: ... or the blocks whose joint conditionals it sums (block).
        self.blocks = None if blocks is None else [np.asarray(b, np.int64) for b in blocks]

    def partition(self, k: int | None = None, kind: str = "strided") -> list[ConditionalTarget]:
        """Sub-targets over disjoint node (or block) subsets whose log_probs sum to this one's.

        ``kind="coding"``: the graph's colour classes within this target's nodes
        (Besag's codings; ``k`` must be None or their number); ``"strided"`` /
        ``"block"``: :func:`mrfpe.targets.partition.split_ids` over the node ids -- or over
        the blocks of a block pseudolikelihood (thesis 5.67, 5.68) -- which are
        codings only by accident of the lattice width.
        """
        from mrfpe.targets.partition import split_ids

        if self.blocks is not None:
            if kind == "coding":
                raise ValueError("kind='coding' needs a target of full conditionals (pl, "
                                 "coding); a block pseudolikelihood splits by blocks")
            parts = split_ids(np.arange(len(self.blocks)), k, kind, what="the target's blocks")
            groups = [[self.blocks[i] for i in p] for p in parts]
            sizes = [sum(b.size for b in g) for g in groups]
            rows = [self.design.block_rows(self.x, g) for g in groups]
            units = [{"blocks": g} for g in groups]
        else:
            if kind == "coding":
                colours = self.design.graph.colouring()[self.nodes]
                groups = [self.nodes[colours == c] for c in np.unique(colours)]
                if k is not None and k != len(groups):
                    raise ValueError(f"k must be None or {len(groups)} (the number of codings) "
                                     f"for kind='coding'; got {k!r}")
            else:
                groups = split_ids(self.nodes, k, kind, what="the target's nodes")
            sizes = [g.size for g in groups]
            rows = [[self.design.conditional_rows(self.x, g)] for g in groups]
            units = [{"nodes": g} for g in groups]
        total = max(sum(sizes), 1)
        return [ConditionalTarget(rows=r, **u, model=self.model, design=self.design, x=self.x,
                                  param_names=self.param_names, bounds=self.bounds,
                                  estimator=self.estimator, cost=self.cost * s / total,
                                  extra=self._extra)
                for r, u, s in zip(rows, units, sizes, strict=True)]

    @property
    def n_rows(self) -> int:
        """Distinct conditional rows kept (the cost of one evaluation)."""
        return sum(g.n_rows for g in self.rows)

    def _row_bytes(self) -> float:
        return 8.0 * 3 * min(sum(g.n_rows * g.n_alternatives for g in self.rows), 1 << 15)

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return softmax_rows_log_prob(self.rows, self.design.psi(theta))

    def describe(self) -> dict:
        return {**super().describe(), "n_distinct_rows": self.n_rows}


class ExactTarget(ModelTarget):
    """The exact log-likelihood ``sum_m log p(x_m | theta)`` (tractable models only)."""

    calibrated = True

    def __init__(self, *, method: str = "auto", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        from mrfpe.models.exact import LogPartition

        self._log_z = LogPartition(self.design, method)  # raises, saying why, if intractable
        self._stats = self.design.statistics(self.x).sum(axis=0)
        self.method = self._log_z.method

    def _row_bytes(self) -> float:
        return float(getattr(self._log_z, "_row_bytes", 0.0))

    def log_partition(self, theta: Any) -> np.ndarray:
        """``log Z(theta)`` (N,) of one configuration (``log_prob`` subtracts M of them)."""
        theta = as_theta_batch(theta, self.ndim)
        return self._log_z(self.design.psi(theta))

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        psi = self.design.psi(theta)
        f = allowed_dot(psi, self._stats)[:, 0]  # -inf: the data hold a forbidden state or pair
        with np.errstate(invalid="ignore"):  # -inf - (-inf) where all are forbidden: -inf
            return np.where(f == -np.inf, -np.inf, f - self.x.shape[0] * self._log_z(psi))

    def describe(self) -> dict:
        return {**super().describe(), "method": self.method}


class LikelihoodTarget(ModelTarget):
    """Unnormalised log-likelihood ``sum_m S(x_m)·psi(theta)`` with a simulator.

    ``log_prob`` omits ``-M log Z(theta)``: it is *not* a density over theta on
    its own. Samplers for doubly-intractable posteriors use it with
    :meth:`simulate` (auxiliary draws at a proposed theta).
    """

    calibrated = True

    #: ``log_prob`` is not a density over theta (it omits ``-M log Z(theta)``).
    normalised = False

    def __init__(self, *, sampler: str = "auto", n_sweeps: int = 200, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.sampler = sampler
        self.n_sweeps = int(n_sweeps)
        self._stats = self.design.statistics(self.x).sum(axis=0)
        self._extra.update({"sampler": sampler, "n_sweeps": self.n_sweeps})

    @property
    def n_observations(self) -> int:
        return int(self.x.shape[0])

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``S(x)·psi(theta)`` (N,) for configurations ``x`` (default the data, summed)."""
        theta = as_theta_batch(theta, self.ndim)
        s = self._stats if x is None else self.sufficient_statistics(x).sum(axis=0)
        return allowed_dot(self.design.psi(theta), s)[:, 0]

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return allowed_dot(self.design.psi(theta), self._stats)[:, 0]

    def log_f_of_draws(self, y: Any) -> Any:
        """``theta (N, d) -> log f(y_k | theta)`` (N, K) for configurations ``y`` (K, n):
        their statistics once, then one product per call, ``-inf`` for a forbidden one."""
        S = self.sufficient_statistics(y)
        return lambda theta: allowed_dot(self.design.psi(theta), S)

    def simulate_aux(self, theta: Any, *, seed: Any = None, n_sweeps: int | None = None,
                     kernel: str = "auto") -> np.ndarray:
        """Auxiliary draws at each row of ``theta`` (B, d): (B, M, n_nodes).

        One chain per row and observed configuration, started at that configuration and
        run ``n_sweeps`` sweeps (default the target's) of the target's sampler: draw
        ``[b, m]`` is distributed as ``simulate(theta[b], init="data")[m]``, the
        auxiliary draw of the exchange algorithm (Murray, Ghahramani & MacKay 2006) from
        the data (Caimo & Friel 2011). All ``B x M`` chains run in one compiled call
        (:func:`~mrfpe.models.simulate_batch.simulate_batch`; ``kernel`` as there: the
        multi-spin kernel for many chains of a binary lattice model, same distribution,
        other random numbers).
        """
        from mrfpe.models.simulate_batch import simulate_batch

        th = as_theta_batch(theta, self.ndim)
        B, M, n = th.shape[0], self.n_observations, self.design.graph.n_nodes
        psi = np.repeat(self.design.psi(th), M, axis=0)  # row b * M + m: chain (b, m)
        draws = simulate_batch(self.design, psi, 1, seed=check_seed(seed), method=self.sampler,
                               n_sweeps=self.n_sweeps if n_sweeps is None else n_sweeps,
                               init=np.tile(self.x, (B, 1)), kernel=kernel)
        return draws.reshape(B, M, n)

    def unnormalised_rows(self, theta: Any, draws: Any) -> np.ndarray:
        """``sum_m S(draws[b, m])·psi(theta[k, b])`` (K, B) for ``theta`` (K, B, d) and
        ``draws`` (B, M, n_nodes): each set of draws at K parameter vectors, the draws'
        statistics computed once; ``-inf`` where a draw holds a forbidden state or pair."""
        th = np.asarray(theta, dtype=np.float64)
        (K, B), P = th.shape[:2], self.design.n_features
        y = np.asarray(draws)
        s = self.design.statistics(y.reshape(-1, y.shape[-1])).reshape(B, -1, P).sum(axis=1)
        psi = self.design.psi(as_theta_batch(th.reshape(K * B, -1), self.ndim))
        fin, forbid = split_forbidden(psi.reshape(K, B, P))
        out = np.einsum("kbp,bp->kb", fin, s)
        if forbid is not None:
            out[np.einsum("kbp,bp->kb", forbid, (s != 0).astype(np.float64)) > 0] = -np.inf
        return out

    def simulate(self, theta: Any, n: int | None = None, *, seed: Any = None,
                 init: Any = "random", n_sweeps: int | None = None,
                 thin: int = 10) -> np.ndarray:
        """Configurations at ``theta``: (n, n_nodes).

        ``init="data"`` runs one chain from each observed configuration and
        returns their final states (``n`` = the number observed): the auxiliary
        draws of the exchange algorithm. Otherwise ``n`` (default as many as
        observed) draws of one chain, ``thin`` sweeps apart, after ``n_sweeps``.
        """
        from mrfpe.models.simulate import simulate

        th = as_theta_batch(theta, self.ndim)
        if th.shape[0] != 1:
            raise ValueError(f"theta must be one parameter vector; got {th.shape[0]}")
        psi = self.design.psi(th)[0]
        sweeps = self.n_sweeps if n_sweeps is None else n_sweeps
        if isinstance(init, str) and init == "data":
            if n not in (None, self.n_observations):
                raise ValueError(f"n must be None (one draw per observed configuration, "
                                 f"{self.n_observations}) with init='data'; got {n!r}")
            rng = np.random.default_rng(check_seed(seed))
            return np.concatenate([
                simulate(self.design, psi, 1, seed=int(rng.integers(2**63)), method=self.sampler,
                         n_sweeps=sweeps, init=xm) for xm in self.x])
        return simulate(self.design, psi, n=self.n_observations if n is None else n, seed=seed,
                        method=self.sampler, n_sweeps=sweeps, thin=thin, init=init)


def make_blocks(graph: Graph, block: Any, q: int) -> list[np.ndarray]:
    """:func:`mrfpe.models.options.node_blocks`, each with at most
    :data:`MAX_BLOCK_CONFIGURATIONS` joint states of ``q`` states per node."""
    blocks = node_blocks(graph, block)
    m = largest_block(blocks)
    if float(q) ** m > MAX_BLOCK_CONFIGURATIONS:
        raise ValueError(f"block of {m} nodes with {q} states has {q}^{m} joint states; "
                         f"block pseudolikelihood enumerates at most "
                         f"{MAX_BLOCK_CONFIGURATIONS} per block (use smaller blocks)")
    return blocks
