"""Dynamically weighted MCMC (thesis 5.5, Eqns. 5.47–5.56; Liu, Liang & Wong 2001).

The chain carries a state X and a weight Π. Each step draws y from a Gaussian
random-walk kernel T(x, ·) (σ = 0.05 of each parameter's range, 7.4) and uses the
Metropolis ratio r(x, y) = ϱ(y)T(y, x) / (ϱ(x)T(x, y)) (5.47; T is symmetric, so
r = ϱ(y)/ϱ(x)). With θ ≥ 0 and u ~ U(0, 1):

* Q-type (5.48): move to (y, max(θ, πr)) if u ≤ min(1, πr/θ), else stay at (x, aπ);
* R-type (5.49): move to (y, πr + θ) if u ≤ πr/(πr + θ), else stay at (x, π(πr + θ)/θ).

The R-type move is IWIW — invariant with respect to importance weights (5.50): if
Σ_π π f(x, π) ∝ ϱ(x) before a step, it holds after it — and the Q-type move is so
approximately (5.51–5.53). θ = 0 makes both moves the plain importance-weight
update Π' = Π r (5.54). The stabiliser of 5.5.4 multiplies the new weight by
V ~ U(1 − δ, 1 + δ) after every step: E[V] = 1 keeps the move IWIW, while
E[log V] < 0 pulls log Π back and stops the R-type weights from drifting to
infinity.

Published forms used where the thesis has typos:

* the stabilised rejection weight is V·π(πr + θ)/θ (5.49 times V); the thesis
  prints V(π(πr) + 1) for θ = 1;
* the thesis's "where a > 1 ..." under the R-type move is copied from the Q-type
  move: ``a`` is a Q-type setting only (here a constant).

Edge cases (documented choices): a proposal outside the bounds has ϱ(y) = 0,
hence r = 0, and is rejected by the formulas themselves (Q: weight × a,
R: weight unchanged); for θ = 0 such a proposal is rejected with the weight
unchanged (the θ → 0⁺ limit of R; 0/0 in 5.48). A chain whose state has zero
density (it never found the support) accepts every in-bounds proposal with its
weight unchanged until it reaches the support.

Everything is in log space: log Π, log r, log θ (−inf for θ = 0), log a, log V.

Initial weight (``initial_weight``): the thesis sets Π₀ = ϱ(θ₀) (7.13), which
makes the start correctly weighted (θ₀ is uniform in the box). Because θ is
compared with πr on an absolute scale, Π₀ = ϱ(θ₀) ties the behaviour to the
target's normalising constant: for an unnormalised pseudolikelihood with
log ϱ ≈ −10⁴, πr ≪ θ = 1 and an R-type chain never moves. The default
``"relative"`` is Π₀ = ϱ(θ₀)/max_c ϱ(θ₀,c) — the thesis's choice divided by one
constant common to all chains (still correctly weighted, and invariant to the
target's scale); ``"absolute"`` is 7.13 literally; ``"unit"`` is Π₀ = 1.

The weighted chain — post-burn-in, thinned pairs (X_i, Π_i) of every chain — is
the sample set. Its weights (``weights``): ``"stratified"`` (the default)
is the estimator the method's authors use for expectations, stratified truncation
(Wong & Liang 1997; Liu, Liang & Wong 2001, the thesis's [68]):
:func:`stratified_truncation` with ``n_strata`` strata of log ϱ and truncation
at the ``truncation`` quantile within each; ``"raw"`` is ``log_weight`` = log Π_i
as before. Measured on a 3-D Gaussian at the default budget
(benchmarks/bench_accuracy.py, 3 seeds) neither is accurate — R-type mean
error ~0.35 sd, Q-type 2 sd — because one 20000-step chain's weights are
dominated by a few excursions; truncation raises the Kish ESS (R: ~18 → ~50,
Q: ~5 → ~28) but not enough. Treat these posteriors as unreliable unless
diagnostics say otherwise.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import (
    check_chain_length,
    evaluate_inside,
    random_walk_proposal,
    start_chains,
)

__all__ = ["QTypeDynamicWeighting", "RTypeDynamicWeighting", "dw_update",
           "stratified_truncation"]

_INITIAL = ("relative", "absolute", "unit")


def dw_update(kind: str, log_pi: np.ndarray, log_r: np.ndarray, log_u: np.ndarray, *,
              theta: float, a: float = 2.0, log_v: np.ndarray | float = 0.0,
              ) -> tuple[np.ndarray, np.ndarray]:
    """One dynamic-weighting acceptance/weight update, vectorised over chains.

    Parameters
    ----------
    kind : str
        ``"q"`` (5.48) or ``"r"`` (5.49).
    log_pi : numpy.ndarray
        (C,) current log weights log Π.
    log_r : numpy.ndarray
        (C,) log Metropolis ratio log r(x, y) of 5.47 (−inf when ϱ(y) = 0).
    log_u : numpy.ndarray
        (C,) log of the U(0, 1) draws.
    theta : float
        The θ ≥ 0 of 5.48/5.49.
    a : float
        The Q-type rejection multiplier (> 1).
    log_v : numpy.ndarray or float
        Log of the stabilising multiplier V of 5.5.4, added to every new weight.

    Returns
    -------
    accept : numpy.ndarray
        (C,) bool, whether the chain moves to y.
    log_pi_new : numpy.ndarray
        (C,) the new log weights.
    """
    log_pi = np.asarray(log_pi, dtype=np.float64)
    log_pr = log_pi + np.asarray(log_r, dtype=np.float64)
    log_theta = np.log(theta) if theta > 0 else -np.inf
    zero = np.isneginf(log_pr)  # ϱ(y) = 0 (or Π = 0): r = 0
    with np.errstate(invalid="ignore"):
        if kind == "q":
            accept = ~zero & (log_u <= np.minimum(0.0, log_pr - log_theta))
            moved = np.maximum(log_theta, log_pr)
            stayed = log_pi + (np.log(a) if theta > 0 else 0.0)
        elif kind == "r":
            log_den = np.logaddexp(log_pr, log_theta)  # log(πr + θ)
            accept = ~zero & (log_u <= log_pr - log_den)
            moved = log_den
            stayed = log_pi + (log_den - log_theta if theta > 0 else 0.0)
        else:
            raise ValueError(f"kind must be 'q' or 'r'; got {kind!r}")
    if theta == 0:  # 5.54: both moves are Π' = Π r; zero-density proposals rejected as-is
        stayed = log_pi
    return accept, np.where(accept, moved, stayed) + log_v


def stratified_truncation(log_weight: np.ndarray, log_target: np.ndarray, *,
                          n_strata: int = 10, quantile: float = 0.99) -> np.ndarray:
    """Stratified truncation of dynamic weights (Wong & Liang 1997; Liu, Liang & Wong 2001).

    The weighted chain's raw weights are heavy-tailed: a few enormous weights
    dominate any average. Its authors estimate expectations after stratifying the
    samples by the target value ``log ϱ(x)`` into ``n_strata`` strata of (about)
    equal size and, within each stratum, truncating the weights at their
    ``quantile``: ``w ← min(w, w_(quantile))``. Strata keep their relative mass up
    to the truncated tail, which removes most of the variance for a small bias.

    Returns the truncated log weights (unnormalised; −inf where ``log_target`` is −inf).
    """
    lw = np.asarray(log_weight, dtype=np.float64).copy()
    lt = np.asarray(log_target, dtype=np.float64)
    ok = np.isfinite(lw) & np.isfinite(lt)
    lw[~ok] = -np.inf
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return lw
    order = idx[np.argsort(lt[idx], kind="stable")]
    for stratum in np.array_split(order, min(n_strata, order.size)):
        cap = np.quantile(lw[stratum], quantile)
        lw[stratum] = np.minimum(lw[stratum], cap)
    return lw


class _DynamicWeighting(Sampler):
    """Shared driver of the Q- and R-type samplers (see the module docstring)."""

    kind = ""
    #: The weighted chain's time average is not a usable moment estimate on a
    #: target much narrower than the box: with 20000 steps on the conformance
    #: Gaussian (sd 0.04-0.06 in the unit cube) the Kish ESS of the weights is
    #: about 10 and the weighted mean is off by ~0.6 sd (R-type) and ~3 sd
    #: (Q-type, whose IWIW is only approximate, 5.51). ``diagnose`` calls such
    #: posteriors unreliable (ESS, Pareto k̂) and ``build`` warns; the moment check
    #: is a known failure (tests/samplers/test_conformance.py). What the method does
    #: guarantee — IWIW — is tested directly (tests/samplers/test_dynamic_weighting.py).
    conformance: ClassVar[dict] = {"quick_config": {"n_steps": 4000}}

    def _check_common(self, n_steps: int, n_chains: int, burn_in: int, thin: int,
                      proposal_sd: float, theta: float, delta: float,
                      initial_weight: str, weights: str = "stratified",
                      n_strata: int = 10, truncation: float = 0.99) -> None:
        self.weights = check_choice("weights", weights, ("stratified", "raw"))
        self.n_strata = check_positive_int("n_strata", n_strata)
        self.truncation = check_range("truncation", truncation, 0.0, 1.0, low_open=True)
        self.n_steps, self.burn_in, self.thin = check_chain_length(n_steps, burn_in, thin)
        self.n_chains = check_positive_int("n_chains", n_chains)
        self.proposal_sd = check_range("proposal_sd", proposal_sd, 0.0, np.inf,
                                       low_open=True, high_open=True)
        self.theta = check_range("theta", theta, 0.0, np.inf, high_open=True)
        self.delta = check_range("delta", delta, 0.0, 1.0, high_open=True)
        self.initial_weight = check_choice("initial_weight", initial_weight, _INITIAL)

    def _a(self) -> float:
        return 1.0

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Run the weighted chain(s) on ``target`` and return the posterior Dataset."""
        n, c = self.n_steps, self.n_chains
        bounds, rng, run, x, lp, kept = start_chains(
            target, seed, n_steps=n, n_chains=c, burn_in=self.burn_in, thin=self.thin,
            desc=self.name, progress=progress, callback=callback, weighted=True)
        sd = self.proposal_sd * (bounds[:, 1] - bounds[:, 0])  # T(x, ·) of 5.47, fixed
        log_pi = self._initial_log_weight(lp)
        acceptance = np.zeros(n)
        for t in range(n):
            y, inside = random_walk_proposal(x, sd, bounds, rng)
            lpy = evaluate_inside(run, target, y, inside)  # -inf outside, not evaluated
            log_u = np.log(rng.random(c))
            log_v = np.log(rng.uniform(1 - self.delta, 1 + self.delta, c)) if self.delta else 0.0
            found = np.isfinite(lp)
            with np.errstate(invalid="ignore"):
                log_r = np.where(found, lpy - np.where(found, lp, 0.0), -np.inf)  # 5.47
            accept, new_log_pi = dw_update(self.kind, log_pi, log_r, log_u,
                                           theta=self.theta, a=self._a(), log_v=log_v)
            accept = np.where(found, accept, inside)  # outside the support: wander in
            log_pi = np.where(found, new_log_pi, log_pi)
            x[accept], lp[accept] = y[accept], lpy[accept]
            acceptance[t] = accept.mean()
            run.offer(x, lp)
            kept.record(t, x, lp, log_pi)
            # chain ESS x Kish efficiency of the raw kept weights at checkpoints, NaN elsewhere
            run.step(t, kept.trace_ess(t), acceptance=float(acceptance[t]),
                     max_log_weight=float(np.max(log_pi)))
        theta, log_target, lw = kept.flat()
        if self.weights == "stratified":  # the estimator the method's authors use
            lw = stratified_truncation(lw, log_target, n_strata=self.n_strata,
                                       quantile=self.truncation)
        return run.finish(theta, log_target, lw, sampler=self.name, config=self.get_config(),
                          seed=seed, chain=kept.chain(),
                          extra_vars={"acceptance": (("step",), acceptance)})

    def _initial_log_weight(self, lp: np.ndarray) -> np.ndarray:
        """log Π₀ per chain (7.13 and the variants of ``initial_weight``)."""
        if self.initial_weight == "unit":
            return np.zeros_like(lp)
        finite = np.isfinite(lp)
        if not finite.any():
            return np.zeros_like(lp)
        ref = lp[finite].max() if self.initial_weight == "relative" else 0.0
        return np.where(finite, lp - ref, 0.0)


