"""Shared machinery of the population samplers (pmc, sir, ppf).

:class:`Run` counts target evaluations in full-lattice-equivalent units
(``target.cost`` per evaluated particle), keeps the best-so-far (MAP) trace
under the *full* target, records the ESS per step, drives the tqdm progress
bar and the ``callback(step, info)`` hook, and assembles the posterior through
:func:`mrfpe.posterior.build`. :func:`grid` is the thesis's evenly spaced
initial sample set, :func:`jitter` the resampling noise (Gaussian kernel truncated
to the bounds) and :func:`softened` the importance-function softening.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.posterior import build

#: Default softening power (5.69) of the thesis's algorithms (PMC (I)/(II), PPF, SIR
#: 5.2.2). The thesis does not state its value; a prototype measured that with PMC (II)
#: powers >= 0.03 collapse the cloud into bad regions and <= 0.01 leave it diffuse
#: (issue 3), so the largest non-collapsing value.
THESIS_POWER = 0.01

__all__ = ["THESIS_POWER", "Run", "check_target", "grid", "jitter", "log_kernel_mass", "log_ratio",
           "partition_or_none", "softened"]


def check_target(target: Any) -> np.ndarray:
    """The target's bounds as a finite (d, 2) float array, or ValueError naming the problem."""
    for attr in ("param_names", "bounds", "log_prob"):
        if not hasattr(target, attr):
            raise ValueError(f"target must provide {attr!r} (the Target contract); "
                             f"got {type(target).__name__}")
    b = np.asarray(target.bounds, dtype=np.float64)
    d = len(target.param_names)
    if b.shape != (d, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise ValueError(f"target.bounds must be a finite ({d}, 2) array with lower < upper; "
                         f"got {b.tolist()}")
    return b


def check_seed(seed: Any) -> None:
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)
                             or seed < 0):
        raise ValueError(f"seed must be a non-negative integer or None; got {seed!r}")


