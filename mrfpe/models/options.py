"""What every model's estimators accept: option checks and the node partition of blocks.

Shared by the discrete :class:`mrfpe.models.MRF` and the Gaussian
:class:`mrfpe.models.gaussian.GaussianMRF` (and available to model plugins),
so that ``covariates``, ``bounds``, ``coding`` and ``block`` mean the same
thing, and are checked the same way, for every model.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.models.graph import Graph
from mrfpe.posterior import load, validate
from mrfpe.targets.options import Option, choice_check, optional
from mrfpe.validation import check_positive_int

__all__ = ["CODING_OPTION", "COMMON_OPTIONS", "PL_ADJUSTED_OPTIONS", "adjusted_options",
           "block_option", "block_option_spec", "bounds_option", "coding_nodes",
           "covariates_option", "jsonable", "node_blocks", "nonneg_int",
           "posterior_option"]


def covariates_option(name: str, value: Any) -> Any:
    """None, a mapping ``name -> array``, or one array (models that name no covariates)."""
    if value is None:
        return None
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, str) or not (hasattr(value, "__len__") or isinstance(value, np.ndarray)):
        raise ValueError(f"{name} must be a mapping name -> array (or one array (nodes[, k])); "
                         f"got {type(value).__name__}")
    return value


def bounds_option(name: str, value: Any) -> Any:
    """A finite ``(d, 2)`` array with lower < upper, or a mapping ``name -> (low, high)``."""
    if isinstance(value, Mapping):
        return dict(value)
    try:
        b = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite (d, 2) array or a mapping name -> (low, "
                         f"high); got {value!r:.80}") from None
    if b.ndim != 2 or b.shape[1] != 2 or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise ValueError(f"{name} must be a finite (d, 2) array with lower < upper, or a mapping "
                         f"name -> (low, high); got {np.asarray(value).tolist()!r:.80}")
    return b


def posterior_option(name: str, value: Any) -> xr.Dataset:
    """A posterior Dataset (:func:`mrfpe.posterior.validate`), or the path of a netCDF file
    :func:`mrfpe.posterior.save` wrote."""
    if isinstance(value, str | os.PathLike):
        if not Path(value).is_file():
            raise ValueError(f"{name}: no posterior file at {str(value)!r}")
        value = load(value)
    if not isinstance(value, xr.Dataset):
        raise ValueError(f"{name} must be a posterior Dataset (a sampler's result) or the path "
                         f"of one saved as netCDF; got {type(value).__name__}")
    try:
        validate(value)
    except (ValueError, TypeError) as err:
        raise ValueError(f"{name} is not a valid posterior: {err}") from None
    return value


def nonneg_int(name: str, value: Any) -> int:
    return check_positive_int(name, value, minimum=0)


def block_option(name: str, value: Any) -> Any:
    """A tile ``(bh, bw)`` (a tuple), a block size, a label per node, or a list of node arrays."""
    if value is None:
        return None
    if isinstance(value, tuple):
        if len(value) == 2 and all(isinstance(v, int | np.integer) and not isinstance(v, bool)
                                   and v >= 1 for v in value):
            return (int(value[0]), int(value[1]))
        raise ValueError(f"{name} as a tuple must be a tile (bh, bw) of positive integers; "
                         f"got {value!r}")
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        if value < 1:
            raise ValueError(f"{name} as a block size must be >= 1; got {value!r}")
        return int(value)
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "iu":
        return value.astype(np.int64)  # a block label per node
    if isinstance(value, list) and value:
        if all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in value):
            return np.asarray(value, dtype=np.int64)  # labels
        if all(np.ndim(v) == 1 for v in value):
            return [np.asarray(v, dtype=np.int64) for v in value]
    raise ValueError(f"{name} must be a tile (bh, bw) on a lattice, a block size, a block label "
                     f"per node, or a list of node-id arrays; got {value!r:.80}")


#: ``covariates`` and ``bounds``: the options every estimator of a model takes.
COMMON_OPTIONS: tuple[Option, ...] = (
    Option("covariates", "mapping name -> array | None", None, covariates_option,
           "node covariates (n_nodes[, k]) or (H, W[, k]); edge covariates (n_edges[, k])"),
    Option("bounds", "(d, 2) array | mapping name -> (low, high) | None", None,
           optional(bounds_option), "sampling-space bounds of theta (default: the model's)"),
)


#: What ``"pl_adjusted"`` (:class:`mrfpe.models.calibration.AdjustedPL`) takes, every model.
PL_ADJUSTED_OPTIONS: tuple[Option, ...] = (
    Option("mode", "'mcmc_mle' | 'mple'", "mcmc_mle", choice_check("mcmc_mle", "mple"),
           "centre at the Monte Carlo MLE, or at the MPLE (curvature only)"),
    Option("align", "'mode' | 'moments'", "moments", choice_check("mode", "moments"),
           "match mode and Hessian, or mean and covariance, to N(MLE, I^-1)"),
    Option("affine", "'cholesky' | 'transport'", "cholesky",
           choice_check("cholesky", "transport"),
           "the map's W from Cholesky factors, or the symmetric (optimal-transport) one"),
    Option("n_draws", "int >= 10", 1000, lambda n, v: check_positive_int(n, v, minimum=10),
           "simulations per Fisher information / MCMC-MLE round"),
    Option("max_rounds", "int >= 1", 10, lambda n, v: check_positive_int(n, v),
           "most Monte Carlo MLE rounds"),
    Option("pilot_sweeps", "int >= 250", 2000,
           lambda n, v: check_positive_int(n, v, minimum=250),
           "shortest pilot chain measuring the simulator's autocorrelation time"),
    Option("seed", "int >= 0", 0, nonneg_int, "seed of every simulation of the calibration"),
    Option("pl_sample", "posterior Dataset | netCDF path | None", None, optional(posterior_option),
           "a sample of exp(PL) (e.g. PMC on the PL target) whose moments are calibrated, "
           "instead of those importance-sampled from the MPLE"),
)


def adjusted_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """The :data:`PL_ADJUSTED_OPTIONS` among a target's checked options."""
    return {o.name: options[o.name] for o in PL_ADJUSTED_OPTIONS}


