"""The auto-normal estimators' declared options, and the block partitions of ``"block"``.

:data:`ESTIMATOR_OPTIONS` states what ``GaussianMRF.target(estimator, data, **options)``
accepts per estimator (:data:`COMMON`, ``covariates`` and ``bounds``, for all of them),
checked before any work; :func:`make_blocks` turns the ``block`` option into a node
partition whose blocks the block pseudolikelihood can factorise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mrfpe.models.graph import Graph
from mrfpe.models.options import (
    CODING_OPTION,
    COMMON_OPTIONS,
    PL_ADJUSTED_OPTIONS,
    block_option_spec,
    node_blocks,
)
from mrfpe.targets.options import Option, choice_check

__all__ = ["COMMON", "ESTIMATOR_OPTIONS", "MAX_BLOCK_NODES", "make_blocks"]

#: Largest block of the block pseudolikelihood (a dense ``m x m`` factorisation per theta).
MAX_BLOCK_NODES = 400

COMMON = COMMON_OPTIONS

ESTIMATOR_OPTIONS: dict[str, tuple[Option, ...]] = {
    "pl": COMMON,
    "coding": (*COMMON, CODING_OPTION),
    "block": (*COMMON, block_option_spec(f"blocks of at most {MAX_BLOCK_NODES} nodes")),
    "exact": (*COMMON, Option("method", "'auto' | 'eigen' | 'sparse'", "auto",
                              choice_check("auto", "eigen", "sparse"),
                              "log det Q from the known spectrum or a sparse LU per theta")),
    "likelihood": (*COMMON, Option("sampler", "'auto' | 'fft' | 'dense' | 'sparse'", "auto",
                                   choice_check("auto", "fft", "dense", "sparse"),
                                   "the exact simulator used for auxiliary draws")),
    "pl_adjusted": (*COMMON, *PL_ADJUSTED_OPTIONS),
}


def make_blocks(graph: Graph, block: Any) -> list[np.ndarray]:
    """:func:`mrfpe.models.options.node_blocks`, each of at most :data:`MAX_BLOCK_NODES` nodes."""
    blocks = node_blocks(graph, block)
    _check_block_sizes(blocks)
    return blocks


def _check_block_sizes(blocks: Sequence[np.ndarray]) -> None:
    m = max((b.size for b in blocks), default=0)
    if m > MAX_BLOCK_NODES:
        raise ValueError(f"block of {m} nodes is too large: block pseudolikelihood factorises "
                         f"an (m, m) matrix per block structure and theta, m <= "
                         f"{MAX_BLOCK_NODES} (use smaller blocks, or 'exact')")
