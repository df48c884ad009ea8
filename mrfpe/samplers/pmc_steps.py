"""Population Monte Carlo as steps: frozen parameters, ``init`` and a pure ``step`` per variant.

The iterations of :class:`~mrfpe.samplers.pmc.PMC` and
:class:`~mrfpe.samplers.ppf.PPF` are written in the manner of BlackJAX. A variant
is an :class:`Algorithm`, a pair of functions:

* ``init(x)`` — the state before iteration 0, from the starting set ``x``;
* ``step(params, state, rng, target)`` — one iteration: it reads the frozen
  :class:`PMCParams`, the state, a random stream and a :class:`StepTarget` (the
  iteration's importance function ``G^n``, the full target and the box), and
  returns the new state and a :class:`StepInfo`. It changes neither its
  arguments (other than drawing from ``rng``) nor anything else: same state, same
  random stream → same result.

Each variant has its own state (:class:`MixtureState`, :class:`ThesisState`,
:class:`Thesis1State`), all with the fields the driver reads: the particles ``x``,
their ``log_weight`` under the iteration and ``log_den``, what the full target is
divided by for the final weights (:func:`final_log_weight`).

:func:`iterate` is the driver both samplers share: it hands each step the
importance function of its iteration as a counted log density, and keeps all the
books — the best-so-far MAP trace, the history, the ESS trace, progress and
callback (:class:`~mrfpe.samplers.kit.Run`) — then reweights the last set with
the full target. The algorithms themselves (thesis 6.6.1, 6.6.2, 5.3; Cappé et
al. 2004) are described in :mod:`mrfpe.samplers.pmc`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import numpy as np

from mrfpe.samplers.kit import (
    THESIS_POWER,
    History,
    Run,
    box_log_evidence,
    covariance_kernel,
    ess,
    jitter,
    jitter_mixture,
    log_box_volume,
    log_mixture_box_mass,
    log_ratio,
    log_resampling_mixture,
    normalise_log_weights,
    partition_or_none,
    resample,
    resampling_components,
    softened,
)

__all__ = ["ALGORITHMS", "Algorithm", "MixtureState", "PMCParams", "StepInfo", "StepTarget",
           "Thesis1State", "ThesisState", "final_log_weight", "importance_functions",
           "iterate", "jitter_scale", "mixture_init", "mixture_log_evidence", "mixture_step",
           "soften", "thesis1_init", "thesis1_step", "thesis2_literal_step", "thesis2_step",
           "thesis_init"]

#: A log density over rows of parameter vectors: ``(n, d) -> (n,)``.
LogDensity = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class PMCParams:
    """What the steps read but never change (validated by the samplers).

    ``n_samples`` particles, ``n_iterations`` = T (the jitter schedule's horizon),
    ``sigma0`` (σ₀ of ``σ_n = σ₀ (1 − n/T)``, 6.6), ``resampling`` scheme, softening
    ``power`` (a float, or ``"auto"``: adaptive annealing, mixture only) with its
    ``auto_ess``, the mixture's ``kernel`` (``"isotropic"``, ``"adaptive"``,
    ``"covariance"``) and ``ess_threshold`` (mixture only: resample only when
    ESS < threshold · N).
    """

    n_samples: int
    n_iterations: int
    sigma0: float = 0.07
    resampling: str = "multinomial"
    power: float | str = THESIS_POWER
    auto_ess: float = 0.5
    kernel: str = "isotropic"
    ess_threshold: float | None = None

    def sigma(self, n: int) -> float:
        """The thesis's jitter schedule ``σ_n = σ₀ (1 − n/T)`` (6.6)."""
        return self.sigma0 * (1.0 - n / self.n_iterations)


class StepTarget(NamedTuple):
    """What a step sees of the target: log densities (the driver counts their evaluations)."""

    log_g: LogDensity  # the iteration's importance function G^n
    log_target: LogDensity  # the full target ϱ
    bounds: np.ndarray  # (d, 2)


class StepInfo(NamedTuple):
    """What one iteration evaluated and chose, for the driver's books."""

    log_g: np.ndarray  # G^n at the new particles (the cheap MAP candidate's score)
    log_target: np.ndarray | None  # ϱ at them when the step evaluated it (PMC (I)), else None
    power: float | str  # the softening power in use
    resampled: bool  # whether the iteration resampled (mixture with ess_threshold)