#: ``coding=k``: which of the graph's colour classes a coding estimator sums.
CODING_OPTION = Option("coding", "int >= 0", 0, nonneg_int,
                       "which colour class (Besag coding) 0 .. n_codings - 1")


def block_option_spec(limit: str) -> Option:
    """The ``block`` option, its help ending with the model's block-size ``limit``."""
    return Option("block", "(bh, bw) | int | labels | list of arrays | None", None,
                  block_option,
                  "tiles (bh, bw) anchored at the top-left corner on a lattice; a node "
                  "partition on a general graph; None: (2, 2) tiles on a lattice, connected "
                  f"blocks of 4 nodes on a graph; {limit}")


def coding_nodes(graph: Graph, k: int) -> tuple[np.ndarray, int]:
    """``(nodes of colour class k, number of codings)``; ValueError naming the range."""
    classes = graph.colour_classes()
    if k >= len(classes):
        raise ValueError(f"coding must be in [0, {len(classes) - 1}] (the graph has "
                         f"{len(classes)} codings); got {k}")
    return classes[k], len(classes)


def jsonable(value: Any) -> Any:
    """``value`` with arrays turned into lists (for a target's ``describe()``)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


def node_blocks(graph: Graph, block: Any) -> list[np.ndarray]:
    """Node blocks from a tile ``(bh, bw)`` (lattice), a size, labels or explicit arrays.

    Tiles are anchored at the top-left corner; partial tiles fill the right and
    bottom edges (nodes in row-major order within a tile). An integer ``m``
    grows connected blocks of up to ``m`` nodes breadth-first; ``None`` means
    ``(2, 2)`` tiles on a lattice and ``m = 4`` on a general graph. Explicit
    arrays must be disjoint, non-empty and cover every node.
    """
    n = graph.n_nodes
    if block is None:
        block = (2, 2) if graph.shape is not None else 4
    if isinstance(block, tuple):
        if graph.shape is None:
            raise ValueError("block must be a node partition (a size, labels or arrays) on a "
                             "general graph; a tile (bh, bw) needs a lattice")
        W = graph.shape[1]
        bh, bw = block
        r, c = np.divmod(np.arange(n), W)
        labels = (r // bh) * (-(-W // bw)) + c // bw
    elif isinstance(block, int):
        labels = _connected_runs(graph, block)
    elif isinstance(block, np.ndarray):
        labels = block
        if labels.shape != (n,):
            raise ValueError(f"block labels must have one entry per node ({n}); got "
                             f"{labels.shape}")
    else:
        blocks = [np.asarray(b, dtype=np.int64) for b in block]
        allnodes = np.concatenate(blocks) if blocks else np.zeros(0, np.int64)
        if any(b.size == 0 for b in blocks):
            raise ValueError("blocks must not be empty")
        if allnodes.size and (allnodes.min() < 0 or allnodes.max() >= n):
            raise ValueError(f"block node ids must lie in [0, {n - 1}]")
        if np.unique(allnodes).size != allnodes.size:
            raise ValueError("blocks must be disjoint (a node appears in two blocks)")
        if allnodes.size != n:
            raise ValueError(f"blocks must cover every node; {n - allnodes.size} of {n} are in "
                             f"no block")
        return blocks
    _, inv = np.unique(labels, return_inverse=True)
    order = np.argsort(inv, kind="stable")
    return np.split(order.astype(np.int64), np.cumsum(np.bincount(inv))[:-1])


def _connected_runs(graph: Graph, m: int) -> np.ndarray:
    """Block labels: connected groups of up to ``m`` nodes grown breadth-first in id order."""
    indptr, nbr, _ = graph.neighbours()
    labels = np.full(graph.n_nodes, -1, dtype=np.int64)
    current = 0
    for start in range(graph.n_nodes):
        if labels[start] >= 0:
            continue
        queue, size = [start], 0
        labels[start] = current
        while queue and size < m:
            v = queue.pop(0)
            size += 1
            for w in nbr[indptr[v]:indptr[v + 1]]:
                if labels[w] < 0 and size + len(queue) < m:
                    labels[w] = current
                    queue.append(int(w))
        current += 1
    return labels


def largest_block(blocks: Sequence[np.ndarray]) -> int:
    return max((b.size for b in blocks), default=0)
