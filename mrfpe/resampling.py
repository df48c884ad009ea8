"""Resampling a weighted particle set: indices of the particles to keep.

``resample(log_w, n, method, rng)`` returns ``n`` indices drawn in proportion
to the weights ``exp(log_w)``. Every scheme is unbiased (each index's expected
count is ``n · w̃_i``); they differ in variance:

- ``multinomial``: ``n`` independent draws I ~ M(1, w̃), the thesis's resampling
  step (5.10–5.12, Appendix A). Highest variance.
- ``stratified``: one uniform draw in each of the ``n`` strata [(i)/n, (i+1)/n).
- ``systematic``: one uniform offset shared by all strata (lowest variance in
  practice; the usual default).
- ``residual``: ``floor(n w̃_i)`` deterministic copies, the remainder drawn
  multinomially from the residual weights.

Degenerate weights are handled, never crashed on: NaN counts as ``-inf``, all
``-inf`` weights resample uniformly, a single finite (or ``+inf``) weight takes
every draw. Zero-weight particles are never selected while some weight is positive.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.posterior import normalise_log_weights

__all__ = ["METHODS", "resample"]

METHODS = ("multinomial", "systematic", "stratified", "residual")


def _cdf(w: np.ndarray) -> np.ndarray:
    """Cumulative weights with the tail pinned to exactly 1 after the last positive weight,
    so rounding can neither run past the end nor select a zero-weight particle."""
    cdf = np.cumsum(w)
    last = int(np.flatnonzero(w > 0)[-1])
    cdf /= cdf[last]
    cdf[last:] = 1.0
    return cdf


def _invert(cdf: np.ndarray, u: np.ndarray) -> np.ndarray:
    # index i is chosen when cdf[i-1] <= u < cdf[i]; zero-weight i has an empty interval
    return np.minimum(np.searchsorted(cdf, u, side="right"), cdf.size - 1)


def resample(log_w: Any, n: int, method: str = "multinomial",
             rng: np.random.Generator | int | None = None) -> np.ndarray:
    """Indices (n,) of the particles selected from weights ``exp(log_w)``.

    Parameters
    ----------
    log_w : (S,) unnormalised log weights.
    n : number of indices to draw (>= 1).
    method : one of :data:`METHODS`.
    rng : ``numpy.random.Generator`` (or a seed for one).

    Raises
    ------
    ValueError
        For an empty weight vector, ``n < 1`` or an unknown method.
    """
    lw = np.asarray(log_w, dtype=np.float64).reshape(-1)
    if lw.size == 0:
        raise ValueError("log_w must hold at least one weight")
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be a positive integer; got {n!r}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    w = np.exp(normalise_log_weights(lw))
    n = int(n)
    if method == "multinomial":
        return _invert(_cdf(w), rng.random(n))
    if method == "stratified":
        return _invert(_cdf(w), (np.arange(n) + rng.random(n)) / n)
    if method == "systematic":
        return _invert(_cdf(w), (np.arange(n) + rng.random()) / n)
    # residual
    copies = np.floor(n * w).astype(np.int64)
    idx = np.repeat(np.arange(w.size), copies)
    rest = n - idx.size
    if rest > 0:
        resid = n * w - copies
        extra = _invert(_cdf(resid), rng.random(rest)) if resid.sum() > 0 else \
            _invert(_cdf(w), rng.random(rest))
        idx = np.concatenate([idx, extra])
    return rng.permutation(idx)
