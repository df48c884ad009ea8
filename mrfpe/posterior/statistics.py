"""Statistics of a posterior's weighted sample set, and resampling it to equal weights.

:func:`weights`, :func:`weighted_mean`, :func:`weighted_cov`,
:func:`weighted_quantiles`, :func:`map_estimate` and :func:`resample`. Kish's
ESS and the perplexity live in the leaf module :mod:`mrfpe.resampling` (they
accept a posterior too) and are re-exported by :mod:`mrfpe.posterior`.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.resampling import normalise_log_weights
from mrfpe.resampling import resample as _resample

__all__ = ["map_estimate", "resample", "weighted_cov", "weighted_mean", "weighted_quantiles",
           "weights"]


def weights(post: xr.Dataset) -> np.ndarray:
    """Normalised linear weights (S,) of a posterior (they sum to 1)."""
    return np.exp(normalise_log_weights(post["log_weight"].values))


def weighted_mean(post: xr.Dataset) -> np.ndarray:
    """Importance-weighted mean (d,) of ``theta``."""
    return weights(post) @ post["theta"].values


def weighted_cov(post: xr.Dataset) -> np.ndarray:
    """Importance-weighted covariance (d, d) of ``theta`` (the biased, weight-normalised form)."""
    w = weights(post)
    x = post["theta"].values - w @ post["theta"].values
    return (x * w[:, None]).T @ x


def weighted_quantiles(post: xr.Dataset, q: Any) -> np.ndarray:
    """Importance-weighted quantiles of each parameter, shape (len(q), d).

    Uses the inverse of the weighted empirical CDF with linear interpolation
    between the midpoints of the sorted samples' weight masses (so equal weights
    give the Hazen quantiles, numpy's ``method="hazen"``); levels outside the
    first/last midpoint clamp to the smallest/largest sample.
    """
    qs = np.atleast_1d(np.asarray(q, dtype=np.float64))
    if qs.ndim != 1 or np.any(~(qs >= 0) | ~(qs <= 1)):
        raise ValueError(f"q must be quantile levels in [0, 1]; got {q!r}")
    w = weights(post)
    theta = post["theta"].values
    out = np.empty((qs.size, theta.shape[1]))
    for j in range(theta.shape[1]):  # d is small; each column is one sort
        order = np.argsort(theta[:, j], kind="stable")
        x, wj = theta[order, j], w[order]
        keep = wj > 0
        x, wj = x[keep], wj[keep]
        mid = np.cumsum(wj) - 0.5 * wj
        out[:, j] = np.interp(qs, mid, x)
    return out


def map_estimate(post: xr.Dataset) -> tuple[np.ndarray, float]:
    """The maximum-a-posteriori point and its target log density.

    The last entry of the best-so-far trace (``map_theta``/``map_log_target``)
    if it is finite, else the final sample with the highest ``log_target``.
    """
    lt_trace = post["map_log_target"].values
    if lt_trace.size and np.isfinite(lt_trace[-1]):
        return post["map_theta"].values[-1].copy(), float(lt_trace[-1])
    lt = np.where(np.isnan(post["log_target"].values), -np.inf, post["log_target"].values)
    best = int(np.argmax(lt))
    return post["theta"].values[best].copy(), float(lt[best])


def resample(post: xr.Dataset, n: int | None = None, method: str = "systematic",
             seed: int | None = None) -> xr.Dataset:
    """An equal-weight posterior drawn from ``post``'s weighted samples.

    Parameters
    ----------
    n : number of draws (default: the sample count of ``post``).
    method : ``"multinomial"``, ``"systematic"``, ``"stratified"`` or ``"residual"``
        (see :mod:`mrfpe.resampling`).
    seed : seed of the resampling draw.

    The trace variables and attributes are kept; the history variables, whose
    ``sample`` axis indexes other sets, and ``chain`` (resampled draws are no
    longer chains) are dropped. The attribute ``resampled`` records the method,
    count and seed. The ``diag_*`` attributes are those of ``post``: they
    describe the information in the weighted set, which resampling cannot
    increase (the equal-weight copy's own Kish ESS, ``n``, would overstate it).
    """
    n = post.sizes["sample"] if n is None else n
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be a positive integer; got {n!r}")
    idx = _resample(post["log_weight"].values, int(n), method, np.random.default_rng(seed))
    drop = [k for k in post.data_vars if k.startswith("history_") or k == "chain"]
    out = post.drop_vars(drop).isel(sample=idx)
    out["log_weight"] = (("sample",), np.full(int(n), -np.log(int(n))))
    out.attrs = dict(post.attrs)
    out.attrs["resampled"] = json.dumps({"method": method, "n": int(n), "seed": seed},
                                        sort_keys=True)
    return out