class MixtureState(NamedTuple):
    """Cappé et al.'s PMC after ``iteration`` iterations.

    ``log_weight`` = ``l·log G^n − log q^n``; ``log_den`` = ``log q^n`` (None: the
    uniform start, weighted by the target itself); ``power`` = the ``l`` reached;
    ``mixture`` = with ``kernel="covariance"``, ``(centres, log_w, chol)`` of the
    untruncated mixture ``log_den`` is the density of (for its box mass, the evidence).
    """

    iteration: int
    x: np.ndarray
    log_weight: np.ndarray | None = None
    log_den: np.ndarray | None = None
    power: float = 0.0
    mixture: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


class ThesisState(NamedTuple):
    """PMC (II) after ``iteration`` iterations: ``log_weight`` = ``log c^n`` =
    ``−log G^n(a^n)`` (6.67), ``log_den`` = ``log G^n(a^n)``."""

    iteration: int
    x: np.ndarray
    log_weight: np.ndarray | None = None
    log_den: np.ndarray | None = None


class Thesis1State(NamedTuple):
    """PMC (I) after ``iteration`` iterations: ``x`` = θ^n, ``log_weight`` = ``log π^n``
    (6.66), ``log_den`` = ``log G^n(θ^n)``; ``x_next``, ``log_target_next`` = step 3's
    resampled set and its target values, the next iteration's input."""

    iteration: int
    x: np.ndarray
    x_next: np.ndarray
    log_weight: np.ndarray | None = None
    log_den: np.ndarray | None = None
    log_target_next: np.ndarray | None = None


class Algorithm(NamedTuple):
    """A variant: ``init(x) -> state`` and ``step(params, state, rng, target) -> (state, info)``."""

    init: Callable[[np.ndarray], Any]
    step: Callable[[PMCParams, Any, np.random.Generator, StepTarget], tuple[Any, StepInfo]]


def soften(log_g: np.ndarray, log_q: np.ndarray | float, prev: float, power: float | str,
           auto_ess: float) -> tuple[float, np.ndarray]:
    """Power ``l`` and log weights ``l · log G^n − log q`` (5.69–5.72).

    ``power="auto"`` anneals: ``l`` is the largest value in ``[prev, 1]`` whose
    weights keep ``ESS(l) >= auto_ess · ESS(prev)`` (bisection on log l), so the
    softening adapts to the target's scale and sharpens as the cloud concentrates
    (adaptive tempering, as in SMC samplers).
    """
    def weights(l: float) -> np.ndarray:
        return log_ratio(l * log_g, log_q)

    if power != "auto":
        return float(power), weights(float(power))
    prev = max(prev, 1e-12)
    goal = auto_ess * ess(weights(prev))
    if not np.isfinite(log_g).any() or ess(weights(1.0)) >= goal:
        return 1.0, weights(1.0)
    lo, hi = np.log(prev), 0.0
    if ess(weights(prev)) < goal:  # cannot happen for auto_ess <= 1; kept for safety
        return prev, weights(prev)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess(weights(np.exp(mid))) >= goal else (lo, mid)
    return float(np.exp(lo)), weights(float(np.exp(lo)))


def jitter_scale(params: PMCParams, n: int, x: np.ndarray,
                 lw: np.ndarray) -> float | np.ndarray:
    """The diagonal kernels' scale at iteration n: the thesis's spherical ``σ_n``, or
    (``kernel="adaptive"``) per parameter ``min(σ_n, h · sd_j)`` with ``sd_j`` the
    weighted sd of the cloud and ``h = (4/((d+2) N))^{1/(d+4)}`` (Silverman's factor),
    so the kernel shrinks in directions the target already pins down."""
    sigma = params.sigma(n)
    if params.kernel == "isotropic":
        return sigma
    w = np.exp(normalise_log_weights(lw))
    sd = np.sqrt(np.maximum(w @ (x - w @ x) ** 2, 0.0))
    d = x.shape[1]
    h = (4.0 / ((d + 2) * x.shape[0])) ** (1.0 / (d + 4))
    return np.clip(h * sd, 1e-6 * sigma, sigma)


def mixture_init(x: np.ndarray) -> MixtureState:
    """The starting set ``x``, nothing weighted yet."""
    return MixtureState(0, x)


