"""Discrete pairwise MRFs declared by graph, states and potentials.

:class:`MRF` is the one class behind every discrete model of
:mod:`mrfpe.models`: Potts, Ising, autologistic CRFs and any model a user
declares::

    from mrfpe import models
    m = models.MRF(graph=models.lattice(4, directional=True), n_states=2,
                   terms=[models.Coupling("product", by_type=True), models.Field(),
                          models.NodeCovariate("z")],
                   state_values=(-1, 1))
    x = m.simulate([0.3, 0.1, 0.0, 0.5], shape=(64, 64), covariates={"z": z}, seed=1)
    pl = m.target("pl", x, covariates={"z": z})

Potentials are either log-linear terms (:mod:`mrfpe.models.terms`) or one
general :class:`Potential` whose tables are batched callables of theta. Both
compile to a :class:`mrfpe.models.design.Design` per graph and covariates,
from which every estimator is generated (:mod:`mrfpe.models.estimators`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.models.base import Model
from mrfpe.models.design import Design, check_configurations, check_design_memory
from mrfpe.models.graph import Graph, LatticeSpec, as_graph_spec
from mrfpe.models.options import (
    CODING_OPTION,
    COMMON_OPTIONS,
    PL_ADJUSTED_OPTIONS,
    adjusted_options,
    block_option_spec,
    bounds_option,
    coding_nodes,
    jsonable,
)
from mrfpe.models.terms import EdgeCovariate, NodeCovariate, Term
from mrfpe.targets.base import Target
from mrfpe.targets.options import Option, choice_check
from mrfpe.validation import check_positive_int

__all__ = ["MRF", "Potential"]


@dataclass(frozen=True)
class Potential:
    """A general (not log-linear) pairwise potential, as batched callables of theta.

    Parameters
    ----------
    params : sequence of (name, (low, high))
        The parameters and their default bounds.
    node : callable (N, d) -> (N, q), optional
        Log node potential of each state (shared by all nodes).
    pair : callable (N, d) -> (N, q, q) or (N, n_edge_types, q, q)
        Log pair potential of each state pair (per edge type or shared); must be
        symmetric in the two states.

    Log-potentials are finite, or ``-inf``: a forbidden state or pair, whose
    configurations have probability zero. ``+inf`` or NaN at some theta is refused
    (ValueError naming theta and the callable) when the potential is evaluated there.
    """

    params: Sequence[tuple[str, tuple[float, float]]]
    pair: Callable[[np.ndarray], Any]
    node: Callable[[np.ndarray], Any] | None = None

    def __post_init__(self) -> None:
        if not callable(self.pair) or (self.node is not None and not callable(self.node)):
            raise ValueError("Potential pair (and node, if given) must be callables of a "
                             "(N, d) theta batch")
        if not self.params:
            raise ValueError("Potential params must name at least one parameter")


COMMON = COMMON_OPTIONS

ESTIMATOR_OPTIONS: dict[str, tuple[Option, ...]] = {
    "pl": COMMON,
    "coding": (*COMMON, CODING_OPTION),
    "block": (*COMMON, block_option_spec("at most 4096 joint states per block")),
    "exact": (*COMMON, Option("method", "'auto' | 'enumerate' | 'eliminate'", "auto",
                              choice_check("auto", "enumerate", "eliminate"),
                              "log Z by enumeration (tiny) or variable elimination")),
    "pl_adjusted": (*COMMON, *PL_ADJUSTED_OPTIONS),
    "likelihood": (*COMMON, Option("sampler", "'auto' | 'gibbs' | 'swendsen_wang'", "auto",
                                   choice_check("auto", "gibbs", "swendsen_wang"),
                                   "the simulator used for auxiliary draws"),
                   Option("n_sweeps", "int >= 1", 200,
                          lambda n, v: check_positive_int(n, v),
                          "sweeps per auxiliary draw (Gibbs / Swendsen-Wang)")),
}


class MRF(Model):
    """A discrete pairwise MRF: graph, ``q`` states, log-linear terms or a general potential.

    Parameters
    ----------
    graph : lattice(...), Graph, 4, 8, adjacency matrix or networkx graph
        A lattice rule applies to data of any shape; a fixed graph to data with
        one state per node.
    n_states : int >= 2
    terms : sequence of :class:`mrfpe.models.terms.Term`, optional
        Log-linear potentials; the parameters are the terms' in order.
    potential : Potential, optional
        A general potential instead of ``terms``.
    state_values : sequence of q numbers, optional
        ``v(a)`` for the ``"value"`` kind of terms (default ``0 .. q-1``; the
        Ising model uses ``(-1, 1)``).
    name : str
    """

    estimators = ("pl", "coding", "block", "exact", "likelihood", "pl_adjusted")
    estimator_options = ESTIMATOR_OPTIONS

    def __init__(self, graph: Any = 4, n_states: int = 2, terms: Sequence[Term] | None = None,
                 potential: Potential | None = None, state_values: Any = None,
                 name: str = "mrf") -> None:
        self.graph_spec = as_graph_spec(graph)
        self.n_states = check_positive_int("n_states", n_states, minimum=2)
        if (terms is None) == (potential is None):
            raise ValueError("give exactly one of terms (log-linear) or potential (general)")
        if terms is not None:
            terms = tuple(terms)
            if not terms or not all(isinstance(t, Term) for t in terms):
                raise ValueError("terms must be a non-empty sequence of mrfpe.models terms "
                                 "(Field, Coupling, NodeCovariate, EdgeCovariate, ...)")
        if potential is not None and not isinstance(potential, Potential):
            raise ValueError(f"potential must be an mrfpe.models.Potential; got "
                             f"{type(potential).__name__}")
        self.terms = terms
        self.potential = potential
        q = self.n_states
        v = np.arange(q, dtype=np.float64) if state_values is None else np.asarray(
            state_values, dtype=np.float64)
        if v.shape != (q,) or not np.all(np.isfinite(v)):
            raise ValueError(f"state_values must be {q} finite numbers; got {state_values!r}")
        self.state_values = v
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty string; got {name!r}")
        self.name = name
        for t in terms or ():  # states in range, edge types the graph has
            t.check(q, self.edge_type_names)

    # -- structure -------------------------------------------------------------------------------
    @property
    def edge_type_names(self) -> tuple[str, ...]:
        return self.graph_spec.edge_type_names

    def graph(self, shape: Any = None) -> Graph:
        """The graph for data of ``shape`` (a lattice's ``(H, W)``; ignored for a fixed graph)."""
        if isinstance(self.graph_spec, LatticeSpec):
            if shape is None:
                raise ValueError("shape must be given: the model is declared on a lattice")
            return self.graph_spec.build(shape)
        return self.graph_spec

    def n_codings(self, shape: Any = None) -> int:
        return self.graph(shape).n_colours

    def node_shape(self, shape: Any = None) -> tuple[int, ...]:
        """Shape of one configuration: ``(H, W)`` on a lattice, ``(n_nodes,)`` otherwise."""
        g = self.graph(shape)
        return g.shape if g.shape is not None else (g.n_nodes,)

    def _params(self, covariates: Mapping[str, np.ndarray] | None) -> list[tuple[str, tuple]]:
        if self.potential is not None:
            return [(str(n), tuple(b)) for n, b in self.potential.params]
        out = []
        for t in self.terms:
            out += t.params(self.n_states, self.edge_type_names, covariates)
        dup = sorted(n for n, c in Counter(n for n, _ in out).items() if c > 1)  # O(q)
        if dup:
            raise ValueError(f"terms declare the parameter name(s) {', '.join(dup)} twice; give "
                             f"the terms distinct names")
        return out

    def param_names(self, covariates: Mapping[str, Any] | None = None,
                    shape: Any = None) -> tuple[str, ...]:
        """Names of theta's entries (a covariate with k features adds k parameters per state).

        On a lattice with covariates, pass the data's ``shape`` too.
        """
        if covariates:
            return self.compile(shape, covariates)[1]
        return tuple(n for n, _ in self._params(None))

    # -- compilation -----------------------------------------------------------------------------
    def _covariates(self, graph: Graph, covariates: Mapping[str, Any] | None) -> dict:
        """Node covariates reshaped to (n_nodes[, k]) and checked against the terms."""
        if covariates is not None and not isinstance(covariates, Mapping):
            raise ValueError("covariates must be a mapping name -> array: the model's terms "
                             "name their covariates")
        covariates = dict(covariates or {})
        needed: list[str] = []
        for t in self.terms or ():
            needed += list(t.covariate_names)
        missing = [n for n in needed if n not in covariates]
        if missing:
            raise ValueError(f"covariates must include {', '.join(map(repr, missing))} (declared "
                             f"by the model's terms); got {sorted(covariates) or 'none'}")
        extra = sorted(set(covariates) - set(needed))
        if extra and self.terms is not None and not any(
                getattr(t, "values", None) is not None for t in self.terms):
            raise ValueError(f"covariates {', '.join(map(repr, extra))} are not used by any term; "
                             f"used: {', '.join(map(repr, needed)) or 'none'}")
        edge_names = {t.covariate for t in self.terms or () if isinstance(t, EdgeCovariate)}
        out = {}
        for name, value in covariates.items():
            try:
                z = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"covariate {name!r} must be an array of numbers") from None
            if not np.all(np.isfinite(z)):
                raise ValueError(f"covariate {name!r} must be finite (it holds NaN or inf)")
            if name not in edge_names:
                node_shape = graph.shape if graph.shape is not None else (graph.n_nodes,)
                k = len(node_shape)
                if z.shape[:k] != tuple(node_shape) or z.ndim > k + 1:
                    raise ValueError(f"covariate {name!r} must have shape {tuple(node_shape)} "
                                     f"or {(*node_shape, 'k')}, one row per node; got {z.shape}")
                z = z.reshape(graph.n_nodes, -1)
                if z.shape[1] == 1:
                    z = z[:, 0]
            out[name] = z
        return out

    def design(self, shape: Any = None, covariates: Mapping[str, Any] | None = None) -> Design:
        """The compiled model on the graph of ``shape`` with ``covariates``."""
        return self.compile(shape, covariates)[0]

    def compile(self, shape: Any = None, covariates: Mapping[str, Any] | None = None
                ) -> tuple[Design, tuple[str, ...], np.ndarray]:
        """``(design, param_names, default_bounds)`` on the graph of ``shape``."""
        g = self.graph(shape)
        q = self.n_states
        if self.potential is not None:
            if covariates:
                raise ValueError("covariates need log-linear terms (NodeCovariate, "
                                 "EdgeCovariate); a general Potential takes none")
            params = self._params(None)
            return (_potential_design(self.potential, g, q), tuple(n for n, _ in params),
                    np.array([b for _, b in params], dtype=np.float64))
        cov = self._covariates(g, covariates)
        params = self._params(cov)
        per_edge = [isinstance(t, EdgeCovariate) for t in self.terms]
        per_node = any(isinstance(t, NodeCovariate) for t in self.terms)
        check_design_memory(q, len(params), g.n_nodes if per_node else 1,
                            g.n_edges if any(per_edge) else g.n_edge_types, any(per_edge))
        nodes, pairs = [], []
        for t in self.terms:
            k = t.n_params(q, self.edge_type_names, cov)
            nd = t.node_design(g, q, self.state_values, cov)
            pd = t.pair_design(g, q, self.state_values, cov)
            nodes.append(np.zeros((1, q, k)) if nd is None else np.asarray(nd, dtype=float))
            pairs.append(np.zeros((g.n_edge_types, q, q, k)) if pd is None
                         else np.asarray(pd, dtype=float))
        n_rows = max(a.shape[0] for a in nodes)
        node = np.concatenate([np.broadcast_to(a, (n_rows, *a.shape[1:])) for a in nodes], -1)
        if any(per_edge):  # one pair row per edge: expand the per-type rows of other terms
            pairs = [a if e else a[g.edge_type] for a, e in zip(pairs, per_edge, strict=True)]
        pair = np.concatenate(pairs, axis=-1)
        return (Design(g, q, node, pair, pair_per_edge=any(per_edge)),
                tuple(n for n, _ in params),
                np.array([b for _, b in params], dtype=np.float64))

    def _data(self, data: Any, options: Mapping[str, Any]
              ) -> tuple[Design, np.ndarray, tuple[str, ...], np.ndarray]:
        """Design, (M, n_nodes) observed states, parameter names and bounds for ``data``."""
        arr = np.asarray(data)
        shape = None
        if isinstance(self.graph_spec, LatticeSpec):
            if arr.ndim not in (2, 3):
                raise ValueError(f"data must be an (H, W) or (M, H, W) array of states on the "
                                 f"lattice model {self.name!r}; got shape {arr.shape}")
            shape = arr.shape[-2:]
        design, names, bounds = self.compile(shape, options.get("covariates"))
        g = design.graph
        x = check_configurations(data, self.n_states,
                                 g.shape if g.shape is not None else (g.n_nodes,))
        b = options.get("bounds")
        if isinstance(b, Mapping):
            bounds = bounds.copy()
            unknown = sorted(set(b) - set(names))
            if unknown:
                raise ValueError(f"bounds names unknown parameter(s) {unknown}; parameters: "
                                 f"{list(names)}")
            for k, v in b.items():
                bounds[names.index(k)] = bounds_option(f"bounds[{k!r}]", [v])[0]
        elif b is not None:
            if b.shape != (len(names), 2):
                raise ValueError(f"bounds must be ({len(names)}, 2), one row per parameter "
                                 f"{names}; got {b.shape}")
            bounds = b
        return design, x, names, bounds

    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        from mrfpe.models import estimators as est

        design, x, names, bounds = self._data(data, options)
        common = {"model": self, "design": design, "x": x, "param_names": names,
                  "bounds": bounds, "estimator": estimator}
        if estimator == "pl":
            return est.ConditionalTarget(rows=[design.conditional_rows(x)],
                                         nodes=np.arange(design.graph.n_nodes), **common)
        if estimator == "coding":
            nodes, n_codings = coding_nodes(design.graph, options["coding"])
            return est.ConditionalTarget(rows=[design.conditional_rows(x, nodes)], nodes=nodes,
                                         cost=nodes.size / design.graph.n_nodes,
                                         extra={"coding": options["coding"],
                                                "n_codings": n_codings}, **common)
        if estimator == "block":
            blocks = est.make_blocks(design.graph, options["block"], design.q)
            return est.ConditionalTarget(rows=design.block_rows(x, blocks), blocks=blocks,
                                         extra={"block": jsonable(options["block"]),
                                                "n_blocks": len(blocks)}, **common)
        if estimator == "exact":
            return est.ExactTarget(method=options["method"], **common)
        if estimator == "likelihood":
            return est.LikelihoodTarget(sampler=options["sampler"],
                                        n_sweeps=options["n_sweeps"], **common)
        if estimator == "pl_adjusted":
            from mrfpe.models.calibration import AdjustedPL

            pl = est.ConditionalTarget(rows=[design.conditional_rows(x)],
                                       nodes=np.arange(design.graph.n_nodes), **common)
            lik = est.LikelihoodTarget(**common)
            return AdjustedPL(pl, lik, **adjusted_options(options))
        raise AssertionError(estimator)  # pragma: no cover - check_estimator ran

    # -- simulation ------------------------------------------------------------------------------
    def simulate(self, theta: Any, shape: Any = None, n: int = 1, *, seed: int | None = None,
                 covariates: Mapping[str, Any] | None = None, method: str = "auto",
                 n_sweeps: int = 200, thin: int = 10, init: Any = "random",
                 kernel: str = "auto") -> np.ndarray:
        """Draw ``n`` configurations at ``theta`` (see :func:`mrfpe.models.simulate.simulate`).

        Returns ``(n, H, W)`` on a lattice, ``(n, n_nodes)`` on a fixed graph; a ``(B, d)``
        theta runs one chain per row (:func:`mrfpe.models.simulate_batch.simulate_batch`)
        and returns ``(B, n, H, W)`` or ``(B, n, n_nodes)``. ``kernel`` (rows only): as
        ``simulate_batch``'s -- many Gibbs chains of a binary lattice model run on the
        multi-spin kernel (same distribution, other draws) unless it is ``"scalar"``.
        """
        from mrfpe.models.simulate import check_simulation_size, simulate
        from mrfpe.models.simulate_batch import check_batch_size, check_theta_rows, simulate_batch

        rows = np.ndim(theta) == 2
        if rows and not covariates:  # before any work: the names need no graph
            check_theta_rows(theta, self.param_names())
        if rows:  # memory checks before the graph
            check_batch_size(self.graph_spec, shape, len(theta), n, n_sweeps, thin)
        else:
            check_simulation_size(self.graph_spec, shape, n, n_sweeps, thin)
        design, names, _ = self.compile(shape, covariates)
        opts = {"seed": seed, "method": method, "n_sweeps": n_sweeps, "thin": thin, "init": init}
        if rows:
            draws = simulate_batch(design, design.psi(check_theta_rows(theta, names)), n,
                                   kernel=kernel, **opts)
        else:
            draws = simulate(design, design.psi(_one_theta(theta, names)[None])[0], n, **opts)
        g = design.graph
        return draws.reshape(*draws.shape[:-1], *(g.shape if g.shape is not None else (g.n_nodes,)))

    def describe(self) -> dict:
        out = super().describe()
        out.update({"n_states": self.n_states, "graph": self.graph_spec.describe(),
                    "param_names": None if self._needs_cov() else list(self.param_names()),
                    "terms": None if self.terms is None else [repr(t) for t in self.terms]})
        return out

    def _needs_cov(self) -> bool:
        return any(t.covariate_names for t in self.terms or ())

    def __repr__(self) -> str:
        return (f"MRF(name={self.name!r}, n_states={self.n_states}, "
                f"graph={self.graph_spec!r})")


