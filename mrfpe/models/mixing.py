"""How fast a model's simulator mixes: the autocorrelation time of its sufficient statistics.

Doubly-intractable methods draw auxiliary data from the model by MCMC
(Gibbs or Swendsen-Wang sweeps); the draws are only as good as the chain is
long compared with its integrated autocorrelation time ``τ``. This module
measures ``τ`` at a parameter value so that samplers and calibrations can
choose chain lengths and flag runs whose chains were too short.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["PILOT_CHUNK", "autocorrelation_time", "statistics_tau", "summary_statistics"]

#: Sweeps per pilot chunk when measuring the autocorrelation time.
PILOT_CHUNK = 250


def summary_statistics(target: Any, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Per-draw statistics (n, k): sufficient statistics where offered, else log f(y | θ)."""
    stats = getattr(target, "sufficient_statistics", None)
    if callable(stats):
        return np.asarray(stats(y), dtype=np.float64)
    return np.array([target.unnormalised(theta, yi[None])[0] for yi in y])[:, None]


def statistics_tau(s: np.ndarray) -> float:
    """The largest integrated autocorrelation time (emcee's estimator) over the columns of
    a chain of statistics ``s`` (n, k), each standardised; 1 when none of them moves."""
    import logging

    from emcee.autocorr import integrated_time

    # emcee logs a caution when the chain is short; the callers judge the length themselves
    logging.getLogger("emcee.autocorr").setLevel(logging.ERROR)
    sd = s.std(axis=0)
    moving = sd > 0
    if not moving.any():
        return 1.0
    z = (s[:, moving] - s[:, moving].mean(axis=0)) / sd[moving]
    return float(np.max(integrated_time(z[:, None, :], quiet=True)))


def autocorrelation_time(target: Any, theta: np.ndarray, *, seed: int,
                         max_sweeps: int = 20000, min_sweeps: int = 2000) -> float:
    """Integrated autocorrelation time (sweeps) of the target's simulator at ``theta``.

    Runs the simulator one sweep per draw, started from the data, in chunks of
    :data:`PILOT_CHUNK` sweeps until ``emcee.autocorr.integrated_time`` is
    trustworthy (the chain is at least 50 τ and ``min_sweeps`` long) or
    ``max_sweeps`` is reached; returns the largest τ over the standardised
    statistics (``inf`` when the chain is shorter than 20 τ at the cap).
    """
    rng = np.random.default_rng(seed)
    x0 = getattr(target, "x", None)
    init: Any = "random" if x0 is None else x0[0]
    rows, length = [], 0
    while True:
        y = target.simulate(theta, n=PILOT_CHUNK, seed=int(rng.integers(2**63)), init=init,
                            n_sweeps=1, thin=1)
        init = y[-1]
        rows.append(summary_statistics(target, y, theta))
        length += PILOT_CHUNK
        s = np.concatenate(rows)
        if not np.any(s.std(axis=0) > 0):
            return 1.0  # the statistics do not move at all: nothing to wait for
        tau = statistics_tau(s)
        if length >= min_sweeps and length >= 50 * tau:
            return tau
        if length >= max_sweeps:
            return math.inf if length < 20 * tau else tau
