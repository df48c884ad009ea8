"""mrfpe-smc: an adaptive-tempering Sequential Monte Carlo sampler, as a third-party plugin.

It registers itself under the ``mrfpe.samplers`` entry-point group (see this
package's ``pyproject.toml``) and uses only mrfpe's public API: the Target
contract (``param_names``, ``bounds``, ``log_prob``, optional ``cost``),
:func:`mrfpe.posterior.build` and the validators of :mod:`mrfpe.samplers.base`.

The algorithm (Del Moral, Doucet & Jasra 2006; Jasra et al. 2011): particles
move from the uniform distribution on the target's box (β = 0) to the target
(β = 1) through the tempered densities π_β(θ) ∝ 1_box(θ) · p(θ)^β. At each stage

1. the next β is found by bisection so that the effective sample size of the
   incremental weights w_i = p(θ_i)^(β' − β) equals ``ess_fraction`` × N;
2. the particles are resampled systematically with those weights;
3. each particle makes random-walk Metropolis moves targeting π_β', with a
   Gaussian proposal whose covariance is the particle cloud's covariance times
   s², s adapted from stage to stage towards ``target_acceptance``; the number
   of moves per stage is chosen from the last acceptance rate so that a particle
   moves at least once with probability ``mixing`` (between ``min_moves`` and
   ``max_moves``).

The product of the mean incremental weights estimates the normalising constant
relative to the box: ``attrs["log_evidence"]`` = log ∫ p(θ) dθ / vol(box) (−inf
when no particle finds the support; if ``max_stages`` stops the run early,
``attrs["final_beta"]`` < 1 and the estimate is that of p^β).
The final, equally weighted cloud at β = 1 is the sample set; ``step`` indexes
the stages (step 0 is the initial uniform draw), with ``beta(step)``,
``acceptance(step)`` and ``n_moves(step)`` as extra variables.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from scipy.special import logsumexp

from mrfpe.posterior import build
from mrfpe.samplers.base import Sampler, check_positive_int, check_range

__all__ = ["AdaptiveTemperingSMC", "next_temperature", "systematic_resample"]
__version__ = "0.1.0"


def systematic_resample(log_w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Ancestor indices (N,) by systematic resampling: one uniform u, points (u + i)/N."""
    w = np.exp(log_w - logsumexp(log_w))
    n = w.size
    cum = np.cumsum(w)
    cum[-1] = 1.0  # guard against round-off
    return np.searchsorted(cum, (rng.random() + np.arange(n)) / n, side="right").clip(0, n - 1)


def _ess(log_w: np.ndarray) -> float:
    if not np.isfinite(log_w).any():
        return 0.0
    return float(np.exp(2 * logsumexp(log_w) - logsumexp(2 * log_w)))


def next_temperature(log_target: np.ndarray, beta: float, ess_target: float,
                     tol: float = 1e-10) -> float:
    """The β' in (β, 1] whose incremental weights p^(β'−β) have ESS = ``ess_target``.

    The ESS decreases as β' grows, so bisection brackets it; β' = 1 when even
    the full step keeps the ESS above the target.
    """
    def ess_at(b: float) -> float:
        with np.errstate(invalid="ignore"):
            return _ess(np.where(np.isfinite(log_target), (b - beta) * log_target, -np.inf))

    if ess_at(1.0) >= ess_target:
        return 1.0
    lo, hi = beta, 1.0
    while hi - lo > tol * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        if ess_at(mid) >= ess_target:
            lo = mid
        else:
            hi = mid
    return max(lo, np.nextafter(beta, 2.0))  # always advance