def _one_theta(theta: Any, names: Sequence[str]) -> np.ndarray:
    th = np.asarray(theta, dtype=np.float64).reshape(-1)
    if th.shape != (len(names),) or not np.all(np.isfinite(th)):
        raise ValueError(f"theta must be {len(names)} finite numbers {tuple(names)}; got "
                         f"{np.asarray(theta).tolist()}")
    return th


def _potential_design(pot: Potential, g: Graph, q: int) -> Design:
    """Indicator design over the tables of a general potential: psi = (node (q), pair (T q q))."""
    T = g.n_edge_types
    P = q + T * q * q
    check_design_memory(q, P, 1, T)
    node = np.zeros((1, q, P))
    node[0, np.arange(q), np.arange(q)] = 1.0
    pair = np.zeros((T, q, q, P))
    pair.reshape(T * q * q, P)[np.arange(T * q * q), q + np.arange(T * q * q)] = 1.0
    # symmetrised indicators: pair[t, a, b] . psi = (T_ab + T_ba) / 2 = T_ab for symmetric tables
    return Design(g, q, node, 0.5 * (pair + pair.transpose(0, 2, 1, 3)),
                  _potential_psi(pot, q, T))


def _potential_psi(pot: Potential, q: int, T: int) -> Callable[[np.ndarray], np.ndarray]:
    """``theta (N, d) -> psi (N, q + T q q)``: the potential's tables, checked; ``-inf`` (a
    forbidden state or pair) is kept as such: the design's users handle it explicitly."""
    d = len(pot.params)

    def psi(theta: np.ndarray) -> np.ndarray:
        n = theta.shape[0]
        nt = np.zeros((n, q)) if pot.node is None else np.asarray(pot.node(theta), dtype=float)
        if nt.shape != (n, q):
            raise ValueError(f"Potential node must return ({n}, {q}) for a ({n}, {d}) theta "
                             f"batch; got {nt.shape}")
        pt = np.asarray(pot.pair(theta), dtype=float)
        if pt.shape == (n, q, q):
            pt = np.broadcast_to(pt[:, None], (n, T, q, q))
        if pt.shape != (n, T, q, q):
            raise ValueError(f"Potential pair must return ({n}, {q}, {q}) or ({n}, {T}, {q}, "
                             f"{q}) for a ({n}, {d}) theta batch; got {pt.shape}")
        _check_tables(pot, theta, nt, pt)
        return np.concatenate([nt, pt.reshape(n, -1)], axis=1)

    return psi


def _check_tables(pot: Potential, theta: np.ndarray, nt: np.ndarray, pt: np.ndarray) -> None:
    """Refuse NaN and +inf log-potentials, naming theta and the callable, and asymmetry."""
    for what, tab in (("node", nt), ("pair", pt)):
        bad = (np.isnan(tab) | (tab == np.inf)).reshape(tab.shape[0], -1).any(axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            th = ", ".join(f"{name}={v:.6g}" for (name, _), v in zip(pot.params, theta[k]))
            kind = "NaN" if np.isnan(tab[k]).any() else "+inf"
            raise ValueError(f"Potential {what} returned {kind} at theta ({th}): log-potentials "
                             f"must be finite, or -inf to forbid a state or pair")
    forbidden = np.isneginf(pt)
    fin = np.where(forbidden, 0.0, pt)
    if not (np.array_equal(forbidden, forbidden.swapaxes(2, 3))
            and np.allclose(fin, fin.swapaxes(2, 3))):
        raise ValueError("Potential pair must return tables symmetric in the two states (its "
                         "-inf entries too)")