def mixture_step(params: PMCParams, state: MixtureState, rng: np.random.Generator,
                 target: StepTarget) -> tuple[MixtureState, StepInfo]:
    """Cappé et al.'s PMC: resample, jitter, weight ``G^n / q^n`` (deterministic mixture).

    Iteration 0 weights the starting set, which represents the uniform proposal, by
    ``G^0``. With ``kernel="covariance"`` a draw that leaves the box takes a fresh
    ancestor (:func:`~mrfpe.samplers.kit.jitter_mixture`); the diagonal kernels are
    truncated to the box, with their exact normalisers.
    """
    n, x = state.iteration, state.x
    if n == 0:
        raw = target.log_g(x)
        power, lw = soften(raw, 0.0, 0.0, params.power, params.auto_ess)
        return MixtureState(1, x, lw, None, power), StepInfo(raw, None, power, True)
    lw_prev = state.log_weight
    resampled = bool(params.ess_threshold is None
                     or ess(lw_prev) < params.ess_threshold * lw_prev.size)
    idx = (resample(lw_prev, params.n_samples, params.resampling, rng) if resampled
           else np.arange(x.shape[0]))
    mixture = None
    if params.kernel == "covariance":
        chol = covariance_kernel(x, lw_prev)
        x_new, lq = jitter_mixture(x, idx, chol, target.bounds, rng)
        mixture = (*resampling_components(x, idx), chol)
    else:
        sigma = jitter_scale(params, n, x, lw_prev)
        x_new = jitter(x[idx], sigma, target.bounds, rng)
        lq = log_resampling_mixture(x_new, x, idx, sigma, target.bounds)
    raw = target.log_g(x_new)
    power, lw = soften(raw, lq, state.power, params.power, params.auto_ess)
    return (MixtureState(n + 1, x_new, lw, lq, power, mixture),
            StepInfo(raw, None, power, resampled))


def thesis_init(x: np.ndarray) -> ThesisState:
    """PMC (II)'s grid ``u^0``, nothing weighted yet."""
    return ThesisState(0, x)


def thesis2_step(params: PMCParams, state: ThesisState, rng: np.random.Generator,
                 target: StepTarget, *, literal: bool = False) -> tuple[ThesisState, StepInfo]:
    """PMC (II), 6.6.2: resample with ``w = c^{n-1} G^n(a^{n-1})`` (6.67), jitter,
    ``c^n = 1 / G^n(a^n)``.

    ``literal=False`` (variant ``"thesis2"``) takes ``c^{n-1}`` as the ``1/N`` that
    resampling returns, so ``w = G^n(a^{n-1})`` and the selections compound;
    ``literal=True`` (``"thesis2_literal"``) as ``1/G^{n-1}(a^{n-1})``, so the set
    keeps representing the uniform distribution (and ``k = 1`` gives ``w = 1``).
    """
    n, x = state.iteration, state.x
    w = target.log_g(x)  # u^0 grid weighted by G^0 (6.6.2, n = 0, step 1)
    if n > 0 and literal:
        w = state.log_weight + w  # 6.67 with c^{n-1} = 1/G^{n-1}(a^{n-1})
    idx = resample(w, params.n_samples, params.resampling, rng)
    a = jitter(x[idx], params.sigma(n), target.bounds, rng)
    lg = target.log_g(a)
    lc = log_ratio(0.0, lg)  # c^n = 1/G^n(a^n), zero where G^n = 0
    return ThesisState(n + 1, a, lc, lg), StepInfo(lg, None, params.power, True)


def thesis2_literal_step(params: PMCParams, state: ThesisState, rng: np.random.Generator,
                         target: StepTarget) -> tuple[ThesisState, StepInfo]:
    """PMC (II) with 6.67 read literally (:func:`thesis2_step` with ``literal=True``)."""
    return thesis2_step(params, state, rng, target, literal=True)


def thesis1_init(x: np.ndarray) -> Thesis1State:
    """PMC (I)'s grid ``u^0``: the first iteration's input, nothing weighted yet."""
    return Thesis1State(0, x, x_next=x)


def thesis1_step(params: PMCParams, state: Thesis1State, rng: np.random.Generator,
                 target: StepTarget) -> tuple[Thesis1State, StepInfo]:
    """PMC (I), 6.6.1: ``v = π^{n-1} G^n(θ^{n-1}) / ePL(θ^{n-1})`` (6.66), resample with
    jitter, ``π^n = ePL(θ^n) / G^n(θ^n)``, resample again (step 3). Evaluates the full
    target every iteration (returned in the info)."""
    n, x = state.iteration, state.x_next  # the previous step-3 resampled set
    if n == 0:  # v^0 = G^0(u^0) on the grid
        v = target.log_g(x)
    else:  # π^{n-1} equal after resampling
        v = log_ratio(target.log_g(x), state.log_target_next)
    idx = resample(v, params.n_samples, params.resampling, rng)
    th = jitter(x[idx], params.sigma(n), target.bounds, rng)
    lg = target.log_g(th)
    lt = target.log_target(th)
    lpi = log_ratio(lt, lg)
    res = resample(lpi, params.n_samples, params.resampling, rng)
    return (Thesis1State(n + 1, th, th[res], lpi, lg, lt[res]),
            StepInfo(lg, lt, params.power, True))


