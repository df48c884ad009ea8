"""The auto-normal parameters' bounds: data-driven defaults, and overrides by name or array.

Default bounds (``GaussianMRF.default_bounds``; ``bounds=`` overrides any of them):

* ``coupling_t``: ``(1 / lambda_min(W_t), 1 / lambda_max(W_t))``, the exact
  interval in which ``Q`` is PD when the other couplings are 0 (for one
  coupling type: exactly the PD interval). On a periodic 4-neighbour lattice of
  even size that is ``(-1/4, 1/4)``; on a free ``H x W`` one it is a little wider,
  ``1 / (2 cos(pi/(H+1)) + 2 cos(pi/(W+1)))``. With several coupling types the
  box spans the PD region's axis intercepts: on the closed-form lattices that is
  exactly the region's bounding box (``log_prob`` is ``-inf`` in the box's corners
  outside the region); on a typed general graph the region may reach beyond the
  box where one coupling compensates another (widen it with ``bounds=``). A coupling type
  with no edges gets ``(-1, 1)``.
* ``precision``: ``(0, 1e4 / v)``, ``v`` the residual variance of the data
  regressed on ``[1, Z]`` (``tau`` is the inverse *conditional* variance, which
  can be far above ``1 / v`` for strongly coupled fields, hence the wide cap).
* covariate coefficient ``k``: ``+-10 s / s_k`` (``s``, ``s_k`` the ranges of
  the data and of covariate ``k``).
* ``mean``: ``[min x - s - c, max x + s + c]`` with ``c = sum_k 10 s / s_k max |z_k|``,
  the largest shift the covariate box allows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from mrfpe.models.gaussian.structure import CARStructure

__all__ = ["data_bounds", "named_bounds"]


def data_bounds(st: CARStructure, x: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``(d, 2)`` default bounds (see the module docstring) of fields ``x`` (M, n), ``Z`` (n, K)."""
    lo_x, hi_x = float(x.min()), float(x.max())
    s = hi_x - lo_x if hi_x > lo_x else 1.0
    K = Z.shape[1]
    D = np.column_stack([np.ones(st.n), Z])
    coef, *_ = np.linalg.lstsq(D, x.T, rcond=None)  # (1 + K, M)
    v = float(np.mean((x.T - D @ coef) ** 2))
    v = v if v > 0 else s * s
    span_z = np.ptp(Z, axis=0) if K else np.zeros(0)
    span_z = np.where(span_z > 0, span_z, 1.0)
    gmax = 10.0 * s / span_z
    c = float(np.sum(gmax * np.abs(Z).max(axis=0))) if K else 0.0
    rows = [(lo_x - s - c, hi_x + s + c), *map(tuple, st.coupling_box()),
            (0.0, 1e4 / v), *((-g, g) for g in gmax)]
    return np.array(rows, dtype=np.float64)


def named_bounds(names: Sequence[str], value: Any, what: str) -> dict[str, tuple[float, float]]:
    """Bounds ``value`` (a ``(d, 2)`` array or a mapping name -> (low, high)) by parameter name.

    Each pair must be finite with low < high; ``what`` names ``value`` in the ValueError.
    """
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in names]
        if unknown:
            raise ValueError(f"{what} names unknown parameter(s) "
                             f"{', '.join(map(repr, unknown))}; parameters: {names}")
        items = list(value.items())
    else:
        b = np.asarray(value, dtype=np.float64)
        if b.shape != (len(names), 2):
            raise ValueError(f"{what} must be ({len(names)}, 2), one row per parameter "
                             f"{names}; got {b.shape}")
        items = list(zip(names, b, strict=True))
    out = {}
    for k, pair in items:
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ValueError(f"{what}[{k!r}] must be (low, high); got {pair!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"{what}[{k!r}] must be finite with low < high; got "
                             f"({lo}, {hi})")
        out[k] = (lo, hi)
    return out
