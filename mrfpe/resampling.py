"""Weights of a particle set and resampling it: a leaf module (numpy and scipy only).

Weight utilities: :func:`normalise_log_weights`, Kish's :func:`ess`,
:func:`perplexity`, the safe :func:`log_ratio`, the boundary check
:func:`check_log_weights` and the importance-sampling evidence estimate
:func:`log_evidence`; and resampling:

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
That lenience is for internal callers (a sampler mid-run); the posterior boundary
(:func:`mrfpe.posterior.build`, the distances, ``to_arviz``) refuses a set with
no positive weight through :func:`check_log_weights`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import logsumexp

__all__ = ["METHODS", "check_log_weights", "ess", "log_evidence", "log_ratio",
           "normalise_log_weights", "perplexity", "resample"]

METHODS = ("multinomial", "systematic", "stratified", "residual")


def normalise_log_weights(log_w: Any) -> np.ndarray:
    """Shift log weights so that logsumexp = 0.

    NaN counts as -inf. If every weight is -inf (a degenerate set) the weights
    become uniform, so downstream statistics stay defined; callers that need
    to know should check the target values.
    """
    lw = np.asarray(log_w, dtype=np.float64).copy()
    lw[np.isnan(lw)] = -np.inf
    if lw.size == 0:
        return lw
    if np.isposinf(lw).any():  # +inf spikes dominate every finite weight: equal mass on them
        return np.where(np.isposinf(lw), -np.log(np.isposinf(lw).sum()), -np.inf)
    if not np.isfinite(lw).any():
        return np.full_like(lw, -np.log(lw.size))
    with np.errstate(over="ignore"):  # huge gaps underflow to -inf, which is the answer
        lw = lw - np.max(lw)
        return lw - np.log(np.sum(np.exp(lw)))


def check_log_weights(log_w: Any, name: str = "log_weight", *,
                      allow_posinf: bool = True) -> np.ndarray:
    """Refuse a degenerate weight vector at a public boundary; return it as float64 (S,).

    Parameters
    ----------
    log_w : (S,) unnormalised log weights.
    name : what to call the weights (or the posterior they belong to) in the error.
    allow_posinf : accept ``+inf`` log weights (they dominate every finite one,
        :func:`normalise_log_weights`); ``False`` refuses them too.

    Raises
    ------
    ValueError
        If there are no weights, if every log weight is ``-inf`` or NaN (zero
        total weight: there is no distribution, and a uniform stand-in would be a
        number made up), or, with ``allow_posinf=False``, if one is ``+inf``.
    """
    lw = np.asarray(log_w, dtype=np.float64).reshape(-1)
    if lw.size == 0:
        raise ValueError(f"{name} holds no weights")
    if not allow_posinf and np.isposinf(lw).any():
        raise ValueError(f"{name} has {int(np.isposinf(lw).sum())} log weight(s) of +inf "
                         "(an infinite weight: a proposal density of 0 where the target is "
                         "positive?)")
    if not (np.isfinite(lw) | np.isposinf(lw)).any():
        what = "NaN" if np.isnan(lw).all() else "-inf or NaN"
        raise ValueError(f"{name} has zero total weight: every log weight is {what} "
                         f"({lw.size} samples); there is no distribution to describe")
    return lw


def log_evidence(log_w: Any) -> tuple[float, float]:
    """Importance-sampling estimate of a normalising constant and its standard error.

    With draws ``x_i ~ q`` from a *normalised* proposal and unnormalised log
    weights ``log w_i = log p̃(x_i) - log q(x_i)``, ``Ẑ = mean(w)`` is an unbiased
    estimate of ``Z = ∫ p̃``. Returned are ``log Ẑ`` and the delta-method
    standard error of ``log Ẑ``, ``sd(w) / (√S · mean(w))``, which in terms of
    Kish's ESS is ``√((S/ESS - 1) / (S - 1))`` (0 for equal weights).

    For a pseudolikelihood target this is the normaliser of the
    pseudolikelihood (tempered by any power), *not* a model evidence: the
    pseudolikelihood is not a density of the data. It is good for comparing
    runs on the same target (a sampler that misses mass finds a smaller ``Ẑ``),
    for checking a proposal against a target whose normaliser is known, and as
    a tempering diagnostic; not for Bayes factors between MRF models.

    The SE is itself estimated from the weights: with a heavy weight tail (a
    Pareto k̂ above 0.7, :func:`mrfpe.posterior.diagnose`) both numbers are
    unreliable, and the SE tends to be too small.

    Parameters
    ----------
    log_w : (S,) unnormalised log weights of draws from a normalised proposal.
        NaN counts as ``-inf`` (zero weight), as in :func:`normalise_log_weights`.

    Returns
    -------
    (log_z, se) : floats; ``se`` is NaN for a single sample.

    Raises
    ------
    ValueError
        For an empty vector, any ``+inf`` weight, or zero total weight.
    """
    lw = check_log_weights(log_w, "log_w", allow_posinf=False)
    lw = np.where(np.isnan(lw), -np.inf, lw)
    S = lw.size
    log_z = float(logsumexp(lw) - np.log(S))
    if S < 2:
        return log_z, float("nan")
    k = ess(lw)
    return log_z, float(np.sqrt(max(S / k - 1.0, 0.0) / (S - 1)))


def _log_weights(post_or_log_w: Any) -> np.ndarray:
    if hasattr(post_or_log_w, "data_vars"):  # a posterior Dataset
        return normalise_log_weights(post_or_log_w["log_weight"].values)
    return normalise_log_weights(np.asarray(post_or_log_w, dtype=np.float64).reshape(-1))


def ess(post_or_log_w: Any) -> float:
    """Kish's effective sample size ``(Σw)² / Σw²`` = ``1 / Σ w̃²`` (w̃ normalised).

    Accepts a posterior Dataset or an array of (unnormalised) log weights.
    Equal weights give the sample count; a single spike gives 1.
    """
    lw = _log_weights(post_or_log_w)
    if lw.size == 0:
        return 0.0
    # a max-shifted log-sum-exp in plain NumPy: samplers call this inside their softening
    # searches, where scipy's logsumexp costs ~10x more per call
    m = float(np.max(2.0 * lw))
    return float(np.exp(-(m + np.log(np.sum(np.exp(2.0 * lw - m))))))


def perplexity(post_or_log_w: Any, *, normalised: bool = True) -> float:
    """Perplexity ``exp(H)`` of the normalised weights, ``H = -Σ w̃ log w̃``.

    With ``normalised=True`` (default) it is divided by the sample count and
    lies in (0, 1], the criterion Cappé et al. use for PMC: 1 for equal
    weights, ``1/S`` for a single spike.
    """
    lw = _log_weights(post_or_log_w)
    if lw.size == 0:
        return 0.0
    w = np.exp(lw)
    h = -np.sum(w[w > 0] * lw[w > 0])
    return float(np.exp(h) / (lw.size if normalised else 1))


def log_ratio(num: Any, den: Any) -> np.ndarray:
    """``num - den`` in log space where both are finite, ``-inf`` elsewhere (a particle
    where the target or the proposal vanishes carries no weight)."""
    num, den = np.broadcast_arrays(np.asarray(num, float), np.asarray(den, float))
    ok = np.isfinite(num) & np.isfinite(den)
    return np.subtract(num, den, out=np.full(num.shape, -np.inf), where=ok)


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
