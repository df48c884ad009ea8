"""Per-node residual transforms for least-squares samplers (thesis 7.10-7.12).

With ``l_i`` a node's term (``log p(x_i | x_N_i, theta)`` for the PL family):

* ``"inverse"`` (7.10, the thesis's choice): ``eps_i = 1 / p_i = exp(-l_i)``,
  clipped at ``exp(300)`` so that ``sum eps_i^2`` stays finite;
* ``"one_minus"`` (7.11): ``eps_i = 1 - exp(l_i)``;
* ``"sqrt"``: ``eps_i = sqrt(-l_i)``, so ``sum eps_i^2 = -log_prob``.

NaN residuals become ``+inf``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LOG_CLIP", "RESIDUAL_KINDS", "check_kind", "transform"]

#: Residual transforms for least-squares samplers.
RESIDUAL_KINDS = ("inverse", "one_minus", "sqrt")
#: Residuals exp(-l) are clipped at exp(LOG_CLIP) so that their squares stay finite.
LOG_CLIP = 300.0


def check_kind(kind: str) -> str:
    """``kind`` if it is one of :data:`RESIDUAL_KINDS`, else ValueError."""
    if kind not in RESIDUAL_KINDS:
        raise ValueError(f"kind must be one of {RESIDUAL_KINDS}; got {kind!r}")
    return kind


def transform(ell: np.ndarray, kind: str) -> np.ndarray:
    """Residuals ``eps`` of per-node terms ``ell`` (any shape) for ``kind`` (7.10-7.11)."""
    if kind == "inverse":
        res = np.exp(np.minimum(-ell, LOG_CLIP))
    elif kind == "one_minus":
        res = 1.0 - np.exp(np.minimum(ell, 0.0))
    else:
        res = np.sqrt(np.maximum(-ell, 0.0))
    return np.where(np.isnan(res), np.inf, res)
