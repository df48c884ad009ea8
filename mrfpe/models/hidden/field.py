"""The label field of a hidden MRF on one graph: its colour classes, neighbour lists and tables.

:class:`LabelField` is built once per compiled MRF (:class:`~mrfpe.models.design.Design`)
and read-only; it evaluates the log-potential tables at a feature vector
(:meth:`LabelField.tables`, through :meth:`Design.tables
<mrfpe.models.design.Design.tables>`) and runs the compiled label updates of
:mod:`mrfpe.models.hidden.kernels` with the emission's data term: Gibbs sweeps,
Swendsen-Wang sweeps with an external field, ICM sweeps, mean-field sweeps, and the
full conditionals of a labelling; and it builds a labelling's conditional rows for the
MRF's pseudolikelihood (:meth:`LabelField.conditional_rows`), by counting integer keys
where nodes share their rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mrfpe.models.design import ConditionalRows, Design
from mrfpe.models.hidden.kernels import (
    conditionals,
    data_factors,
    gibbs_sweep,
    gibbs_sweep_serial,
    icm_sweep,
    mean_field_sweep,
    row_counts,
    swendsen_wang_sweep,
)
from mrfpe.models.simulate import swendsen_wang_form
from mrfpe.threads import thread_budget

__all__ = ["LabelField", "Tables"]


class Tables(NamedTuple):
    """The MRF's log-potential tables at one feature vector, and its Swendsen-Wang form."""

    node: np.ndarray  # (n | 1, q)
    pair: np.ndarray  # (T | E, q, q)
    enode: np.ndarray  # (n | 1, q): exp(node), each row scaled to a largest entry of 1
    epair: np.ndarray  # ((T | E) q, q): row t q + b is exp(pair[t, :, b]), scaled likewise
    sw_field: np.ndarray | None  # (n, q): node tables plus the pair tables' per-state parts
    p_bond: np.ndarray | None  # (T | E,): 1 - exp(-J) per table
    sw_reason: str  # why there is no Swendsen-Wang form ("" when there is)


def _scaled_exp(v: np.ndarray) -> np.ndarray:
    """``exp(v - max)`` along the last axis (a constant factor per row, which a conditional
    does not see): factors of at most 1; a row of ``-inf`` gives 0s."""
    m = v.max(axis=-1, keepdims=True)
    return np.ascontiguousarray(np.exp(v - np.where(np.isfinite(m), m, 0.0)))


