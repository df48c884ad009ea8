"""Random-walk Metropolis–Hastings (thesis 5.4, Eqns. 5.41–5.46), several chains at once.

Each step proposes θ' = θ_i + s·L·z (z ~ N(0, I)) for every chain and accepts with
probability α = min(1, p(X|θ')/p(X|θ_i)) (5.44/5.45: the Gaussian proposal is
symmetric, so the Hastings factor g(θ_i|θ')/g(θ'|θ_i) of 5.41/5.46 is 1, and the
flat prior cancels as in 5.43). The chains advance together, so a step costs one
batched ``log_prob`` call. Proposals outside the bounds are rejected without
being evaluated (their density is zero; the thesis does the same in 7.4).

The thesis gives no MH settings (it abandoned plain MH for dynamic weighting,
5.5, because on the sharp PL target "the acceptance ratio was too low"). The
defaults spend the thesis's MCMC budget of 20000 evaluations (8 chains × 2500
steps) with the same kernel width as its dynamic-weighting runs (σ = 0.05 of
each parameter's range, 7.4). With ``adapt=True`` (default) the proposal is
tuned *during burn-in only* — the scale by Robbins–Monro towards
``target_acceptance``, the shape to the chains' empirical covariance (Haario
et al.) — and then frozen, so the post-burn-in chain is a plain MH chain.
The post-burn-in, thinned states of all chains are the equal-weight sample set.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from mrfpe.samplers.base import Callback, Sampler, check_positive_int
from mrfpe.samplers.kit import (
    AdaptiveRandomWalk,
    check_chain_length,
    evaluate_inside,
    metropolis_accept,
    start_chains,
)

__all__ = ["MetropolisHastings", "metropolis_accept", "run_random_walk"]  # accept rule: the kit


class MetropolisHastings(Sampler):
    """Random-walk Metropolis–Hastings (5.41–5.46), vectorised over chains.

    Parameters
    ----------
    n_steps : int
        Steps per chain, burn-in included (default 2500; × 8 chains = 20000
        evaluations, the thesis's MCMC budget of 7.4).
    n_chains : int
        Independent chains advanced in one batched ``log_prob`` call per step.
    burn_in : int
        Leading steps discarded (and used for adaptation); must be < ``n_steps``.
    thin : int
        Keep every ``thin``-th post-burn-in state.
    proposal_sd : float
        Initial Gaussian proposal sd as a fraction of each parameter's range
        (0.05, the kernel of 7.4).
    adapt : bool
        Tune scale and shape of the proposal during burn-in (then freeze it).
    target_acceptance : float
        Acceptance rate aimed at by the adaptation (0.234, Roberts et al. 1997).
    """

    name = "mh"
    conformance: ClassVar[dict] = {"quick_config": {"n_steps": 1000, "burn_in": 250}}

    def __init__(self, n_steps: int = 2500, n_chains: int = 8, burn_in: int = 500,
                 thin: int = 1, proposal_sd: float = 0.05, adapt: bool = True,
                 target_acceptance: float = 0.234):
        self.n_steps, self.burn_in, self.thin = check_chain_length(n_steps, burn_in, thin)
        self.n_chains = check_positive_int("n_chains", n_chains)
        self.proposal_sd, self.adapt, self.target_acceptance = AdaptiveRandomWalk.check_options(
            proposal_sd, adapt, target_acceptance)

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Run the chains on ``target`` and return the posterior Dataset."""
        return run_random_walk(self, target, seed, progress, callback)


def run_random_walk(sampler: Any, target: Any, seed: int | None, progress: bool,
                    callback: Callback | None):
    """Adaptive random-walk Metropolis chains on ``target`` with ``sampler``'s settings
    (``n_steps``, ``n_chains``, ``burn_in``, ``thin``, ``proposal_sd``, ``adapt``,
    ``target_acceptance``), recorded under its ``name`` and ``get_config()``: the body of
    :class:`MetropolisHastings`, shared with samplers that fall back to it."""
    n, c = sampler.n_steps, sampler.n_chains
    bounds, rng, run, x, lp, kept = start_chains(
        target, seed, n_steps=n, n_chains=c, burn_in=sampler.burn_in, thin=sampler.thin,
        desc=sampler.name, progress=progress, callback=callback)
    walk = AdaptiveRandomWalk(bounds, c, sampler.proposal_sd, sampler.burn_in, sampler.adapt,
                              sampler.target_acceptance)
    acceptance, scales = np.zeros(n), np.zeros(n)
    for t in range(n):
        scale = walk.scale
        y, inside = walk.propose(x, rng)
        lpy = evaluate_inside(run, target, y, inside)  # -inf outside, not evaluated
        accept = inside & metropolis_accept(np.log(rng.random(c)), lp, lpy)
        x[accept], lp[accept] = y[accept], lpy[accept]
        acceptance[t], scales[t] = accept.mean(), scale
        run.offer(x, lp)
        walk.update(t, x, acceptance[t])
        kept.record(t, x, lp)
        run.step(t, kept.trace_ess(t), acceptance=float(acceptance[t]),
                 proposal_scale=float(scale))
    theta, log_target, _ = kept.flat()
    return run.finish(theta, log_target, None, sampler=sampler.name,
                      config=sampler.get_config(), seed=seed, chain=kept.chain(),
                      extra_vars={"acceptance": (("step",), acceptance),
                                  "proposal_scale": (("step",), scales)})
