"""The posterior Dataset every sampler returns (DESIGN.md, "Posterior").

Dims ``sample``, ``param``, ``step``; variables ``theta(sample, param)``,
``log_weight(sample)`` (normalised: logsumexp = 0), ``log_target(sample)``,
``map_theta(step, param)``, ``map_log_target(step)``, ``ess(step)`` and the
optional ``history_theta(step, sample, param)`` /
``history_log_weight(step, sample)``; attributes ``sampler``, ``config``
(JSON), ``seed``, ``target`` (JSON), ``mrfpe_version``, ``n_target_evals``,
``wall_time_s``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import xarray as xr
from scipy.special import logsumexp

__all__ = ["build", "normalise_log_weights", "weighted_cov", "weighted_mean", "weights"]


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
    if not np.isfinite(lw).any():
        if np.isposinf(lw).any():  # +inf spikes: equal mass on the spikes
            return np.where(np.isposinf(lw), -np.log(np.isposinf(lw).sum()), -np.inf)
        return np.full_like(lw, -np.log(lw.size))
    lw[np.isposinf(lw)] = np.nanmax(lw[np.isfinite(lw)])  # pragma: no cover - defensive
    return lw - logsumexp(lw)


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


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        return repr(o)
    return json.dumps(obj, default=default, sort_keys=True)


def build(
    theta: Any,
    log_target: Any,
    *,
    param_names: Any,
    log_weight: Any = None,
    map_theta: Any = None,
    map_log_target: Any = None,
    ess: Any = None,
    history_theta: Any = None,
    history_log_weight: Any = None,
    sampler: str,
    config: dict | None = None,
    seed: int | None = None,
    target: Any = None,
    n_target_evals: float = 0.0,
    wall_time_s: float = 0.0,
    extra_vars: dict[str, tuple] | None = None,
    extra_attrs: dict[str, Any] | None = None,
) -> xr.Dataset:
    """Assemble the posterior Dataset.

    Parameters
    ----------
    theta : (S, d) final sample set in the target's sampling space.
    log_target : (S,) target log density of each sample.
    log_weight : (S,) unnormalised log weights; ``None`` for equal weights.
    map_theta, map_log_target : (T, d), (T,) best-so-far trace per step.
        ``None`` gives a one-step trace from the final set.
    ess : (T,) effective sample size per step (NaN where meaningless).
    history_theta, history_log_weight : (T, S, d), (T, S), optional.
    target : the target object (its ``describe()`` is stored) or a dict.
    extra_vars : further ``{name: (dims, values)}`` variables (e.g. ``acceptance``).
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim != 2:
        raise ValueError(f"theta must be (sample, param); got shape {theta.shape}")
    names = [str(p) for p in param_names]
    if len(names) != theta.shape[1]:
        raise ValueError(f"{len(names)} param_names for {theta.shape[1]} parameters")
    lt = np.asarray(log_target, dtype=np.float64).reshape(-1)
    if lt.shape[0] != theta.shape[0]:
        raise ValueError(f"log_target has {lt.shape[0]} values for {theta.shape[0]} samples")
    lw = np.zeros(theta.shape[0]) if log_weight is None else np.asarray(log_weight, float)
    lw = normalise_log_weights(lw)
    if map_theta is None:
        finite = np.where(np.isnan(lt), -np.inf, lt)
        best = int(np.argmax(finite)) if finite.size else 0
        map_theta, map_log_target = theta[best][None], np.array([finite[best]])
    map_theta = np.asarray(map_theta, dtype=np.float64).reshape(-1, theta.shape[1])
    map_log_target = np.asarray(map_log_target, dtype=np.float64).reshape(-1)
    n_steps = map_theta.shape[0]
    ess = np.full(n_steps, np.nan) if ess is None else np.asarray(ess, float).reshape(-1)
    if ess.shape[0] != n_steps or map_log_target.shape[0] != n_steps:
        raise ValueError("map_theta, map_log_target and ess must have one entry per step")
    data = {
        "theta": (("sample", "param"), theta),
        "log_weight": (("sample",), lw),
        "log_target": (("sample",), lt),
        "map_theta": (("step", "param"), map_theta),
        "map_log_target": (("step",), map_log_target),
        "ess": (("step",), ess),
    }
    if history_theta is not None:
        data["history_theta"] = (("step", "sample", "param"), np.asarray(history_theta, float))
    if history_log_weight is not None:
        data["history_log_weight"] = (("step", "sample"), np.asarray(history_log_weight, float))
    for k, v in (extra_vars or {}).items():
        data[k] = v
    target_desc = target.describe() if hasattr(target, "describe") else (target or {})
    from mrfpe import __version__

    attrs = {
        "sampler": sampler,
        "config": _json(config or {}),
        "seed": -1 if seed is None else int(seed),
        "target": _json(target_desc),
        "mrfpe_version": __version__,
        "n_target_evals": float(n_target_evals),
        "wall_time_s": float(wall_time_s),
        **(extra_attrs or {}),
    }
    return xr.Dataset(data, coords={"param": names, "step": np.arange(n_steps)}, attrs=attrs)
