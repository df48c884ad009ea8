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
``...(by_type={g: ts})``  one ``coupling_<g>`` per group ``g`` of edge types ``ts``
``NodeCovariate(name)``   ``name[_k][_a]``: ``z_ik [x_i = a]`` (a >= 1) or ``z_ik v(x_i)``
``...(states=S)``         ``name[_k]_a`` for ``a`` in ``S`` only: ``z_ik [x_i = a]``
``EdgeCovariate(name)``   ``name[_k]``: ``w_ek [x_i = x_j]`` or ``w_ek v(x_i) v(x_j)``
========================  =====================================================

Node covariates are passed as ``covariates={name: array}`` of shape
``(n_nodes,)`` / ``(n_nodes, k)`` (on a lattice ``(H, W)`` / ``(H, W, k)``);
edge covariates as ``(n_edges,)`` / ``(n_edges, k)`` in the order of
``graph.edges`` (``model.graph((H, W)).edges`` on a lattice), or as a callable
``(graph, covariates) -> array`` (e.g. a contrast-sensitive weight ``exp(-|z_i - z_j|)``).

What a term declares that depends on the model (states in range, edge types the
graph has) is checked by :meth:`Term.check` when the model is declared.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
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

    def check(self, q: int, edge_types: tuple[str, ...]) -> None:
        """Raise ValueError if the term does not fit ``q`` states or the graph's edge types."""


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


def _state_features(q: int, values: np.ndarray, kind: str,
                    states: tuple[int, ...] | None = None) -> np.ndarray:
    """``(q, m)``: per state, the feature vector (one-hot of ``states``, by default every
    state but the reference 0, or the value)."""
    if kind == "value":
        return np.asarray(values, dtype=np.float64)[:, None]
    return np.eye(q)[:, 1:] if states is None else np.eye(q)[:, list(states)]


def _suffixes(q: int, kind: str, states: tuple[int, ...] | None = None) -> list[str]:
    if states is not None:  # chosen states are always named, even one of two
        return [f"_{a}" for a in states]
    if kind == "value" or q == 2:
        return [""]
    return [f"_{a}" for a in range(1, q)]


def _state_tuple(states: Any) -> tuple[int, ...] | None:
    """``states=`` of a term as distinct non-negative ints (ValueError naming ``states``)."""
    if states is None:
        return None
    items = [states] if isinstance(states, int | np.integer) else states
    try:
        out = tuple(int(a) for a in items
                    if isinstance(a, int | np.integer) and not isinstance(a, bool))
        ok = len(out) == len(items) > 0
    except TypeError:
        ok = False
    if not ok or min(out) < 0:
        raise ValueError(f"states must be one state or a non-empty sequence of states (integers "
                         f">= 0); got {states!r}")
    if len(set(out)) != len(out):
        raise ValueError(f"states lists the state {next(a for a in out if out.count(a) > 1)} "
                         f"twice; got {states!r}")
    return out


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


def _type_groups(by_type: Mapping) -> list[tuple[str, tuple[str, ...]]]:
    """``by_type={group: edge types}`` as checked ``[(group, types), ...]``."""
    if not by_type:
        raise ValueError("Coupling by_type must be True, False or a non-empty mapping group -> "
                         "edge types, e.g. {'straight': ('horizontal', 'vertical')}")
    groups, seen = [], {}
    for g, types in by_type.items():
        if not isinstance(g, str) or not g.isidentifier():
            raise ValueError(f"Coupling by_type group names must be identifiers (they name the "
                             f"parameters); got {g!r}")
        ts = (types,) if isinstance(types, str) else tuple(types) if isinstance(
            types, Sequence) else ()
        if not ts or not all(isinstance(t, str) for t in ts):
            raise ValueError(f"Coupling by_type[{g!r}] must be an edge type or a non-empty "
                             f"sequence of edge types (strings); got {types!r}")
        for t in ts:
            if t in seen:
                raise ValueError(f"Coupling by_type lists the edge type {t!r} twice (in "
                                 f"{seen[t]!r} and {g!r}); an edge type belongs to one group")
            seen[t] = g
        groups.append((g, ts))
    return groups


