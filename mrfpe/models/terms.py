"""Log-linear potentials of a discrete pairwise MRF, declared as terms.

A discrete pairwise MRF on a graph with ``q`` states per node has

    ``log p(x | theta) = sum_i theta . f_i(x_i) + sum_(ij) theta . g_ij(x_i, x_j) - log Z``

(thesis 4.3-4.5 with T = 1; Besag 1974 Sec. 4). Each term below contributes a
few parameters and their *design*: node features ``f_i(a)`` as an array
``(n_nodes or 1, q, k)`` and pair features ``g_e(a, b)`` as ``(n_edge_types or
n_edges, q, q, k)`` (symmetric in ``a, b``). A first axis of length 1 (nodes)
or ``n_edge_types`` (pairs) means the feature is shared, which lets the
estimators keep only distinct neighbourhood patterns. Covariates (a CRF) make
the features node- or edge-specific.

========================  =====================================================
term                      parameters and feature
========================  =====================================================
``Field()``               ``field_a`` (a >= 1): ``[x_i = a]`` (state 0 the reference)
``Field("value")``        ``field``: ``v(x_i)`` with the model's state values
``Coupling()``            ``coupling``: ``[x_i = x_j]`` (Potts)
``Coupling("product")``   ``coupling``: ``v(x_i) v(x_j)`` (Ising / autologistic)
``...(by_type=True)``     one ``coupling_<type>`` per edge type (direction)
``NodeCovariate(name)``   ``name[_k][_a]``: ``z_ik [x_i = a]`` (a >= 1) or ``z_ik v(x_i)``
``EdgeCovariate(name)``   ``name[_k]``: ``w_ek [x_i = x_j]`` or ``w_ek v(x_i) v(x_j)``
========================  =====================================================

Node covariates are passed as ``covariates={name: array}`` of shape
``(n_nodes,)`` / ``(n_nodes, k)`` (on a lattice ``(H, W)`` / ``(H, W, k)``);
edge covariates as ``(n_edges,)`` / ``(n_edges, k)`` in the order of
``graph.edges``, or as a callable ``(graph, covariates) -> array`` (e.g. a
contrast-sensitive weight ``exp(-|z_i - z_j|)``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.models.graph import Graph

__all__ = ["Coupling", "EdgeCovariate", "Field", "NodeCovariate", "Term"]

_NODE_KINDS = ("indicator", "value")
_PAIR_KINDS = ("indicator", "product")


class Term:
    """One log-linear term: its parameters and their node or pair design."""

    #: Names of the covariates the term reads (checked before any work).
    covariate_names: tuple[str, ...] = ()

    def params(self, q: int, edge_types: tuple[str, ...],
               covariates: Mapping[str, np.ndarray] | None) -> list[tuple[str, tuple]]:
        """``[(name, (low, high)), ...]``: parameter names and default bounds."""
        raise NotImplementedError

    def node_design(self, graph: Graph, q: int, values: np.ndarray,
                    covariates: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """``(n_nodes or 1, q, k)`` node features, or None."""
        return None

    def pair_design(self, graph: Graph, q: int, values: np.ndarray,
                    covariates: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """``(n_edge_types or n_edges, q, q, k)`` pair features, or None."""
        return None

    def n_params(self, q: int, edge_types: tuple[str, ...],
                 covariates: Mapping[str, np.ndarray] | None) -> int:
        return len(self.params(q, edge_types, covariates))


def _check_kind(kind: Any, what: str, kinds: tuple[str, ...] = _NODE_KINDS) -> str:
    if kind not in kinds:
        raise ValueError(f"{what} kind must be {' or '.join(map(repr, kinds))}; got {kind!r}")
    return kind


def _bounds_pair(bounds: Any, what: str) -> tuple[float, float]:
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"{what} bounds must be (low, high); got {bounds!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"{what} bounds must be finite with low < high; got {bounds!r}")
    return lo, hi


def _state_features(q: int, values: np.ndarray, kind: str) -> np.ndarray:
    """``(q, m)``: per state, the feature vector (one-hot without state 0, or the value)."""
    if kind == "value":
        return np.asarray(values, dtype=np.float64)[:, None]
    return np.eye(q)[:, 1:]


def _suffixes(q: int, kind: str) -> list[str]:
    if kind == "value" or q == 2:
        return [""]
    return [f"_{a}" for a in range(1, q)]


@dataclass(frozen=True)
class Field(Term):
    """Node field: ``h_a [x_i = a]`` per state ``a >= 1`` (or ``h v(x_i)`` for ``"value"``)."""

    kind: str = "indicator"
    bounds: tuple = (-3.0, 3.0)
    name: str = "field"

    def __post_init__(self) -> None:
        _check_kind(self.kind, "Field")
        _bounds_pair(self.bounds, "Field")

    def params(self, q, edge_types, covariates):
        b = _bounds_pair(self.bounds, "Field")
        return [(self.name + s, b) for s in _suffixes(q, self.kind)]

    def node_design(self, graph, q, values, covariates):
        return _state_features(q, values, self.kind)[None]  # (1, q, k)


def _pair_feature(q: int, values: np.ndarray, kind: str) -> np.ndarray:
    """``(q, q)``: ``[a = b]`` (indicator) or ``v(a) v(b)`` (product)."""
    if kind == "product":
        v = np.asarray(values, dtype=np.float64)
        return np.outer(v, v)
    return np.eye(q)


@dataclass(frozen=True)
class Coupling(Term):
    """Pair coupling: ``J [x_i = x_j]`` (``"indicator"``, Potts) or ``J v(x_i) v(x_j)``.

    ``by_type=True`` gives every edge type (lattice direction) its own parameter
    ``coupling_<type>``.
    """

    kind: str = "indicator"
    by_type: bool = False
    bounds: tuple = (-2.0, 2.0)
    name: str = "coupling"

    def __post_init__(self) -> None:
        _check_kind(self.kind, "Coupling", _PAIR_KINDS)
        _bounds_pair(self.bounds, "Coupling")

    def params(self, q, edge_types, covariates):
        b = _bounds_pair(self.bounds, "Coupling")
        if self.by_type and len(edge_types) > 1:
            return [(f"{self.name}_{t}", b) for t in edge_types]
        return [(self.name, b)]

    def pair_design(self, graph, q, values, covariates):
        f = _pair_feature(q, values, self.kind)
        T = graph.n_edge_types
        if self.by_type and T > 1:
            out = np.zeros((T, q, q, T))
            for t in range(T):
                out[t, :, :, t] = f
            return out
        return np.broadcast_to(f[None, :, :, None], (T, q, q, 1)).copy()


def _node_covariate(covariates: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    return np.asarray(covariates[name], dtype=np.float64)


@dataclass(frozen=True)
class NodeCovariate(Term):
    """Node covariate ``z_i`` (k features): ``beta_ka z_ik [x_i = a]`` or ``beta_k z_ik v(x_i)``."""

    covariate: str
    kind: str = "indicator"
    bounds: tuple = (-3.0, 3.0)

    def __post_init__(self) -> None:
        if not isinstance(self.covariate, str) or not self.covariate.isidentifier():
            raise ValueError(f"NodeCovariate name must be an identifier; got {self.covariate!r}")
        _check_kind(self.kind, "NodeCovariate")
        _bounds_pair(self.bounds, "NodeCovariate")

    @property
    def covariate_names(self) -> tuple[str, ...]:
        return (self.covariate,)

    def _k(self, covariates) -> int:
        if covariates is None or self.covariate not in covariates:
            return 1
        z = np.asarray(covariates[self.covariate])
        return 1 if z.ndim == 1 else int(z.shape[-1])

    def params(self, q, edge_types, covariates):
        b = _bounds_pair(self.bounds, "NodeCovariate")
        k = self._k(covariates)
        feats = [""] if k == 1 else [f"_{j}" for j in range(k)]
        return [(self.covariate + f + s, b) for f in feats for s in _suffixes(q, self.kind)]

    def node_design(self, graph, q, values, covariates):
        z = _node_covariate(covariates, self.covariate)
        z = z.reshape(graph.n_nodes, -1)  # (n, k); validated by the model
        s = _state_features(q, values, self.kind)  # (q, m)
        # (n, q, k*m), feature-major to match params()
        return (z[:, None, :, None] * s[None, :, None, :]).reshape(graph.n_nodes, q, -1)


@dataclass(frozen=True)
class EdgeCovariate(Term):
    """Edge covariate ``w_e`` (k features) scaling a coupling: ``gamma_k w_ek [x_i = x_j]``
    (or ``gamma_k w_ek v(x_i) v(x_j)`` for ``kind="product"``).

    ``values`` is the covariate's name in ``covariates`` (an ``(n_edges,)`` or
    ``(n_edges, k)`` array in ``graph.edges`` order), or a callable
    ``(graph, covariates) -> array`` computing it from node covariates.
    """

    covariate: str
    kind: str = "indicator"
    bounds: tuple = (-2.0, 2.0)
    values: Callable[[Graph, Mapping[str, np.ndarray]], Any] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.covariate, str) or not self.covariate.isidentifier():
            raise ValueError(f"EdgeCovariate name must be an identifier; got {self.covariate!r}")
        _check_kind(self.kind, "EdgeCovariate", _PAIR_KINDS)
        _bounds_pair(self.bounds, "EdgeCovariate")
        if self.values is not None and not callable(self.values):
            raise ValueError("EdgeCovariate values must be a callable (graph, covariates) -> "
                             "array, or None to read covariates[name]")

    @property
    def covariate_names(self) -> tuple[str, ...]:
        return () if self.values is not None else (self.covariate,)

    def edge_values(self, graph: Graph, covariates: Mapping[str, np.ndarray]) -> np.ndarray:
        """``(n_edges, k)`` edge covariate values, checked."""
        raw = (self.values(graph, covariates) if self.values is not None
               else covariates[self.covariate])
        w = np.asarray(raw, dtype=np.float64)
        if w.ndim == 1:
            w = w[:, None]
        if self.values is not None and w.ndim == 2 and w.shape[1] != 1:
            raise ValueError(f"the callable of EdgeCovariate {self.covariate!r} must return one "
                             f"value per edge, ({graph.n_edges},); got shape {np.shape(raw)}")
        if w.ndim != 2 or w.shape[0] != graph.n_edges:
            raise ValueError(f"covariate {self.covariate!r} must be ({graph.n_edges},) or "
                             f"({graph.n_edges}, k), one row per edge in graph.edges order; "
                             f"got shape {np.shape(raw)}")
        if not np.all(np.isfinite(w)):
            raise ValueError(f"covariate {self.covariate!r} must be finite")
        return w

    def params(self, q, edge_types, covariates):
        b = _bounds_pair(self.bounds, "EdgeCovariate")
        k = 1
        if covariates is not None and self.values is None and self.covariate in covariates:
            z = np.asarray(covariates[self.covariate])
            k = 1 if z.ndim == 1 else int(z.shape[-1])
        return [(self.covariate + ("" if k == 1 else f"_{j}"), b) for j in range(k)]

    def pair_design(self, graph, q, values, covariates):
        w = self.edge_values(graph, covariates)  # (E, k)
        f = _pair_feature(q, values, self.kind)  # (q, q)
        return w[:, None, None, :] * f[None, :, :, None]
