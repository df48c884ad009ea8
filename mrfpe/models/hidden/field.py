"""The label field of a hidden MRF on one graph: its colour classes, neighbour lists and tables.

:class:`LabelField` is built once per compiled MRF (:class:`~mrfpe.models.design.Design`)
and read-only; it evaluates the log-potential tables at a feature vector
(:meth:`LabelField.tables`, through :meth:`Design.tables
<mrfpe.models.design.Design.tables>`) and runs the compiled label updates of
:mod:`mrfpe.models.hidden.kernels` with the emission's data term: Gibbs sweeps,
Swendsen-Wang sweeps with an external field, ICM sweeps, mean-field sweeps, and the
full conditionals of a labelling.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mrfpe.models.design import Design
from mrfpe.models.hidden.kernels import (
    conditionals,
    gibbs_sweep,
    icm_sweep,
    log_pseudolikelihood,
    mean_field_sweep,
    swendsen_wang_sweep,
)
from mrfpe.models.simulate import swendsen_wang_form
from mrfpe.threads import thread_budget

__all__ = ["LabelField", "Tables"]


class Tables(NamedTuple):
    """The MRF's log-potential tables at one feature vector, and its Swendsen-Wang form."""

    node: np.ndarray  # (n | 1, q)
    pair: np.ndarray  # (T | E, q, q)
    sw_field: np.ndarray | None  # (n, q): node tables plus the pair tables' per-state parts
    p_bond: np.ndarray | None  # (T | E,): 1 - exp(-J) per table
    sw_reason: str  # why there is no Swendsen-Wang form ("" when there is)


class LabelField:
    """Colour classes, neighbour lists and tables of a compiled MRF (see the module docstring).

    Parameters
    ----------
    design : Design
    """

    def __init__(self, design: Design) -> None:
        g = design.graph
        self.design, self.n, self.q = design, int(g.n_nodes), int(design.q)
        classes = g.colour_classes()
        self.order = np.concatenate(classes).astype(np.int64)
        self.cptr = np.cumsum([0, *map(len, classes)]).astype(np.int64)
        indptr, nbr, eidx = g.neighbours()
        self.etab = (np.arange(g.n_edges) if design.pair_per_edge
                     else np.asarray(g.edge_type)).astype(np.int64)
        self.indptr, self.nbr = indptr.astype(np.int64), nbr.astype(np.int64)
        self.ntab = self.etab[eidx].astype(np.int64)
        self.edges = np.ascontiguousarray(g.edges, dtype=np.int64)
        for a in (self.order, self.cptr, self.etab, self.indptr, self.nbr, self.ntab,
                  self.edges):
            a.setflags(write=False)

    def _graph_args(self) -> tuple:
        return self.indptr, self.nbr, self.ntab

    def tables(self, psi: np.ndarray, swendsen_wang: bool = False) -> Tables:
        """The tables at one feature vector ``psi`` (P,), and (if asked) their
        Swendsen-Wang form."""
        node, pair = self.design.tables(np.asarray(psi, dtype=np.float64)[None])
        node, pair = np.ascontiguousarray(node[0]), np.ascontiguousarray(pair[0])
        form = swendsen_wang_form(pair) if swendsen_wang else "not asked for"
        if isinstance(form, str):
            return Tables(node, pair, None, None, form)
        J, f = form
        fold = np.zeros((self.n, self.q))
        for end in (0, 1):  # per-state parts of the pair tables move to both end nodes
            np.add.at(fold, self.edges[:, end], f[self.etab])
        field = np.broadcast_to(node, (self.n, self.q)) + fold
        return Tables(node, pair, field, -np.expm1(-J), "")

    def gibbs(self, x: np.ndarray, tables: Tables, loglik: np.ndarray, u: np.ndarray,
              acc: np.ndarray | None = None) -> None:
        """One chequerboard Gibbs sweep of ``x`` (n,) in place; adds the conditional
        probabilities to ``acc`` (n, q) if given."""
        accumulate = acc is not None
        acc = np.zeros((1, self.q)) if acc is None else acc
        with thread_budget(self.n * self.q * 8):
            gibbs_sweep(x, self.order, self.cptr, tables.node, tables.pair,
                          *self._graph_args(), loglik, u, acc, accumulate)

    def swendsen_wang(self, x: np.ndarray, tables: Tables, loglik: np.ndarray,
                      rng: np.random.Generator) -> None:
        """One Swendsen-Wang sweep with the data as external field (Higdon 1998), in place."""
        if tables.sw_field is None:
            raise ValueError(f"labels='swendsen_wang' needs ferromagnetic Potts pair tables "
                             f"(J [a == b] + per-state terms, J >= 0): {tables.sw_reason}")
        u_bond, u_cluster = rng.random(self.edges.shape[0]), rng.random(self.n)
        swendsen_wang_sweep(x, np.ascontiguousarray(tables.sw_field + loglik), self.edges,
                              self.etab, tables.p_bond, u_bond, u_cluster)

    def icm(self, x: np.ndarray, tables: Tables, loglik: np.ndarray) -> int:
        """One ICM sweep of ``x`` in place; how many nodes changed."""
        with thread_budget(self.n * self.q * 8):
            return int(icm_sweep(x, self.order, self.cptr, tables.node, tables.pair,
                                   *self._graph_args(), loglik))

    def conditionals(self, x: np.ndarray, tables: Tables, loglik: np.ndarray) -> np.ndarray:
        """(n, q): every node's full conditional given its neighbours in ``x`` and its data."""
        out = np.empty((self.n, self.q))
        conditionals(np.asarray(x, np.int64), tables.node, tables.pair, *self._graph_args(),
                       loglik, out)
        return out

    def log_pl(self, x: np.ndarray, tables: Tables) -> float:
        """Besag's log pseudolikelihood of the labels ``x`` at the tables (one pass)."""
        return float(log_pseudolikelihood(np.asarray(x, np.int64), tables.node, tables.pair,
                                          *self._graph_args()))

    def mean_field(self, P: np.ndarray, tables: Tables, loglik: np.ndarray) -> float:
        """One mean-field sweep of ``P`` (n, q) in place; the largest change."""
        with thread_budget(self.n * self.q * self.q * 8):
            return float(mean_field_sweep(P, self.order, self.cptr, tables.node, tables.pair,
                                            *self._graph_args(), loglik))