@dataclass(frozen=True)
class Coupling(Term):
    """Pair coupling: ``J [x_i = x_j]`` (``"indicator"``, Potts) or ``J v(x_i) v(x_j)``.

    ``by_type=True`` gives every edge type (lattice direction) its own parameter
    ``coupling_<type>``; a mapping ``{group: edge types}`` gives each group of edge
    types one shared parameter ``coupling_<group>``, e.g. ``{"straight": ("horizontal",
    "vertical"), "diagonal": ("diagonal", "antidiagonal")}`` on ``lattice(8,
    directional=True)`` (edge types it does not list get no coupling from this term).
    """

    kind: str = "indicator"
    by_type: bool | Mapping[str, Sequence[str]] = field(default=False, hash=False)
    bounds: tuple = (-2.0, 2.0)
    name: str = "coupling"

    def __post_init__(self) -> None:
        _check_kind(self.kind, "Coupling", _PAIR_KINDS)
        _bounds_pair(self.bounds, "Coupling")
        if isinstance(self.by_type, Mapping):
            _type_groups(self.by_type)
        elif not isinstance(self.by_type, bool | np.bool_):
            raise ValueError(f"Coupling by_type must be True, False or a mapping group -> edge "
                             f"types; got {self.by_type!r}")

    def _groups(self, edge_types: tuple[str, ...]) -> list[tuple[str, list[int]]] | None:
        """``[(group, edge type indices), ...]``; None for one shared parameter."""
        if isinstance(self.by_type, Mapping):
            return [(g, [edge_types.index(t) for t in ts]) for g, ts in
                    _type_groups(self.by_type)]
        if self.by_type and len(edge_types) > 1:
            return [(t, [k]) for k, t in enumerate(edge_types)]
        return None

    def check(self, q, edge_types):
        if isinstance(self.by_type, Mapping):
            unknown = [t for _, ts in _type_groups(self.by_type) for t in ts
                       if t not in edge_types]
            if unknown:
                raise ValueError(f"Coupling by_type names edge type(s) "
                                 f"{', '.join(map(repr, unknown))} the graph does not have; its "
                                 f"edge types: {', '.join(map(repr, edge_types))}")

    def params(self, q, edge_types, covariates):
        b = _bounds_pair(self.bounds, "Coupling")
        groups = self._groups(edge_types)
        if groups is None:
            return [(self.name, b)]
        return [(f"{self.name}_{g}", b) for g, _ in groups]

    def pair_design(self, graph, q, values, covariates):
        f = _pair_feature(q, values, self.kind)
        T = graph.n_edge_types
        groups = self._groups(graph.edge_type_names)
        if groups is None:
            return np.broadcast_to(f[None, :, :, None], (T, q, q, 1)).copy()
        out = np.zeros((T, q, q, len(groups)))
        for k, (_, types) in enumerate(groups):
            out[types, :, :, k] = f
        return out


def _node_covariate(covariates: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    return np.asarray(covariates[name], dtype=np.float64)


@dataclass(frozen=True)
class NodeCovariate(Term):
    """Node covariate ``z_i`` (k features): ``beta_ka z_ik [x_i = a]`` or ``beta_k z_ik v(x_i)``.

    ``states=S`` (indicator kind) lets the covariate act on the states in ``S`` only:
    parameters ``name[_k]_a`` for ``a`` in ``S``, features ``z_ik [x_i = a]``; the other
    states (state 0 among them unless listed) are its reference. Listing all ``q``
    states is refused: their effects would be identified only up to a common shift.
    """

    covariate: str
    kind: str = "indicator"
    bounds: tuple = (-3.0, 3.0)
    states: Any = field(default=None, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.covariate, str) or not self.covariate.isidentifier():
            raise ValueError(f"NodeCovariate name must be an identifier; got {self.covariate!r}")
        _check_kind(self.kind, "NodeCovariate")
        _bounds_pair(self.bounds, "NodeCovariate")
        if self.states is not None and self.kind != "indicator":
            raise ValueError(f"NodeCovariate {self.covariate!r}: states= needs kind='indicator' "
                             f"(a per-state effect); got kind={self.kind!r}")
        _state_tuple(self.states)

    def check(self, q, edge_types):
        states = _state_tuple(self.states)
        if states is None:
            return
        if max(states) >= q:
            raise ValueError(f"NodeCovariate {self.covariate!r} states must lie in [0, {q - 1}] "
                             f"for n_states={q}; got {self.states!r}")
        if len(states) == q:
            raise ValueError(f"NodeCovariate {self.covariate!r} states lists all {q} states: "
                             f"their effects are identified only up to a common shift; leave "
                             f"one out as the reference")

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
        suffixes = _suffixes(q, self.kind, _state_tuple(self.states))
        return [(self.covariate + f + s, b) for f in feats for s in suffixes]

    def node_design(self, graph, q, values, covariates):
        z = _node_covariate(covariates, self.covariate)
        z = z.reshape(graph.n_nodes, -1)  # (n, k); validated by the model
        s = _state_features(q, values, self.kind, _state_tuple(self.states))  # (q, m)
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