class QTypeDynamicWeighting(_DynamicWeighting):
    """Q-type dynamically weighted MCMC (5.48), the weighted chain as the sample set.

    Parameters
    ----------
    n_steps : int
        Steps per chain (20000, 7.4).
    n_chains : int
        Independent chains, advanced in one batched ``log_prob`` call per step
        (1, as the thesis).
    burn_in, thin : int
        Leading steps dropped from the sample set (0: the thesis keeps the whole
        chain) and thinning of the rest.
    proposal_sd : float
        Gaussian kernel sd as a fraction of each parameter's range (0.05, 7.4).
    theta : float
        θ ≥ 0 of 5.48 (1, 7.4; 0 gives the importance-weight chain of 5.5.3).
    a : float
        Rejection weight multiplier a > 1 of 5.48 (2; the thesis gives no value).
    delta : float
        Half-width of the stabilising multiplier V ~ U(1 − δ, 1 + δ) of 5.5.4
        (0: the Q-type weights stabilise by themselves, 5.5.4).
    initial_weight : ``"relative"`` | ``"absolute"`` | ``"unit"``
        Π₀ (module docstring; ``"absolute"`` is 7.13 literally).
    """

    name = "dw_q"
    kind = "q"

    def __init__(self, n_steps: int = 20000, n_chains: int = 1, burn_in: int = 0,
                 thin: int = 1, proposal_sd: float = 0.05, theta: float = 1.0,
                 a: float = 2.0, delta: float = 0.0, initial_weight: str = "relative",
                 weights: str = "stratified", n_strata: int = 10, truncation: float = 0.99):
        self._check_common(n_steps, n_chains, burn_in, thin, proposal_sd, theta, delta,
                           initial_weight, weights, n_strata, truncation)
        self.a = check_range("a", a, 1.0, np.inf, low_open=True, high_open=True)

    def _a(self) -> float:
        return self.a