def _key_radix(design: Design, indptr: np.ndarray, ntab: np.ndarray) -> np.ndarray | None:
    """Digit sizes of a node's conditional row as one integer (:meth:`LabelField.
    conditional_rows`): per edge type ``t`` and state ``b``, the most type-``t`` neighbours
    of any node, plus one; ``None`` where the rows are not shared by nodes (covariates)
    or the key would not fit in 62 bits."""
    if not design.node_shared or design.pair_per_edge:
        return None
    n, T = design.graph.n_nodes, design.graph.n_edge_types
    owner = np.repeat(np.arange(n), np.diff(indptr))
    most = np.bincount(owner * T + ntab, minlength=n * T).reshape(n, T).max(axis=0)
    radix = np.repeat(most + 1, design.q)
    if not radix.size or design.q * np.prod(radix.astype(float)) >= 2.0 ** 62:
        return None
    return radix.astype(np.int64)


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
        # unsigned indices: numba skips its negative-index wraparound (as simulate's kernel)
        index = np.uint32 if 2 * g.n_edges + g.n_nodes < 2**32 else np.int64
        self.order = np.concatenate(classes).astype(index)
        self.cptr = np.cumsum([0, *map(len, classes)]).astype(np.int64)
        indptr, nbr, eidx = g.neighbours()
        self.etab = (np.arange(g.n_edges) if design.pair_per_edge
                     else np.asarray(g.edge_type)).astype(np.int64)
        self.indptr, self.nbr = indptr.astype(index), nbr.astype(index)
        self.ntab = self.etab[eidx].astype(index)
        self.edges = np.ascontiguousarray(g.edges, dtype=np.int64)
        self.radix = radix = _key_radix(design, self.indptr, self.ntab)
        self.stride = None if radix is None else self.q * np.cumprod([1, *radix[:-1]])
        for a in (self.order, self.cptr, self.etab, self.indptr, self.nbr, self.ntab,
                  self.edges, *([] if radix is None else [radix, self.stride])):
            a.setflags(write=False)

    def _graph_args(self) -> tuple:
        return self.indptr, self.nbr, self.ntab

    def tables(self, psi: np.ndarray, swendsen_wang: bool = False) -> Tables:
        """The tables at one feature vector ``psi`` (P,), and (if asked) their
        Swendsen-Wang form."""
        node, pair = self.design.tables(np.asarray(psi, dtype=np.float64)[None])
        node, pair = np.ascontiguousarray(node[0]), np.ascontiguousarray(pair[0])
        exp_tables = (_scaled_exp(node), _scaled_exp(pair.transpose(0, 2, 1)).reshape(-1, self.q))
        form = swendsen_wang_form(pair) if swendsen_wang else "not asked for"
        if isinstance(form, str):
            return Tables(node, pair, *exp_tables, None, None, form)
        J, f = form
        fold = np.zeros((self.n, self.q))
        for end in (0, 1):  # per-state parts of the pair tables move to both end nodes
            np.add.at(fold, self.edges[:, end], f[self.etab])
        field = np.broadcast_to(node, (self.n, self.q)) + fold
        return Tables(node, pair, *exp_tables, field, -np.expm1(-J), "")

    def gibbs(self, x: np.ndarray, tables: Tables, loglik: np.ndarray, u: np.ndarray,
              acc: np.ndarray | None = None) -> None:
        """One chequerboard Gibbs sweep of ``x`` (n,) in place at uniforms ``u`` (n,); adds
        the conditional probabilities to ``acc`` (n, q) if given."""
        accumulate = acc is not None
        acc = np.zeros((1, self.q)) if acc is None else acc
        with thread_budget(self.n * self.q // 4) as threads:  # as simulate's Gibbs sweep
            (gibbs_sweep if threads > 1 else gibbs_sweep_serial)(
                x, self.order, self.cptr, tables.node, tables.pair, tables.enode, tables.epair,
                *self._graph_args(), loglik, data_factors(loglik), u, acc, accumulate)

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

    def conditional_rows(self, x: np.ndarray) -> ConditionalRows:
        """The MRF's conditional rows of the labelling ``x`` (n,), as
        :meth:`Design.conditional_rows <mrfpe.models.design.Design.conditional_rows>`:
        each distinct (label, neighbours per edge type and state) once, with its count.
        Where nodes share their rows, each node's is one integer (mixed radix,
        :func:`~mrfpe.models.hidden.kernels.row_counts`), counted in one compiled pass
        (no sort of float rows)."""
        x = np.ascontiguousarray(x, dtype=np.int64)
        if self.stride is None:
            return self.design.conditional_rows(x[None])
        size = int(self.q * np.prod(self.radix))
        tally = size <= 4 * self.n
        keys, counts = np.empty(0 if tally else self.n, np.int64), np.zeros(size if tally else 0)
        row_counts(x, self.indptr, self.nbr, self.ntab, self.stride, self.q, keys, counts)
        if counts.size:
            distinct = np.flatnonzero(counts)
            counts = counts[distinct]
        else:  # too many possible rows to count in an array
            distinct, counts = np.unique(keys, return_counts=True)
        c = (distinct[:, None] // self.stride[None]) % self.radix[None]  # (R, T q)
        c = c.astype(np.float64).reshape(distinct.size, -1, self.q)
        d = self.design
        G = d.node[0][None] + np.einsum("rtb,tabp->rap", c, d.pair)
        return ConditionalRows(np.ascontiguousarray(G), distinct % self.q,
                               counts.astype(np.float64), d.may_forbid)

    def mean_field(self, P: np.ndarray, tables: Tables, loglik: np.ndarray) -> float:
        """One mean-field sweep of ``P`` (n, q) in place; the largest change."""
        with thread_budget(self.n * self.q * self.q * 8):
            return float(mean_field_sweep(P, self.order, self.cptr, tables.node, tables.pair,
                                            *self._graph_args(), loglik))
