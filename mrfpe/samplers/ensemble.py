"""Affine-invariant ensemble MCMC through emcee (Goodman & Weare 2010; Foreman-Mackey et al. 2013).

Beyond the thesis: a modern MCMC baseline next to its Metropolis–Hastings
(5.41–5.46) and dynamic weighting (5.47–5.49). ``emcee.EnsembleSampler`` runs
with ``vectorize=True``, so each half-ensemble update is one batched
``log_prob`` call. Walkers start uniformly inside the bounds (redrawn where the
target is −inf, :func:`~mrfpe.samplers.kit.draw_in_support`); emcee's
random state is seeded from the same ``SeedSequence`` as the start points, so
one ``seed`` fixes every number. The target is −inf outside its bounds, so
stretch moves that leave the box are rejected and every sample respects the
bounds. The post-burn-in, thinned walker positions are the equal-weight
sample set, kept as one ensemble (``KeptStates(..., ensemble=True)``, so
``attrs["chain_type"] = "ensemble"``): the walkers move using each other and are
not independent chains, so :func:`mrfpe.posterior.diagnose` judges them as Goodman
& Weare (2010) and emcee's documentation (Foreman-Mackey et al. 2013) do, by the
ensemble's integrated autocorrelation time τ (``autocorr_time(param)``, in kept
steps): reliable only when the kept chain is at least 50 τ long, with an ESS of
``n_walkers × n_kept / τ``. R̂ across the walkers is reported, not decisive. Default
budget: 32 walkers × 625 steps = 20000 evaluations, the thesis's MCMC budget (7.4);
the stretch move's τ grows with the dimension (about 35–40 steps in 3-D, 100–125 in
10-D on Gaussians), so that budget is too short for 50 τ and reads unreliable: ask for
``n_steps`` of 50 τ plus the burn-in.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from mrfpe.posterior.diagnostics import ensemble_autocorr_time
from mrfpe.samplers.base import Callback, Sampler, check_positive_int, check_range
from mrfpe.samplers.kit import (
    KeptStates,
    Run,
    check_chain_length,
    check_seed,
    check_target,
    draw_in_support,
)

__all__ = ["EmceeEnsemble"]


class EmceeEnsemble(Sampler):
    """emcee's affine-invariant stretch-move ensemble, vectorised over walkers.

    Parameters
    ----------
    n_walkers : int
        Walkers (even, at least 2·d + 2 is checked at run time; default 32).
    n_steps : int
        Ensemble steps, burn-in included (625: 20000 evaluations with 32 walkers). The
        posterior reads reliable once the kept steps span 50 integrated autocorrelation
        times τ (:func:`mrfpe.posterior.diagnose`; the warning names the ``n_steps``).
    burn_in : int
        Leading steps dropped from the sample set; must be < ``n_steps``.
    thin : int
        Keep every ``thin``-th post-burn-in step.
    stretch_scale : float
        The stretch move's ``a`` > 1 (emcee's default 2).
    """

    name = "emcee"
    conformance: ClassVar[dict] = {"quick_config": {"n_steps": 300, "burn_in": 100}}

    def __init__(self, n_walkers: int = 32, n_steps: int = 625, burn_in: int = 125,
                 thin: int = 1, stretch_scale: float = 2.0):
        self.n_walkers = check_positive_int("n_walkers", n_walkers, minimum=4)
        if self.n_walkers % 2:
            raise ValueError(f"n_walkers must be even (emcee splits the ensemble in two); "
                             f"got {n_walkers}")
        self.n_steps, self.burn_in, self.thin = check_chain_length(n_steps, burn_in, thin)
        self.stretch_scale = check_range("stretch_scale", stretch_scale, 1.0, np.inf,
                                         low_open=True, high_open=True)

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Run the ensemble on ``target`` and return the posterior Dataset."""
        import emcee

        bounds = check_target(target)
        check_seed(seed)
        d, w, n = bounds.shape[0], self.n_walkers, self.n_steps
        if w < 2 * d + 2:
            raise ValueError(f"n_walkers must be at least 2*d + 2 = {2 * d + 2} for a "
                             f"{d}-parameter target; got {w}")
        ss_start, ss_emcee = np.random.SeedSequence(seed).spawn(2)
        rng = np.random.default_rng(ss_start)
        run = Run(target, n, progress=progress, callback=callback, desc=self.name,
                  rows=n + w * (n // self.thin + 4))
        p0, lp0 = draw_in_support(run, target, rng, w, bounds)

        sampler = emcee.EnsembleSampler(w, d, lambda x: run.evaluate(target, x), vectorize=True,
                                        moves=emcee.moves.StretchMove(a=self.stretch_scale))
        rstate = np.random.RandomState(np.random.MT19937(ss_emcee)).get_state()
        acceptance = np.zeros(n)
        kept = KeptStates(n, self.burn_in, self.thin, w, d, ensemble=True)  # walkers interact
        prev = p0
        states = sampler.sample(emcee.State(p0, log_prob=lp0, random_state=rstate),
                                iterations=n, store=False, skip_initial_state_check=True)
        for t, state in enumerate(states):
            x, lp = state.coords, state.log_prob
            acceptance[t] = np.mean(np.any(x != prev, axis=1))  # a rejected walker stays put
            prev = x.copy()
            run.offer(x, lp)
            kept.record(t, x, lp)
            run.step(t, kept.trace_ess(t), acceptance=float(acceptance[t]))
        tau, _ = ensemble_autocorr_time(kept.theta.transpose(1, 0, 2))  # diagnose's τ
        theta, log_target, _ = kept.flat()
        extra = {"acceptance": (("step",), acceptance), "autocorr_time": (("param",), tau)}
        return run.finish(theta, log_target, None, sampler=self.name, config=self.get_config(),
                          seed=seed, extra_vars=extra, **kept.build_kwargs())