class RTypeDynamicWeighting(_DynamicWeighting):
    """R-type dynamically weighted MCMC (5.49, IWIW), the weighted chain as the sample set.

    Parameters
    ----------
    n_steps : int
        Steps per chain (20000, 7.4).
    n_chains : int
        Independent chains, advanced in one batched ``log_prob`` call per step
        (1, as the thesis).
    burn_in, thin : int
        Leading steps dropped from the sample set (0: the thesis keeps the whole
        chain) and thinning of the rest.
    proposal_sd : float
        Gaussian kernel sd as a fraction of each parameter's range (0.05, 7.4).
    theta : float
        θ ≥ 0 of 5.49 (1, 7.4).
    delta : float
        Half-width of the stabilising multiplier V ~ U(1 − δ, 1 + δ) of 5.5.4.
        The thesis gives no value; 0.1 measured best of {0, 0.05, 0.1, 0.2, 0.3,
        0.5} on the conformance Gaussian (12 seeds, 20000 steps: weighted-mean
        error 0.55 sd on average, against 0.77 for δ = 0 and 1.24 for δ = 0.3),
        while δ = 0.5 let the weights' random-walk noise dominate.
    initial_weight : ``"relative"`` | ``"absolute"`` | ``"unit"``
        Π₀ (module docstring; ``"absolute"`` is 7.13 literally).
    """

    name = "dw_r"
    kind = "r"

    def __init__(self, n_steps: int = 20000, n_chains: int = 1, burn_in: int = 0,
                 thin: int = 1, proposal_sd: float = 0.05, theta: float = 1.0,
                 delta: float = 0.1, initial_weight: str = "relative",
                 weights: str = "stratified", n_strata: int = 10, truncation: float = 0.99):
        self._check_common(n_steps, n_chains, burn_in, thin, proposal_sd, theta, delta,
                           initial_weight, weights, n_strata, truncation)
