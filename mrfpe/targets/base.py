"""The Target contract: a batched log density over parameter vectors.

A target has ``param_names``, ``bounds`` (d, 2) in its *sampling* space and
``log_prob(theta)``: (N, d) -> (N,), ``-inf`` outside the bounds and never NaN.
Samplers rely on nothing else; ``partition``, ``residuals``,
``residuals_and_jacobians`` and ``to_natural`` are optional extras that some
samplers use when present (:func:`has_residual_jacobian`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.budget import check_memory, chunk_rows
from mrfpe.validation import check_bool

__all__ = ["Target", "as_theta_batch", "has_residual_jacobian"]


def has_residual_jacobian(target: Any) -> bool:
    """Whether ``target`` offers analytic Jacobians of its residuals.

    The optional extra is a method ``residuals_and_jacobians(thetas)`` returning the
    residuals (K, m) of ``target.residuals`` at K points (K, d) and their Jacobians
    (K, m, d) in one pass (used by ``lm_multiseed``); a target whose build decides
    whether it can (a kernel family without the tables, say) says so in a boolean
    attribute ``residual_jacobian``.
    """
    return (callable(getattr(target, "residuals_and_jacobians", None))
            and bool(getattr(target, "residual_jacobian", True)))


def as_theta_batch(theta: Any, d: int, name: str = "theta") -> np.ndarray:
    """Validate a batch of parameter vectors and return it as float64 (N, d).

    A single vector of length ``d`` is accepted and returned as (1, d).

    Raises
    ------
    ValueError
        If the trailing dimension is not ``d``, the array has more than two
        dimensions, or any entry is NaN.
    """
    try:
        arr = np.asarray(theta, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an (N, {d}) or ({d},) array of numbers; got "
                         f"{type(theta).__name__} {theta!r:.60}") from None
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
    calibrated : bool or None
        ``True``: ``exp(log_prob)`` is a likelihood (or a posterior calibrated to one), so
        a posterior of it is the Bayesian posterior under the flat prior on the bounds;
        ``False``: a composite likelihood (a pseudolikelihood), whose "posterior" is a
        pseudo-posterior -- its location and spread are not the Bayesian posterior's;
        ``None`` (the default): not declared. Every posterior records it and says so
        (:func:`mrfpe.posterior.caveats`).
    """

    param_names: tuple[str, ...] = ()
    bounds: np.ndarray = np.zeros((0, 2))
    cost: float = 1.0
    #: Declared keyword options (:class:`mrfpe.targets.options.Option`); none by default.
    option_specs: tuple = ()
    #: What :func:`mrfpe.targets.get` passes as the first argument ("scene", "configurations").
    data_kind: str = "data"
    #: Is ``exp(log_prob)`` a likelihood (True), a composite likelihood (False) or undeclared?
    calibrated: bool | None = None

    @property
    def ndim(self) -> int:
        return len(self.param_names)

    def in_bounds(self, theta: np.ndarray) -> np.ndarray:
        """Boolean mask (N,) of rows inside the closed bounds."""
        b = np.asarray(self.bounds, dtype=float)
        return np.all((theta >= b[:, 0]) & (theta <= b[:, 1]), axis=1)

    def log_prob(self, theta: Any, *, progress: bool = False) -> np.ndarray:
        """Log density of each row of ``theta`` (N, d) -> (N,); -inf outside bounds.

        Parameters
        ----------
        theta : (N, d) or (d,) array
            A single (d,) vector is treated as a batch of one: the result is (1,).
        progress : bool
            Show a tqdm progress bar over the batch's chunks.

        Notes
        -----
        The batch is evaluated in chunks whose working memory stays below
        :data:`mrfpe.budget.WORKING_CHUNK_BYTES`; a batch whose input,
        output and one chunk would exceed :func:`mrfpe.targets.memory_budget`
        raises :class:`mrfpe.targets.MemoryBudgetError` before any evaluation.
        NaN values are returned as ``-inf``.
        """
        theta = as_theta_batch(theta, self.ndim)
        check_bool("progress", progress)
        n = theta.shape[0]
        per_row = float(self._row_bytes())
        chunks = chunk_rows(n, per_row)
        rows = chunks[0].stop - chunks[0].start if chunks else 0
        check_memory(n * (self.ndim + 3) * 8.0 + rows * per_row,
                     f"{type(self).__name__}.log_prob on {n} parameter vectors",
                     "evaluate fewer at a time")
        out = np.full(n, -np.inf)
        idx = np.flatnonzero(self.in_bounds(theta))
        if not idx.size:
            return out
        bar = None
        if progress:  # no bar object otherwise: a chain's single-point calls pay ~40 µs for one
            from tqdm.auto import tqdm

            bar = tqdm(total=int(idx.size), unit="theta", leave=False,
                       desc=f"{getattr(self, 'name', '') or type(self).__name__} log_prob")
        try:
            for sl in chunk_rows(int(idx.size), per_row):
                rows_ix = idx[sl]
                vals = np.asarray(self._log_prob(theta[rows_ix]), dtype=np.float64)
                out[rows_ix] = np.where(np.isnan(vals), -np.inf, vals)
                if bar is not None:
                    bar.update(rows_ix.size)
        finally:
            if bar is not None:
                bar.close()
        return out

    def _row_bytes(self) -> float:
        """Working memory of ``_log_prob`` per parameter vector (bytes; 0: never chunk)."""
        return 0.0

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
