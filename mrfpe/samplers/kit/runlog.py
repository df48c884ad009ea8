"""The run log every sampler keeps: :class:`Run`.

It counts target evaluations in full-lattice-equivalent units (``target.cost``
per evaluated particle), keeps the best-so-far (MAP) trace under the *full*
target, records the ESS per step, drives the tqdm progress bar and the
``callback(step, info)`` hook, and assembles the posterior through
:func:`mrfpe.posterior.build`.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.budget import check_memory
from mrfpe.posterior import build
from mrfpe.samplers.kit.warm import warm_target

__all__ = ["Run"]


class Run:
    """Book-keeping of one sampler run (see the module docstring).

    Parameters
    ----------
    target : the full target (its values define the MAP trace).
    n_steps : number of steps, for the progress bar (None when not known in advance).
    progress : show a tqdm bar (stderr) with the step's ESS and extra info; the
        target is evaluated once before the bar starts, so that compiling its
        kernels (:func:`mrfpe.samplers.kit.warm.warm_target`) counts neither in the ETA nor in
        the posterior's ``wall_time_s``.
    callback : ``callback(step, info)`` after each step; ``info`` holds ``ess``,
        ``map_log_target``, ``n_target_evals`` and the sampler's extras.
    rows : how many parameter vectors (particles, kept states, history rows, one
        float per step) the sampler will hold at once: checked against the memory
        budget (:func:`mrfpe.targets.memory_budget`) before anything is allocated,
        so an oversized setting fails at once, not with a bare ``MemoryError``.
    check_first_step : raise at the first :meth:`step` if no point evaluated so far was
        finite (:meth:`require_support`); ``False`` for samplers whose first step sees
        too few points to judge (a multi-start optimiser's first optimum).
    """

    def __init__(self, target: Any, n_steps: int | None, *, progress: bool = False,
                 callback: Callable[[int, dict], Any] | None = None, desc: str = "",
                 rows: float = 0, check_first_step: bool = True):
        if callback is not None and not callable(callback):
            raise ValueError(f"callback must be callable or None; got {callback!r}")
        self.target = target
        self.d = len(target.param_names)
        check_memory(8.0 * (self.d + 4) * float(rows),
                     f"sampler {desc or '?'} holding {float(rows):.3g} rows of {self.d} "
                     "parameters", "lower its sample, chain or step counts")
        self.n_evals = 0.0
        self.n_points = 0  # points evaluated, and whether any was finite (no support?)
        self.seen_finite = False
        self.check_first_step = check_first_step
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

            warm_target(target)  # compile before the bar, whose ETA would count it 20-fold
            self.t0 = time.perf_counter()  # and before the clock: compiling is not sampling
            self._bar = tqdm(total=n_steps, desc=desc, leave=False, file=sys.stderr)

    def evaluate(self, fn: Any, theta: np.ndarray) -> np.ndarray:
        """``fn.log_prob(theta)`` with NaN -> -inf, counting ``fn.cost`` per row.

        Raises ``ValueError`` at once if a value is ``+inf``: no log density takes
        it, and every weight or acceptance computed from it would be NaN.
        """
        theta = np.asarray(theta, dtype=np.float64)
        lp = np.asarray(fn.log_prob(theta), dtype=np.float64).reshape(-1)
        if lp.shape[0] != theta.shape[0]:
            raise ValueError(f"log_prob returned {lp.shape[0]} values for {theta.shape[0]} rows")
        self.n_evals += float(getattr(fn, "cost", 1.0)) * theta.shape[0]
        if np.isposinf(lp).any():
            i = int(np.flatnonzero(np.isposinf(lp))[0])
            raise ValueError(f"the target's log_prob is +inf at {int(np.isposinf(lp).sum())} of "
                             f"{lp.size} points (e.g. theta={theta[i].tolist()}); a log "
                             "density must be finite or -inf")
        self.n_points += lp.size
        self.seen_finite = self.seen_finite or bool(np.isfinite(lp).any())
        return np.where(np.isnan(lp), -np.inf, lp)

    def require_support(self, where: str) -> None:
        """Raise ``ValueError`` if every point evaluated so far was ``-inf`` or NaN.

        Samplers call it (through :func:`draw_in_support` and the first
        :meth:`step`) so that a target without support in its bounds stops the run
        before the work, instead of ending as a posterior of meaningless points.
        """
        if self.n_points and not self.seen_finite:
            raise ValueError(f"the target's log_prob is -inf or NaN at all {self.n_points} "
                             f"points evaluated {where}: it has no support in its bounds that "
                             "the sampler can find (is the data or the target misconfigured?)")

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
        """Close a step: append the MAP trace and ESS, update the bar, call the callback.

        The first step raises ``ValueError`` if no point evaluated so far was finite
        (:meth:`require_support`).
        """
        if not self.ess and self.check_first_step:
            self.require_support("in the first step")
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

    def finish(self, theta: np.ndarray, log_target: np.ndarray, log_weight: np.ndarray | None,
               *, sampler: str, config: dict, seed: int | None, **build_kwargs: Any,
               ) -> xr.Dataset:
        """Close the bar and build the posterior Dataset.

        The run's own records (MAP trace, ESS trace, evaluation count, wall
        time, target) are passed to :func:`mrfpe.posterior.build` together with
        ``build_kwargs`` — ``history_theta``/``history_log_weight`` (see
        :meth:`History.build_kwargs <mrfpe.samplers.kit.History.build_kwargs>`),
        ``extra_vars``, ``extra_attrs`` (e.g. a ``log_evidence``) and whatever
        options ``build`` accepts (per-sample chain ids, diagnostics). This is
        the diagnostics hook: every sampler's posterior passes through here.
        """
        if self._bar is not None:
            self._bar.close()
        mt = np.asarray(self.map_theta)
        if np.isnan(mt).any():  # no finite point was ever seen: fall back to the set
            first = theta[0]
            mt = np.where(np.isnan(mt), first, mt)
        return build(theta, log_target, param_names=self.target.param_names,
                     log_weight=log_weight, map_theta=mt, map_log_target=self.map_log_target,
                     ess=self.ess, sampler=sampler, config=config, seed=seed,
                     target=self.target, n_target_evals=self.n_evals,
                     wall_time_s=time.perf_counter() - self.t0, **build_kwargs)
