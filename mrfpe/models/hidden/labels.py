"""The label summaries every hidden-MRF result carries, as posterior data variables.

``label_probability`` (the node dimensions × ``state``: ``row, col`` on a lattice,
``node`` on a fixed graph) holds each node's label probabilities -- the posterior
marginals for the sampler, EM's mean-field posterior for ``mean_field_em``, the full
conditionals at the final labelling for ``icm`` --, ``label_mode`` the most probable
label of each node (the marginal-posterior-mode labelling, for the sampler) and
``label_uncertainty`` ``1 - max_a p(x_i = a)``. A sampler adds
``label_probability_mcse``, the Monte Carlo standard error of each probability.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["label_variables", "node_dims"]


def node_dims(node_shape: tuple[int, ...]) -> tuple[str, ...]:
    """``("row", "col")`` on a lattice, ``("node",)`` on a fixed graph."""
    return ("row", "col") if len(node_shape) == 2 else ("node",)


def label_variables(target: Any, prob: np.ndarray,
                    mcse: np.ndarray | None = None) -> dict[str, tuple]:
    """``extra_vars`` for :func:`mrfpe.posterior.build`: the label summaries of ``prob``
    (n, q) (and its Monte Carlo standard errors) in the data's node shape."""
    shape, dims = tuple(target.node_shape), node_dims(target.node_shape)
    prob = np.asarray(prob, dtype=np.float64)
    q = prob.shape[1]
    out = {
        "label_probability": ((*dims, "state"), prob.reshape(*shape, q)),
        "label_mode": (dims, np.argmax(prob, axis=1).astype(np.int64).reshape(shape)),
        "label_uncertainty": (dims, (1.0 - prob.max(axis=1)).reshape(shape)),
    }
    if mcse is not None:
        out["label_probability_mcse"] = ((*dims, "state"),
                                         np.asarray(mcse, np.float64).reshape(*shape, q))
    return out
