"""The auto-normal model on a lattice or a graph: :class:`GaussianMRF` and :func:`autonormal`.

The model states its graph, coupling types and covariates, and builds every
estimator's target on data (:meth:`GaussianMRF.target`), its precision matrix and
mean, and exact draws (:meth:`GaussianMRF.simulate`); see :mod:`mrfpe.models.gaussian`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from mrfpe.models.base import Model
from mrfpe.models.gaussian.bounds import data_bounds, named_bounds
from mrfpe.models.gaussian.data import real_array
from mrfpe.models.gaussian.likelihood import GaussianExactTarget, GaussianLikelihoodTarget
from mrfpe.models.gaussian.options import ESTIMATOR_OPTIONS, make_blocks
from mrfpe.models.gaussian.pseudolikelihood import GaussianBlockTarget, GaussianPLTarget
from mrfpe.models.gaussian.structure import CARStructure
from mrfpe.models.graph import Graph, LatticeSpec, as_graph_spec
from mrfpe.models.options import coding_nodes, jsonable
from mrfpe.targets.base import Target
from mrfpe.validation import check_bool, check_choice, check_positive_int, check_seed

__all__ = ["GaussianMRF", "autonormal"]

_RESERVED = ("mean", "precision", "coupling")


class GaussianMRF(Model):
    """Besag's auto-normal (CAR) model on a lattice or a graph (see :mod:`mrfpe.models.gaussian`).

    Parameters
    ----------
    graph : lattice(...), Graph, 4, 8, adjacency matrix or networkx graph
    directional : bool
        One coupling per lattice direction (or per edge type of a graph):
        ``coupling_horizontal``, ``coupling_vertical``, ... A ``lattice(...)`` rule
        that is itself directional (or periodic) stays so.
    periodic : bool
        Torus boundary (lattices only; a ValueError for a fixed graph).
    covariates : int >= 0 or sequence of str
        Number of anonymous node covariates (parameters ``z`` for one, ``z_0``,
        ``z_1``, ... for several; passed as an array ``(H, W[, k])``) or their
        names (each passed as ``{name: (H, W)}``, or stacked in that order).
    bounds : (d, 2) array or mapping name -> (low, high), optional
        Overrides of the data-driven default bounds.
    name : str
    """

    estimators = ("pl", "coding", "block", "exact", "likelihood", "pl_adjusted")
    estimator_options = ESTIMATOR_OPTIONS

    def __init__(self, graph: Any = 4, *, directional: bool = False, periodic: bool = False,
                 covariates: int | Sequence[str] = 0, bounds: Any = None,
                 name: str = "autonormal") -> None:
        check_bool("directional", directional)
        check_bool("periodic", periodic)
        spec = as_graph_spec(graph)
        if isinstance(spec, LatticeSpec):
            spec = replace(spec, periodic=bool(spec.periodic or periodic),
                           directional=bool(spec.directional or directional))
            self.directional = spec.directional
        else:
            if periodic:
                raise ValueError("periodic applies to lattices; the graph given is fixed (build "
                                 "a periodic lattice with lattice(..., periodic=True))")
            self.directional = bool(directional)
        self.graph_spec: Graph | LatticeSpec = spec
        if isinstance(covariates, bool) or not (
                isinstance(covariates, int | np.integer | Sequence)):
            raise ValueError(f"covariates must be a number of covariates or a sequence of "
                             f"names; got {covariates!r}")
        if isinstance(covariates, int | np.integer):
            k = check_positive_int("covariates", covariates, minimum=0)
            self.covariate_names: tuple[str, ...] = ("z",) if k == 1 else tuple(
                f"z_{j}" for j in range(k))
            self._anonymous = True
        else:
            names = (covariates,) if isinstance(covariates, str) else tuple(covariates)
            if not all(isinstance(c, str) and c for c in names) or len(set(names)) != len(names):
                raise ValueError(f"covariates must be distinct non-empty names; got "
                                 f"{covariates!r}")
            self.covariate_names = names
            self._anonymous = False
        clash = [c for c in self.covariate_names
                 if c in _RESERVED or c.startswith("coupling_")]
        if clash:
            raise ValueError(f"covariates must not be named {', '.join(map(repr, clash))} (a "
                             f"parameter of the model)")
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty string; got {name!r}")
        self.name = name
        self._structures: dict[Any, CARStructure] = {}
        self._bounds = (None if bounds is None
                        else named_bounds(self.param_names(), bounds, "bounds"))

    # -- structure -------------------------------------------------------------------------------
    @property
    def n_covariates(self) -> int:
        return len(self.covariate_names)

    @property
    def coupling_type_names(self) -> tuple[str, ...]:
        names = self.graph_spec.edge_type_names
        return names if self.directional and len(names) > 1 else ("edge",)

    def graph(self, shape: Any = None) -> Graph:
        """The graph for data of ``shape`` (a lattice's ``(H, W)``; ignored for a fixed graph)."""
        return self.structure(shape).graph

    def structure(self, shape: Any = None) -> CARStructure:
        """The compiled :class:`CARStructure` on the graph of ``shape`` (cached)."""
        if isinstance(self.graph_spec, LatticeSpec):
            if shape is None:
                raise ValueError("shape must be given: the model is declared on a lattice")
            g = self.graph_spec.build(shape)
            key = g.shape
        else:
            g, key = self.graph_spec, None
        if key not in self._structures:
            if len(self._structures) >= 8:
                self._structures.pop(next(iter(self._structures)))
            spec = self.graph_spec if isinstance(self.graph_spec, LatticeSpec) else None
            self._structures[key] = CARStructure(g, spec, self.directional)
        return self._structures[key]

    def node_shape(self, shape: Any = None) -> tuple[int, ...]:
        """Shape of one field: ``(H, W)`` on a lattice, ``(n_nodes,)`` otherwise."""
        g = self.graph(shape)
        return g.shape if g.shape is not None else (g.n_nodes,)

    def n_codings(self, shape: Any = None) -> int:
        return self.graph(shape).n_colours

    def param_names(self, covariates: Any = None, shape: Any = None) -> tuple[str, ...]:
        """``("mean", "coupling" | "coupling_<type>"..., "precision", <covariates>...)``.

        The names do not depend on the data (``covariates``, ``shape`` are accepted for
        the interface of :class:`mrfpe.models.MRF` and ignored).
        """
        types = self.coupling_type_names
        coup = ("coupling",) if len(types) == 1 else tuple(f"coupling_{t}" for t in types)
        return ("mean", *coup, "precision", *self.covariate_names)

    # -- data ------------------------------------------------------------------------------------
    def _fields(self, data: Any) -> tuple[CARStructure, np.ndarray]:
        """Structure and (M, n) float64 fields; ValueError naming ``data`` otherwise."""
        try:
            arr = np.asarray(data)
        except (TypeError, ValueError):
            raise ValueError(f"data must be an array of real numbers; got "
                             f"{type(data).__name__}") from None
        if arr.dtype.kind not in "iuf":
            raise ValueError(f"data must hold real numbers; got dtype {arr.dtype}")
        if isinstance(self.graph_spec, LatticeSpec):
            if arr.ndim not in (2, 3) or 0 in arr.shape:
                raise ValueError(f"data must be an (H, W) or (M, H, W) array of real numbers on "
                                 f"the lattice model {self.name!r}; got shape {arr.shape}")
            st = self.structure(arr.shape[-2:])
            node_shape: tuple[int, ...] = arr.shape[-2:]
        else:
            st = self.structure()
            node_shape = self.node_shape()
            if arr.shape == node_shape:
                arr = arr[None]
            if arr.shape[1:] != node_shape or arr.ndim != len(node_shape) + 1 or \
                    arr.shape[0] < 1:
                raise ValueError(f"data must have shape {node_shape} or (M, "
                                 f"{', '.join(map(str, node_shape))}) on the graph of model "
                                 f"{self.name!r}; got {np.shape(data)}")
        x = np.asarray(arr, dtype=np.float64).reshape(-1, st.n)
        if not np.all(np.isfinite(x)):
            bad = np.argwhere(~np.isfinite(x))[0]
            raise ValueError(f"data must be finite; observation {bad[0]} node {bad[1]} is "
                             f"{x[bad[0], bad[1]]}")
        return st, x

    def covariate_matrix(self, covariates: Any, shape: Any = None) -> np.ndarray:
        """Covariates as an ``(n_nodes, k)`` float array, checked against the declaration."""
        g = self.graph(shape)
        node_shape = g.shape if g.shape is not None else (g.n_nodes,)
        names, K = self.covariate_names, self.n_covariates
        if covariates is not None and isinstance(covariates, Mapping) and not covariates:
            covariates = None
        if K == 0:
            if covariates is not None:
                raise ValueError("covariates: the model declares none (build it with "
                                 "autonormal(covariates=k or names))")
            return np.zeros((g.n_nodes, 0))
        if covariates is None:
            raise ValueError(f"covariates must be given: the model declares {K} "
                             f"({', '.join(names)})")
        if isinstance(covariates, Mapping):
            if self._anonymous and set(covariates) == {"z"}:
                covariates = covariates["z"]
            else:
                if set(covariates) != set(names):
                    raise ValueError(f"covariates must hold exactly {', '.join(map(repr, names))};"
                                     f" got {', '.join(map(repr, sorted(map(str, covariates))))}")
                cols = []
                for c in names:
                    z = real_array(covariates[c], f"covariate {c!r}")
                    if z.shape not in (tuple(node_shape), (*node_shape, 1)):
                        raise ValueError(f"covariate {c!r} must have shape {tuple(node_shape)}, "
                                         f"one value per node; got {z.shape}")
                    cols.append(z.reshape(g.n_nodes))
                return np.stack(cols, axis=1)
        z = real_array(covariates, "covariates")
        ok = (*node_shape, K) if K > 1 else None
        if z.shape == tuple(node_shape) and K == 1:
            return z.reshape(g.n_nodes, 1)
        if z.shape != (*node_shape, K):
            want = f"{tuple(node_shape)} or {(*node_shape, 1)}" if ok is None else str(ok)
            raise ValueError(f"covariates must have shape {want} ({K} per node: "
                             f"{', '.join(names)}); got {z.shape}")
        return z.reshape(g.n_nodes, K)

    def default_bounds(self, data: Any, covariates: Any = None) -> np.ndarray:
        """``(d, 2)`` data-driven default bounds, before overrides.

        See :mod:`mrfpe.models.gaussian.bounds`.
        """
        st, x = self._fields(data)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        return data_bounds(st, x, Z)

    def _bounds_for(self, st: CARStructure, x: np.ndarray, Z: np.ndarray,
                    option: Any) -> np.ndarray:
        b = data_bounds(st, x, Z)
        names = self.param_names()
        for over in (self._bounds, option):
            for k, pair in (over or {}).items():
                b[names.index(k)] = pair
        bad = np.flatnonzero(b[:, 0] >= b[:, 1])
        if bad.size:
            k = names[bad[0]]
            raise ValueError(f"bounds of {k!r} must have low < high; got {b[bad[0]].tolist()}")
        return b

    # -- targets ---------------------------------------------------------------------------------
    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        st, x = self._fields(data)
        Z = self.covariate_matrix(options["covariates"], st.graph.shape)
        over = None if options["bounds"] is None else named_bounds(
            self.param_names(), options["bounds"], "bounds")
        common = {"model": self, "structure": st, "x": x, "Z": Z, "estimator": estimator}
        if estimator == "coding":
            nodes, n_codings = coding_nodes(st.graph, options["coding"])
            _check_coding(st, x, self.covariate_matrix(options["covariates"], st.graph.shape),
                          nodes, options["coding"], self.param_names())
        if estimator == "block":
            blocks = make_blocks(st.graph, options["block"])
        if st.needs_factorisation():
            st.check_sparse_size(f"deciding positive definiteness (estimator {estimator!r})")
        common["bounds"] = self._bounds_for(st, x, Z, over)
        if estimator == "pl":
            return GaussianPLTarget(**common)
        if estimator == "coding":
            return GaussianPLTarget(nodes=nodes, cost=nodes.size / st.n,
                                    extra={"coding": options["coding"],
                                           "n_codings": n_codings}, **common)
        if estimator == "block":
            return GaussianBlockTarget(blocks=blocks, extra={
                "block": jsonable(options["block"]), "n_blocks": len(blocks)}, **common)
        if estimator == "exact":
            return GaussianExactTarget(method=options["method"], **common)
        if estimator == "likelihood":
            return GaussianLikelihoodTarget(sampler=options["sampler"], **common)
        if estimator == "pl_adjusted":
            from mrfpe.models.calibration import AdjustedPL
            from mrfpe.models.options import adjusted_options

            return AdjustedPL(GaussianPLTarget(**{**common, "estimator": "pl"}),
                              GaussianLikelihoodTarget(**{**common, "estimator": "likelihood"}),
                              **adjusted_options(options))
        raise AssertionError(estimator)  # pragma: no cover - check_estimator ran

    # -- parameters in use -----------------------------------------------------------------------
    def _one_theta(self, theta: Any) -> np.ndarray:
        names = self.param_names()
        try:
            th = np.asarray(theta, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"theta must be {len(names)} finite numbers {names}; got "
                             f"{theta!r:.80}") from None
        if th.shape != (len(names),) or not np.all(np.isfinite(th)):
            raise ValueError(f"theta must be {len(names)} finite numbers {names}; got "
                             f"{np.asarray(theta).tolist()}")
        return th

    def precision_matrix(self, theta: Any, shape: Any = None) -> sp.csr_matrix:
        """The sparse precision ``Q = tau (I - sum_t beta_t W_t)`` at ``theta``."""
        st = self.structure(shape)
        th = self._one_theta(theta)
        return (th[1 + st.T] * st.A(th[1:1 + st.T])).tocsr()

    def mean_vector(self, theta: Any, shape: Any = None, covariates: Any = None) -> np.ndarray:
        """``mu = m + Z gamma`` (n_nodes,) at ``theta``."""
        st = self.structure(shape)
        th = self._one_theta(theta)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        return th[0] + Z @ th[2 + st.T:]

    def simulate(self, theta: Any, shape: Any = None, n: int = 1, *, seed: int | None = None,
                 covariates: Any = None, method: str = "auto") -> np.ndarray:
        """``n`` exact draws at ``theta``: ``(n, H, W)`` on a lattice, ``(n, n_nodes)`` otherwise.

        Parameters
        ----------
        theta : (d,) parameters (:meth:`param_names`).
        shape : (H, W) on a lattice.
        n : int >= 1
        seed : int or None
            ``numpy.random.default_rng(seed)``: the same seed gives the same draws.
        covariates : as for :meth:`target`.
        method : 'auto' | 'fft' | 'dense' | 'sparse'
            FFT on periodic lattices, a dense Cholesky factor up to
            :data:`~mrfpe.models.gaussian.structure.MAX_DENSE_SIMULATION`
            nodes, a sparse ``LDL'`` beyond (auto).

        Raises
        ------
        ValueError
            For bad arguments, or a theta outside the positive-definite region.
        """
        n = check_positive_int("n", n)
        seed = check_seed(seed)
        method = check_choice("method", method, ("auto", "fft", "dense", "sparse"))
        st = self.structure(shape)
        th = self._one_theta(theta)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        rng = np.random.default_rng(seed)
        u = st.sample(th[1:1 + st.T], float(th[1 + st.T]), n, rng, method,
                      f"theta {th.tolist()}")
        x = th[0] + Z @ th[2 + st.T:] + u
        g = st.graph
        return x.reshape(n, *(g.shape if g.shape is not None else (g.n_nodes,)))

    def describe(self) -> dict:
        out = super().describe()
        out.update({"graph": self.graph_spec.describe(), "directional": self.directional,
                    "param_names": list(self.param_names()),
                    "covariates": list(self.covariate_names),
                    "bounds": None if self._bounds is None else {
                        k: list(v) for k, v in self._bounds.items()}})
        return out

    def __repr__(self) -> str:
        return (f"GaussianMRF(name={self.name!r}, graph={self.graph_spec!r}, "
                f"directional={self.directional}, covariates={self.covariate_names})")


def _check_coding(st: CARStructure, x: np.ndarray, Z: np.ndarray, nodes: np.ndarray, k: int,
                  names: Sequence[str]) -> None:
    """Refuse a coding whose nodes cannot identify the parameters (naming it and why).

    A coding's likelihood is a regression of ``x_i`` on ``[1, (W_t (x - xbar))_i, z_i]``
    over its nodes (Besag 1974, Sec. 6.1), with the precision the inverse residual
    variance: it identifies ``theta`` only if those columns have full rank and leave a
    residual degree of freedom. Otherwise its maximum runs to the box's edge (a perfect
    fit: an infinite precision), e.g. for one node alone in its colour, or a class whose
    nodes have no neighbours (no information on the coupling).
    """
    M = x.shape[0]
    u = x - x.mean()
    cols = [np.ones((M, nodes.size))] + [(W @ u.T).T[:, nodes] for W in st.W] + [
        np.broadcast_to(Z[nodes, j], (M, nodes.size)) for j in range(Z.shape[1])]
    D = np.stack([c.reshape(-1) for c in cols], axis=1)
    p = D.shape[1]
    rank = np.linalg.matrix_rank(D) if D.shape[0] else 0
    if rank == p and D.shape[0] > p:
        return
    where = f"coding {k} ({nodes.size} node{'s' if nodes.size != 1 else ''}: " \
            f"{nodes[:8].tolist()}{' ...' if nodes.size > 8 else ''})"
    if D.shape[0] <= p:
        why = (f"{D.shape[0]} observation(s) for {p} regression coefficients and the "
               f"precision: no residual is left to estimate the precision")
    else:
        lonely = [names[1 + t] for t, W in enumerate(st.W) if not W[nodes].nnz]
        still = [names[1 + t] for t in range(st.T) if np.ptp(D[:, 1 + t]) == 0]
        why = (f"its nodes have no neighbours, so it carries no information on "
               f"{', '.join(lonely)}" if lonely else
               f"its nodes' neighbour sums are all alike (one shared neighbour, say), so "
               f"{', '.join(still)} and the mean cannot be told apart" if still else
               "its regressors (1, neighbour sums, covariates) are collinear")
    raise ValueError(f"{where} does not identify the parameters: {why}; use 'pl', 'block' or "
                     f"another coding")


def autonormal(graph: Any = 4, *, directional: bool = False,
               covariates: int | Sequence[str] = 0, periodic: bool = False,
               bounds: Any = None) -> GaussianMRF:
    """Besag's auto-normal (Gaussian CAR) model.

    ``x_i | x_-i ~ N(mu_i + sum_t beta_t sum_{j ~_t i} (x_j - mu_j), 1/tau)``,
    ``mu_i = mean + z_i . gamma``; ``theta = (mean, coupling[_<type>]..., precision,
    gamma...)``. See :mod:`mrfpe.models.gaussian` for estimators, default bounds
    and simulation.

    Parameters
    ----------
    graph : 4, 8, lattice(...), Graph, adjacency matrix or networkx graph
    directional : bool
        One coupling per direction (lattice) or edge type (graph).
    covariates : int >= 0 or sequence of str
        Anonymous covariates (``z`` or ``z_0``, ``z_1`` ...) or named ones.
    periodic : bool
        Torus boundary (lattices only).
    bounds : (d, 2) array or mapping name -> (low, high), optional
        Overrides of the default bounds. These follow the data
        (:mod:`mrfpe.models.gaussian.bounds`): the couplings' is the positive-definite
        interval, the precision's ``(0, tau_PL max(2, 1 + 10 sqrt(2 / n_min)))`` with
        ``tau_PL`` the pseudolikelihood's maximum over the precision and ``n_min`` the
        fewest terms of any estimator (the smallest coding): ten of the PL's
        curvature sds beyond its maximum, so fields scaled by ``c`` get a box scaled
        by ``1 / c^2``.

    Returns
    -------
    GaussianMRF
        Its estimators (``model.target(name, y)``): ``"pl"``, ``"coding"``,
        ``"block"``, ``"exact"``/``"likelihood"`` (the exact Gaussian likelihood, which
        exchange samples with the exact simulator) and ``"pl_adjusted"``.

    Examples
    --------
    >>> from mrfpe import models
    >>> m = models.autonormal(4)
    >>> m.param_names()
    ('mean', 'coupling', 'precision')
    >>> y = m.simulate([1.0, 0.2, 2.0], shape=(16, 16), seed=0)
    >>> m.target("likelihood", y).bounds.round(2).tolist()  # the precision's box follows y
    [[-5.43, 6.9], [-0.25, 0.25], [0.0, 4.35]]

    References
    ----------
    Besag, J. (1974). Spatial interaction and the statistical analysis of lattice
    systems. JRSS B 36(2), 192-236.
    """
    return GaussianMRF(graph, directional=directional, periodic=periodic,
                       covariates=covariates, bounds=bounds)