ALGORITHMS: dict[str, Algorithm] = {
    "mixture": Algorithm(mixture_init, mixture_step),
    "thesis2": Algorithm(thesis_init, thesis2_step),
    "thesis2_literal": Algorithm(thesis_init, thesis2_literal_step),
    "thesis1": Algorithm(thesis1_init, thesis1_step),
}


def final_log_weight(state: Any, log_target: np.ndarray) -> np.ndarray:
    """The final reweighting with the full target: ``log ϱ(x) − log_den``."""
    return log_target if state.log_den is None else log_ratio(log_target, state.log_den)


def importance_functions(target: Any, k: int, partition: str,
                         power: float | None = None) -> list:
    """The importance functions ``G^n`` cycled ``n mod k`` (7.9): the target's ``k``
    sub-lattice targets (5.67 blocks / 5.68 strided) when it has ``partition``, else the
    full target; softened with ``power`` (5.69) when given (the thesis's weights), as
    they are otherwise (the mixture step softens its weights itself, :func:`soften`)."""
    parts = partition_or_none(target, k, partition) or [target]
    return parts if power is None else [softened(p, power) for p in parts]


def iterate(run: Run, algorithm: Algorithm, params: PMCParams, start: np.ndarray,
            rng: np.random.Generator, importance: Sequence[Any], target: Any,
            bounds: np.ndarray, history: History,
            report: Callable[[int, StepInfo], dict[str, Any]],
            ) -> tuple[Any, np.ndarray, np.ndarray]:
    """The driver: ``params.n_iterations`` steps from ``start`` and the final reweighting.

    Iteration n's step gets ``importance[n mod k]`` as its ``G^n``; every evaluation
    goes through ``run.evaluate`` (counted). After each step the driver offers the
    MAP trace the step's full-target values (PMC (I)) or else evaluates the full
    target at the best particle under ``G^n``, records the history and closes the step
    (ESS, progress, ``callback`` with ``report(n, info)``). The last set is reweighted
    with the full target (:func:`final_log_weight`) and every particle offered.

    Returns ``(state, log_target, log_weight)`` of the final set.
    """
    state = algorithm.init(start)
    full = partial(run.evaluate, target)
    last = params.n_iterations - 1
    for n in range(params.n_iterations):
        view = StepTarget(partial(run.evaluate, importance[n % len(importance)]), full, bounds)
        state, info = algorithm.step(params, state, rng, view)
        lw = state.log_weight
        if n == last:  # final reweighting with the full target
            lt = full(state.x) if info.log_target is None else info.log_target
            lw = final_log_weight(state, lt)
            run.offer(state.x, lt)
        elif info.log_target is not None:
            run.offer(state.x, info.log_target)
        else:
            run.offer_candidate(state.x, info.log_g)
        history.record(state.x, lw)
        run.step(n, ess(lw), **report(n, info))
    return state, lt, lw


def mixture_log_evidence(state: MixtureState, log_weight: np.ndarray, bounds: np.ndarray,
                         rng: np.random.Generator) -> dict[str, float]:
    """``{"log_evidence": …, "log_evidence_se": …}`` (relative to the box,
    :mod:`mrfpe.samplers.kit.evidence`) of the mixture variant's final weights
    ``ϱ(x)/q(x)``; empty when every weight is zero (``build`` refuses the set).

    ``q`` is the last jittered resample's density: exact on the box for the
    diagonal kernels, the untruncated mixture for ``kernel="covariance"`` (its box
    mass is estimated with ``rng``, after the run, so the draws are unchanged); with
    a single iteration the weights are ``ϱ`` itself on the uniform start.
    """
    if not np.isfinite(log_weight).any():
        return {}
    log_vol = log_box_volume(bounds)
    lw = log_weight + log_vol if state.log_den is None else log_weight  # U(box): q = 1/vol
    mass, mass_se = (0.0, 0.0) if state.mixture is None else log_mixture_box_mass(
        *state.mixture, bounds, rng)
    lz, se = box_log_evidence(lw, bounds, mass, mass_se)
    return {"log_evidence": lz, "log_evidence_se": se}
