"""The data tables the engine reads: the classic CSR layout of a data term, read-only.

:class:`DataTables` holds, for a set of nodes, every observation (slot) its
labels influence and the separable radiance features of its triangles
(:mod:`mrfpe.brdf.engine.classic` explains the layout;
:func:`mrfpe.brdf.targets.energy.build_tables` builds it from a scene).
:func:`chunk_bounds` cuts the nodes into the kernels' parallel chunks.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

__all__ = ["DataTables", "chunk_bounds", "read_only"]


def read_only(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """``arrays`` marked read-only (the same objects): tables never change once built."""
    for arr in arrays:
        arr.flags.writeable = False
    return arrays


#: Variable-triangle entries per parallel chunk (features of a chunk stay in L2).
_CHUNK_ENTRIES = 4096


@dataclass(frozen=True)
class DataTables:
    """Data-energy tables of a set of nodes (all arrays indexed by *local* node).

    Attributes
    ----------
    nodes : (n,) int64
        Global node ids (lattice numbering), ascending.
    slot_ptr : (n + 1,) int64
    slot_y, slot_w : (n_slots,) float64
    slot_nvar : (n_slots,) int64
    fix_feat : (5, n_slots) float64
        Separable features of each slot's fixed triangle (zero if none).
    var_ptr : (n + 1,) int64
    var_feat : (5, n_var_entries) float64
        Features of node ``i``'s ``t``-th variable triangle at label ``s`` in
        column ``var_ptr[i] + t * B + s`` (structure of arrays).
    n_labels : int
    data_term : str
    """

    nodes: np.ndarray
    slot_ptr: np.ndarray
    slot_y: np.ndarray
    slot_w: np.ndarray
    slot_nvar: np.ndarray
    fix_feat: np.ndarray
    var_ptr: np.ndarray
    var_feat: np.ndarray
    n_labels: int
    data_term: str

    def __post_init__(self) -> None:
        read_only(self.nodes, self.slot_ptr, self.slot_y, self.slot_w, self.slot_nvar,
                  self.fix_feat, self.var_ptr, self.var_feat)

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, f).nbytes for f in (
            "nodes", "slot_ptr", "slot_y", "slot_w", "slot_nvar", "fix_feat", "var_ptr",
            "var_feat")))

    @cached_property  # read on every log_prob call; the tables never change
    def brdf_evals_per_particle(self) -> int:
        """Triangle radiances one particle costs: variable entries + fixed triangles."""
        return int(self.var_feat.shape[1] + np.count_nonzero(self.slot_nvar == 1)
                   * (self.data_term == "pixel"))

    def astype(self, dtype: Any) -> DataTables:
        """The tables with the floating-point arrays (intensities, weights, features) cast."""
        return replace(self, slot_y=self.slot_y.astype(dtype), slot_w=self.slot_w.astype(dtype),
                       fix_feat=self.fix_feat.astype(dtype), var_feat=self.var_feat.astype(dtype))

    def subset(self, local: np.ndarray) -> DataTables:
        """Tables restricted to the nodes at local indices ``local`` (ascending)."""
        local = np.asarray(local, dtype=np.int64)
        sptr, sidx = _gather(self.slot_ptr, local)
        vptr, vidx = _gather(self.var_ptr, local)
        return DataTables(
            nodes=self.nodes[local], slot_ptr=sptr, slot_y=self.slot_y[sidx],
            slot_w=self.slot_w[sidx], slot_nvar=self.slot_nvar[sidx],
            fix_feat=np.ascontiguousarray(self.fix_feat[:, sidx]), var_ptr=vptr,
            var_feat=np.ascontiguousarray(self.var_feat[:, vidx]),
            n_labels=self.n_labels, data_term=self.data_term)


def _gather(ptr: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """New CSR pointer and flat row indices of the rows of ``idx`` (no Python loop)."""
    counts = ptr[idx + 1] - ptr[idx]
    new = np.zeros(idx.shape[0] + 1, dtype=np.int64)
    np.cumsum(counts, out=new[1:])
    flat = np.repeat(ptr[idx] - new[:-1], counts) + np.arange(new[-1], dtype=np.int64)
    return new, flat


def chunk_bounds(var_ptr: np.ndarray, entries: int = _CHUNK_ENTRIES) -> np.ndarray:
    """Node ranges of the kernel's parallel chunks: about ``entries`` variable entries each.

    Depends only on the tables, never on the machine, so sums are reproducible.
    """
    n = var_ptr.shape[0] - 1
    if n == 0:
        return np.zeros(1, dtype=np.int64)
    total = int(var_ptr[-1])
    n_chunks = max(1, -(-total // entries))
    cuts = np.searchsorted(var_ptr, np.arange(1, n_chunks) * (total / n_chunks))
    return np.unique(np.concatenate([[0], cuts, [n]])).astype(np.int64)