class AdaptiveTemperingSMC(Sampler):
    """Adaptive-tempering SMC: ESS-chosen temperatures, systematic resampling, tuned RW moves.

    Parameters
    ----------
    n_particles : int
        Particles N (default 1000, as the thesis's PMC runs).
    ess_fraction : float
        Target ESS of each stage's incremental weights, as a fraction of N.
    target_acceptance : float
        Acceptance rate the proposal scale is steered to.
    mixing : float
        Probability that a particle moves at least once per stage, which sets
        the number of moves from the last acceptance rate.
    min_moves, max_moves : int
        Bounds on the Metropolis moves per stage.
    max_stages : int
        Safety cap on the number of tempering stages.
    """

    name = "smc"
    conformance: ClassVar[dict] = {"quick_config": {"n_particles": 300, "max_moves": 5}}

    def __init__(self, n_particles: int = 1000, ess_fraction: float = 0.5,
                 target_acceptance: float = 0.234, mixing: float = 0.9, min_moves: int = 2,
                 max_moves: int = 10, max_stages: int = 500):
        self.n_particles = check_positive_int("n_particles", n_particles, minimum=2)
        self.ess_fraction = check_range("ess_fraction", ess_fraction, 0.0, 1.0,
                                        low_open=True, high_open=True)
        self.target_acceptance = check_range("target_acceptance", target_acceptance, 0.0, 1.0,
                                             low_open=True, high_open=True)
        self.mixing = check_range("mixing", mixing, 0.0, 1.0, low_open=True, high_open=True)
        self.min_moves = check_positive_int("min_moves", min_moves)
        self.max_moves = check_positive_int("max_moves", max_moves)
        if self.max_moves < self.min_moves:
            raise ValueError(f"max_moves must be >= min_moves ({self.min_moves}); "
                             f"got {max_moves}")
        self.max_stages = check_positive_int("max_stages", max_stages)

    # -- helpers -------------------------------------------------------------
    @staticmethod
    def _box(target: Any) -> np.ndarray:
        for attr in ("param_names", "bounds", "log_prob"):
            if not hasattr(target, attr):
                raise ValueError(f"target must provide {attr!r}; got {type(target).__name__}")
        b = np.asarray(target.bounds, dtype=np.float64)
        d = len(target.param_names)
        if b.shape != (d, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
            raise ValueError(f"target.bounds must be a finite ({d}, 2) array with lower < upper")
        return b

    def _moves(self, acc: float) -> int:
        if acc <= 0.0:
            return self.max_moves
        if acc >= 1.0:
            return self.min_moves
        k = math.ceil(math.log(1.0 - self.mixing) / math.log(1.0 - acc))
        return int(min(self.max_moves, max(self.min_moves, k)))

    # -- the sampler ---------------------------------------------------------
    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callable[[int, dict], Any] | None = None):
        """Temper from the uniform box to ``target``; return the posterior Dataset."""
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)
                                 or seed < 0):
            raise ValueError(f"seed must be a non-negative integer or None; got {seed!r}")
        if callback is not None and not callable(callback):
            raise ValueError(f"callback must be callable or None; got {callback!r}")
        b = self._box(target)
        lo, hi = b[:, 0], b[:, 1]
        n, d = self.n_particles, b.shape[0]
        rng = np.random.default_rng(seed)
        t0 = time.perf_counter()
        cost = float(getattr(target, "cost", 1.0))
        evals = 0.0
        best_x, best_lp = None, -np.inf

        def evaluate(x: np.ndarray) -> np.ndarray:
            nonlocal evals, best_x, best_lp
            lp = np.asarray(target.log_prob(x), dtype=np.float64).reshape(-1)
            lp = np.where(np.isnan(lp), -np.inf, lp)
            evals += cost * x.shape[0]
            if lp.size and (best_x is None or lp.max() > best_lp):
                i = int(np.argmax(lp))
                best_x, best_lp = x[i].copy(), float(lp[i])
            return lp

        # Stage 0: uniform particles, redrawn where the target vanishes (π_0+ is the
        # uniform law on the support).
        x = lo + (hi - lo) * rng.random((n, d))
        lp = evaluate(x)
        for _ in range(20):
            bad = np.flatnonzero(~np.isfinite(lp))
            if bad.size == 0:
                break
            cand = lo + (hi - lo) * rng.random((n, d))
            lpc = evaluate(cand)
            good = np.flatnonzero(np.isfinite(lpc))[: bad.size]
            x[bad[: good.size]], lp[bad[: good.size]] = cand[good], lpc[good]
        finite = np.isfinite(lp)
        if finite.any() and not finite.all():  # copy support points; the moves spread them
            src = rng.choice(np.flatnonzero(finite), size=int((~finite).sum()))
            x[~finite], lp[~finite] = x[src], lp[src]

        betas, ess, acc_trace, moves_trace = [0.0], [float(n)], [np.nan], [0]
        map_x, map_lp = [best_x.copy()], [best_lp]
        log_z, beta = 0.0, 0.0
        log_scale = math.log(2.38 / math.sqrt(d))
        acc = self.target_acceptance
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(desc=self.name, unit="stage", leave=False)
        stage = 0
        while finite.any() and beta < 1.0 and stage < self.max_stages:
            stage += 1
            new_beta = next_temperature(lp, beta, self.ess_fraction * n)
            with np.errstate(invalid="ignore"):
                inc = np.where(np.isfinite(lp), (new_beta - beta) * lp, -np.inf)
            log_z += float(logsumexp(inc) - math.log(n))
            stage_ess = _ess(inc)
            idx = systematic_resample(inc, rng)
            x, lp, beta = x[idx], lp[idx], new_beta

            cov = np.atleast_2d(np.cov(x, rowvar=False)) + np.diag((1e-9 * (hi - lo)) ** 2)
            chol = np.linalg.cholesky(cov)
            k = self._moves(acc)
            accepted = 0
            for _ in range(k):
                y = x + math.exp(log_scale) * rng.standard_normal((n, d)) @ chol.T
                inside = np.all((y >= lo) & (y <= hi), axis=1)
                lpy = np.full(n, -np.inf)
                if inside.any():
                    lpy[inside] = evaluate(y[inside])
                with np.errstate(invalid="ignore"):
                    log_alpha = np.where(np.isfinite(lpy), beta * (lpy - lp), -np.inf)
                move = np.log(rng.random(n)) < log_alpha
                x[move], lp[move] = y[move], lpy[move]
                accepted += int(move.sum())
            acc = accepted / (k * n)
            log_scale += acc - self.target_acceptance  # steer the next stage's scale

            betas.append(beta)
            ess.append(stage_ess)
            acc_trace.append(acc)
            moves_trace.append(k)
            map_x.append(best_x.copy())
            map_lp.append(best_lp)
            info = {"beta": beta, "ess": stage_ess, "acceptance": acc, "n_moves": k,
                    "map_log_target": best_lp, "n_target_evals": evals}
            if bar is not None:
                bar.update(1)
                bar.set_postfix(beta=f"{beta:.3g}", ess=f"{stage_ess:.0f}", acc=f"{acc:.2f}")
            if callback is not None:
                callback(stage, info)
        if bar is not None:
            bar.close()
        return build(
            x, lp, param_names=target.param_names, map_theta=np.asarray(map_x),
            map_log_target=np.asarray(map_lp), ess=np.asarray(ess), sampler=self.name,
            config=self.get_config(), seed=seed, target=target, n_target_evals=evals,
            wall_time_s=time.perf_counter() - t0,
            extra_vars={"beta": (("step",), np.asarray(betas)),
                        "acceptance": (("step",), np.asarray(acc_trace)),
                        "n_moves": (("step",), np.asarray(moves_trace, dtype=np.int64))},
            extra_attrs={"log_evidence": log_z if finite.any() else -math.inf,
                         "final_beta": beta},
        )