def log_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num - den`` in log space where both are finite, ``-inf`` elsewhere (a particle
    where the target or the proposal vanishes carries no weight)."""
    num, den = np.broadcast_arrays(np.asarray(num, float), np.asarray(den, float))
    ok = np.isfinite(num) & np.isfinite(den)
    return np.subtract(num, den, out=np.full(num.shape, -np.inf), where=ok)


def grid(bounds: np.ndarray, n: int) -> np.ndarray:
    """``n`` evenly spaced points in the box (the thesis's initial set, 6.6.1–6.6.2).

    The box is cut into ``m = ceil(n^(1/d))`` cells per axis and the cell
    centres are used (1000 = 10³ in 3-D gives the thesis's 10×10×10 grid); when
    ``n`` is not a perfect power, ``n`` of the ``m^d`` centres are taken at
    evenly spaced positions of the lexicographic order.
    """
    b = np.asarray(bounds, dtype=np.float64)
    d = b.shape[0]
    m = max(1, math.ceil(round(n ** (1.0 / d), 9)))
    axes = [b[j, 0] + (np.arange(m) + 0.5) / m * (b[j, 1] - b[j, 0]) for j in range(d)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    if pts.shape[0] == n:
        return pts
    return pts[np.round(np.linspace(0, pts.shape[0] - 1, n)).astype(np.int64)]


def softened(target: Any, power: float) -> Any:
    """The softened importance function ``s(g) = g^l`` (5.69–5.72) of ``target``
    (``mrfpe.targets.softening.softened``; the target itself when ``power == 1``)."""
    if power == 1.0:
        return target
    from mrfpe.targets.softening import softened as _softened

    return _softened(target, power)


def jitter(x: np.ndarray, sigma: float | np.ndarray, bounds: np.ndarray,
           rng: np.random.Generator) -> np.ndarray:
    """Add N(0, diag(σ²)) noise to each row, redrawing any row that leaves the bounds.

    ``sigma`` is a scalar (the thesis's spherical kernel, 5.12) or one scale per
    parameter (d,).

    Each new point is therefore drawn from the Gaussian kernel centred on its
    ancestor *truncated to the box* (density: :func:`log_kernel_mass` gives the
    normalising constants). Particles never leave the bounds, so none is wasted.
    """
    sigma = np.asarray(sigma, dtype=np.float64)
    if np.all(sigma <= 0):
        return x.copy()
    lo, hi = bounds[:, 0], bounds[:, 1]
    out = x + sigma * rng.standard_normal(x.shape)
    bad = np.flatnonzero(~np.all((out >= lo) & (out <= hi), axis=1))
    for _ in range(10_000):  # acceptance >= 2^-d for ancestors inside the box
        if bad.size == 0:
            return out
        out[bad] = x[bad] + sigma * rng.standard_normal((bad.size, x.shape[1]))
        bad = bad[~np.all((out[bad] >= lo) & (out[bad] <= hi), axis=1)]
    return np.clip(out, lo, hi)  # pragma: no cover - ancestors outside the box


def log_kernel_mass(centres: np.ndarray, sigma: float | np.ndarray,
                    bounds: np.ndarray) -> np.ndarray:
    """``log P(c + σZ ∈ box)`` for each centre (U,): the truncated kernels' normalisers
    (``sigma`` scalar or per parameter; the kernel is diagonal so the mass factorises)."""
    from scipy.special import ndtr

    lo = (bounds[:, 0] - centres) / sigma
    hi = (bounds[:, 1] - centres) / sigma
    return np.sum(np.log(np.clip(ndtr(hi) - ndtr(lo), 1e-300, None)), axis=1)


def partition_or_none(target: Any, k: int, kind: str) -> list[Any] | None:
    """``target.partition(k, kind)`` if the target offers it (and k > 1), else None."""
    if k <= 1 or not callable(getattr(target, "partition", None)):
        return None
    parts = list(target.partition(k, kind=kind))
    return parts or None


class Run:
    """Book-keeping of one sampler run (see the module docstring).

    Parameters
    ----------
    target : the full target (its values define the MAP trace).
    n_steps : number of steps, for the progress bar.
    progress : show a tqdm bar (stderr) with the step's ESS and extra info.
    callback : ``callback(step, info)`` after each step; ``info`` holds ``ess``,
        ``map_log_target``, ``n_target_evals`` and the sampler's extras.
    """

    def __init__(self, target: Any, n_steps: int, *, progress: bool = False,
                 callback: Callable[[int, dict], Any] | None = None, desc: str = ""):
        if callback is not None and not callable(callback):
            raise ValueError(f"callback must be callable or None; got {callback!r}")
        self.target = target
        self.d = len(target.param_names)
        self.n_evals = 0.0
        self.best_theta = np.full(self.d, np.nan)
        self.best_lt = -np.inf
        self.map_theta: list[np.ndarray] = []
        self.map_log_target: list[float] = []
        self.ess: list[float] = []
        self.callback = callback
        self.t0 = time.perf_counter()
        self._bar = None
        if progress:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=n_steps, desc=desc, leave=False, file=sys.stderr)

    def evaluate(self, fn: Any, theta: np.ndarray) -> np.ndarray:
        """``fn.log_prob(theta)`` with NaN -> -inf, counting ``fn.cost`` per row."""
        theta = np.asarray(theta, dtype=np.float64)
        lp = np.asarray(fn.log_prob(theta), dtype=np.float64).reshape(-1)
        if lp.shape[0] != theta.shape[0]:
            raise ValueError(f"log_prob returned {lp.shape[0]} values for {theta.shape[0]} rows")
        self.n_evals += float(getattr(fn, "cost", 1.0)) * theta.shape[0]
        return np.where(np.isnan(lp), -np.inf, lp)

    def offer(self, theta: np.ndarray, log_target: np.ndarray) -> None:
        """Update the best-so-far point with full-target values ``log_target`` of ``theta``."""
        if log_target.size == 0:
            return
        i = int(np.argmax(log_target))
        if log_target[i] > self.best_lt or np.isnan(self.best_theta).all():
            self.best_lt, self.best_theta = float(log_target[i]), theta[i].copy()

    def offer_candidate(self, theta: np.ndarray, score: np.ndarray) -> None:
        """Evaluate the full target at the particle with the highest ``score`` (one
        evaluation) and offer it: a cheap MAP trace when the steps use partial targets."""
        if score.size == 0 or not np.isfinite(score).any():
            return
        i = int(np.argmax(score))
        self.offer(theta[i:i + 1], self.evaluate(self.target, theta[i:i + 1]))

    def step(self, step: int, ess_value: float, **info: Any) -> None:
        """Close a step: append the MAP trace and ESS, update the bar, call the callback."""
        self.map_theta.append(self.best_theta.copy())
        self.map_log_target.append(self.best_lt)
        self.ess.append(float(ess_value))
        if self._bar is not None:
            self._bar.update(1)
            self._bar.set_postfix(ess=f"{ess_value:.1f}", map=f"{self.best_lt:.4g}",
                                  **{k: (f"{v:.3g}" if isinstance(v, float) else v)
                                     for k, v in info.items()})
        if self.callback is not None:
            self.callback(int(step), {"ess": float(ess_value), "map_log_target": self.best_lt,
                                      "map_theta": self.best_theta.copy(),
                                      "n_target_evals": self.n_evals, **info})

    def finish(self, theta: np.ndarray, log_target: np.ndarray, log_weight: np.ndarray, *,
               sampler: str, config: dict, seed: int | None,
               history_theta: Any = None, history_log_weight: Any = None,
               extra_vars: dict | None = None) -> xr.Dataset:
        """Close the bar and build the posterior Dataset."""
        if self._bar is not None:
            self._bar.close()
        mt = np.asarray(self.map_theta)
        if np.isnan(mt).any():  # no finite point was ever seen: fall back to the set
            first = theta[0]
            mt = np.where(np.isnan(mt), first, mt)
        return build(theta, log_target, param_names=self.target.param_names,
                     log_weight=log_weight, map_theta=mt, map_log_target=self.map_log_target,
                     ess=self.ess, history_theta=history_theta,
                     history_log_weight=history_log_weight, sampler=sampler, config=config,
                     seed=seed, target=self.target, n_target_evals=self.n_evals,
                     wall_time_s=time.perf_counter() - self.t0, extra_vars=extra_vars)
