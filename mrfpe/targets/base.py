"""The Target contract: a batched log density over parameter vectors.

A target has ``param_names``, ``bounds`` (d, 2) in its *sampling* space and
``log_prob(theta)``: (N, d) -> (N,), ``-inf`` outside the bounds and never NaN.
Samplers rely on nothing else; ``partition``, ``residuals`` and ``to_natural``
are optional extras that some samplers use when present.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["Target", "as_theta_batch"]


def as_theta_batch(theta: Any, d: int, name: str = "theta") -> np.ndarray:
    """Validate a batch of parameter vectors and return it as float64 (N, d).

    A single vector of length ``d`` is accepted and returned as (1, d).

    Raises
    ------
    ValueError
        If the trailing dimension is not ``d``, the array has more than two
        dimensions, or any entry is NaN.
    """
    arr = np.asarray(theta, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != d:
        raise ValueError(f"{name} must have shape (N, {d}) or ({d},); got {np.shape(theta)}")
    if np.isnan(arr).any():
        raise ValueError(f"{name} contains NaN (rows {np.flatnonzero(np.isnan(arr).any(1))[:5]})")
    return arr


class Target:
    """Base class for batched log-density targets.

    Subclasses set ``param_names`` and ``bounds`` and implement
    ``_log_prob(theta)`` for in-bounds rows only; the base class validates the
    batch, returns ``-inf`` outside the bounds and maps NaN to ``-inf``.

    Attributes
    ----------
    param_names : tuple of str
    bounds : ndarray, shape (d, 2)
        Lower and upper bound of each parameter in the sampling space.
    cost : float
        Cost of one evaluation in full-lattice-equivalent evaluations (1 for a
        full target, ``1/k`` for one of ``k`` sub-lattices). Samplers add up
        ``cost`` per evaluated particle to report ``n_target_evals``.
    """

    param_names: tuple[str, ...] = ()
    bounds: np.ndarray = np.zeros((0, 2))
    cost: float = 1.0

    @property
    def ndim(self) -> int:
        return len(self.param_names)

    def in_bounds(self, theta: np.ndarray) -> np.ndarray:
        """Boolean mask (N,) of rows inside the closed bounds."""
        b = np.asarray(self.bounds, dtype=float)
        return np.all((theta >= b[:, 0]) & (theta <= b[:, 1]), axis=1)

    def log_prob(self, theta: Any) -> np.ndarray:
        """Log density of each row of ``theta`` (N, d) -> (N,); -inf outside bounds."""
        theta = as_theta_batch(theta, self.ndim)
        out = np.full(theta.shape[0], -np.inf)
        inside = self.in_bounds(theta)
        if inside.any():
            vals = np.asarray(self._log_prob(theta[inside]), dtype=np.float64)
            out[inside] = np.where(np.isnan(vals), -np.inf, vals)
        return out

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_natural(self, theta: Any) -> np.ndarray:
        """Map sampling-space parameters to natural units (identity by default)."""
        return np.asarray(theta, dtype=np.float64)

    def describe(self) -> dict:
        """JSON-serialisable description stored in a posterior's ``target`` attribute."""
        return {"class": type(self).__name__, "param_names": list(self.param_names),
                "bounds": np.asarray(self.bounds).tolist()}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(param_names={self.param_names})"
