"""mrfpe-smc: an adaptive-tempering Sequential Monte Carlo sampler, as a third-party plugin.

Registered under the ``mrfpe.samplers`` entry-point group (this package's
``pyproject.toml``); it uses only mrfpe's public API: the Target contract, the
sampler author's kit :mod:`mrfpe.samplers.kit` and :mod:`mrfpe.samplers.base`.

The algorithm (Del Moral, Doucet & Jasra 2006; Jasra et al. 2011) moves particles
from the uniform law on the box (β = 0) to the target (β = 1) through
π_β ∝ 1_box · p^β. Each stage (1) picks the next β by bisection so that the ESS of
the incremental weights p^(β' − β) is ``ess_fraction`` × N, (2) resamples
systematically, (3) makes random-walk Metropolis moves on π_β' with the cloud's
covariance times s² (s steered towards ``target_acceptance``), as many as make a
particle move at least once with probability ``mixing`` — with the kit's random-walk
pieces, as ``mh``: :func:`~mrfpe.samplers.kit.random_walk_proposal`,
:func:`~mrfpe.samplers.kit.evaluate_inside` (proposals outside the box are rejected
without evaluation) and :func:`~mrfpe.samplers.kit.metropolis_accept`.

``log_evidence`` = log(∫_box p / vol(box)) (mrfpe's convention,
:mod:`mrfpe.samplers.kit.evidence`): the support's share of the box times the product
of the stages' mean incremental weights. ``log_evidence_se`` sums the stages'
delta-method variances as if independent, a lower bound on the true SE (the spread
over 6 seeds on ``benchmarks/bench_accuracy.py``'s Gaussians is 1.5–3× it). The final
equally weighted cloud is the sample set; ``beta``, ``acceptance``, ``n_moves`` per step.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
from scipy.special import logsumexp

from mrfpe.samplers import kit
from mrfpe.samplers.base import Callback, Sampler

__all__ = ["AdaptiveTemperingSMC", "next_temperature", "systematic_resample"]
__version__ = "0.1.0"


def systematic_resample(log_w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Ancestor indices (N,) by systematic resampling (one uniform u, points (u + i)/N)."""
    return kit.resample(log_w, np.size(log_w), "systematic", rng)


def next_temperature(log_target: np.ndarray, beta: float, ess_target: float,
                     tol: float = 1e-10) -> float:
    """The β' in (β, 1] whose incremental weights p^(β'−β) have ESS = ``ess_target``.

    The ESS decreases as β' grows, so bisection brackets it; β' = 1 when even
    the full step keeps the ESS above the target.
    """
    def ess_at(b: float) -> float:
        with np.errstate(invalid="ignore"):
            return kit.ess(np.where(np.isfinite(log_target), (b - beta) * log_target, -np.inf))

    if ess_at(1.0) >= ess_target:
        return 1.0
    lo, hi = beta, 1.0
    while hi - lo > tol * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess_at(mid) >= ess_target else (lo, mid)
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
        open_unit = {"low_open": True, "high_open": True}
        self.n_particles = kit.check_positive_int("n_particles", n_particles, minimum=2)
        self.ess_fraction = kit.check_range("ess_fraction", ess_fraction, 0.0, 1.0, **open_unit)
        self.target_acceptance = kit.check_range("target_acceptance", target_acceptance,
                                                 0.0, 1.0, **open_unit)
        self.mixing = kit.check_range("mixing", mixing, 0.0, 1.0, **open_unit)
        self.min_moves = kit.check_positive_int("min_moves", min_moves)
        self.max_moves = kit.check_positive_int("max_moves", max_moves)
        if self.max_moves < self.min_moves:
            raise ValueError(f"max_moves must be >= min_moves ({self.min_moves}); "
                             f"got {max_moves}")
        self.max_stages = kit.check_positive_int("max_stages", max_stages)

    def _moves(self, acc: float) -> int:
        """Moves so that a particle moves at least once with probability ``mixing``."""
        if acc <= 0.0:
            return self.max_moves
        if acc >= 1.0:
            return self.min_moves
        k = math.ceil(math.log(1.0 - self.mixing) / math.log(1.0 - acc))
        return int(min(self.max_moves, max(self.min_moves, k)))

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Temper from the uniform box to ``target``; return the posterior Dataset."""
        b = kit.check_target(target)
        kit.check_seed(seed)
        lo, hi = b[:, 0], b[:, 1]
        n, d = self.n_particles, b.shape[0]
        rng = np.random.default_rng(seed)
        run = kit.Run(target, None, progress=progress, callback=callback, desc=self.name,
                      rows=8 * n)
        # Stage 0: uniform draws, redrawn where the target vanishes (π_0+ is uniform on the
        # support; up to 20 batches of N candidates).
        x, lp, share = kit.draw_in_support(run, target, rng, n, b, max_draws=20 * n,
                                           return_fraction=True)
        finite = np.isfinite(lp)
        run.offer(x, lp)
        run.step(0, float(n), beta=0.0)
        trace = {"beta": [0.0], "acceptance": [np.nan], "n_moves": [0]}
        # log Z relative to the box: the support's share, then each stage's mean weight
        log_z = math.log(share) if share > 0 else -math.inf
        var_z = (1.0 - share) / (share * n) if share > 0 else math.inf
        beta, stage = 0.0, 0
        log_scale, acc = math.log(2.38 / math.sqrt(d)), self.target_acceptance
        while finite.any() and beta < 1.0 and stage < self.max_stages:
            stage += 1
            new_beta = next_temperature(lp, beta, self.ess_fraction * n)
            with np.errstate(invalid="ignore"):
                inc = np.where(np.isfinite(lp), (new_beta - beta) * lp, -np.inf)
            log_z += float(logsumexp(inc) - math.log(n))
            stage_ess = kit.ess(inc)
            var_z += (n / stage_ess - 1.0) / (n - 1)  # delta method, this stage alone
            idx = kit.resample(inc, n, "systematic", rng)
            x, lp, beta = x[idx], lp[idx], new_beta

            cov = np.atleast_2d(np.cov(x, rowvar=False)) + np.diag((1e-9 * (hi - lo)) ** 2)
            chol = np.linalg.cholesky(cov)
            k, accepted = self._moves(acc), 0
            for _ in range(k):  # proposals outside the box are rejected unevaluated
                y, inside = kit.random_walk_proposal(x, chol, b, rng, math.exp(log_scale))
                lpy = kit.evaluate_inside(run, target, y, inside)
                run.offer(y[inside], lpy[inside])
                with np.errstate(invalid="ignore"):  # the tempered ratio (π_β'(y)/π_β'(x))
                    log_alpha = np.where(np.isfinite(lpy), beta * (lpy - lp), -np.inf)
                move = kit.metropolis_accept(np.log(rng.random(n)), np.zeros(n), log_alpha)
                x[move], lp[move] = y[move], lpy[move]
                accepted += int(move.sum())
            acc = accepted / (k * n)
            log_scale += acc - self.target_acceptance  # steer the next stage's scale
            for key, v in (("beta", beta), ("acceptance", acc), ("n_moves", k)):
                trace[key].append(v)
            run.step(stage, stage_ess, beta=beta, acceptance=acc, n_moves=k)
        extra = {key: (("step",), np.asarray(v)) for key, v in trace.items()}
        ok = finite.any()
        return run.finish(x, lp, None, sampler=self.name, config=self.get_config(), seed=seed,
                          log_evidence=log_z if ok else -math.inf,
                          log_evidence_se=math.sqrt(var_z) if ok else math.nan,
                          extra_vars=extra, extra_attrs={"final_beta": beta})
