"""Population Monte Carlo with sub-lattice importance functions (thesis 5.6, 6.6, 7.9).

Importance functions ``G^n`` (7.9): when the target offers ``partition(k, kind)``
they are its ``k`` sub-lattice targets (5.67 blocks / 5.68 strided subsets),
softened with power ``l`` (5.69–5.72) and cycled ``n mod k``; otherwise the
softened full target. Iteration 0 weights a starting set (for the thesis variants the evenly
spaced grid from face to face, for ``"mixture"`` a scrambled Halton design); every
resampling adds Gaussian jitter (the thesis's ``σ_n = σ₀ (1 − n/T)``, σ₀ = 0.07,
6.6), and after the last iteration the set is reweighted with the full target.

Variants
--------
``"mixture"`` (default, Cappé et al. 2004; deterministic-mixture weights):
    iteration n ≥ 1 resamples ancestors from the current weights, jitters them,
    and weights each new particle by ``G^n(x) / q^n(x)`` with
    ``q^n(x) = (1/N) Σ_i N_box(x; x_{I_i}, σ_n² I)`` the density of the jittered
    resampling mixture the particles were drawn from (log-sum-exp over the
    distinct ancestors, vectorised in chunks). The final weights are
    ``target(x) / q^{T-1}(x)``. One ``G^n`` evaluation per particle and iteration.
    By default the softening power anneals adaptively (``power="auto"``), the
    start is a scrambled Halton design (``initial="halton"``; a tensor grid in
    10-D is the 2¹⁰ corners of {0.25, 0.75}¹⁰) and the kernel follows the cloud's
    weighted covariance (``kernel="covariance"``, :func:`~mrfpe.samplers.kit.covariance_kernel`):
    extensions beyond the thesis, measured in ``benchmarks/bench_accuracy.py``
    and ``benchmarks/bench_pmc.py``. ``kernel="adaptive"`` (diagonal
    ``min(σ_n, h·sd_j)``, an earlier default: too narrow once σ_n → 0,
    weighted sd 0.67–0.77 of the truth) and ``initial="grid"`` (cell centres) are kept;
    ``power=<float>, kernel="isotropic"`` is the thesis's fixed softening and
    spherical ``σ_n``.
``"thesis2"`` (PMC (II), 6.6.2, read as compounding): resample with
    ``w = G^n(a^{n-1})`` — 6.67's ``c^{n-1}`` taken as the ``c̄ = 1/N`` that
    resampleParticles returns (5.1.1 step 6) —, jitter, and keep
    ``c^n = 1 / G^n(a^n)`` for π and the weight variance; final weights
    ``ePL(a) / G^{T-1}(a)``; softening :data:`THESIS2_POWER` = 1e-4. The cloud's
    density then compounds, ``≈ ∏_j G^j`` (an annealing ladder over 7.9's cycled
    sub-lattices), which is what reproduces Table 7.1's fall of the MAP distance and
    of the weight variances (``docs/results/pmc_thesis2_readings/report.md``, 30
    scenes). The final weights are then not exact importance weights of the
    posterior (the cloud is not distributed as ``G^{T-1}``): use it for the MAP;
    ``"mixture"`` is the exact variant.
``"thesis2_literal"`` (PMC (II), 6.6.2 as printed): ``w = c^{n-1} G^n(a^{n-1})``
    (6.67) with ``c^{n-1} = 1/G^{n-1}(a^{n-1})`` at the same points, i.e.
    ``G^n/G^{n-1}``: it undoes the previous selection every iteration, so the cloud
    stays distributed as one ``G^n`` and nothing accumulates; with ``k = 1`` the
    weight is exactly 1 (no selection at all after iteration 0). Kept for studies;
    softening :data:`THESIS_POWER`.
``"thesis1"`` (PMC (I), 6.6.1, exact): the set represents the target at every
    iteration: ``v = π^{n-1} G^n(θ^{n-1}) / ePL(θ^{n-1})`` (6.66), resample with
    jitter, ``π^n = ePL(θ^n) / G^n(θ^n)``, resample (full-target evaluations
    every iteration).

Boundary choice: with the diagonal kernels a jittered particle that leaves the
bounds is redrawn from the same kernel (no reflection), i.e. each kernel is the
Gaussian truncated to the box; the mixture density ``q`` uses the truncated
kernels' normalising constants, so the weights stay exact and no particle is
wasted outside the support. A full-covariance kernel's box mass has no closed
form, so with ``kernel="covariance"`` a particle that leaves the box is redrawn
from a *fresh ancestor* (:func:`~mrfpe.samplers.kit.jitter_resampled`): the draws
then follow the untruncated mixture restricted to the box, whose normaliser is
one global constant that self-normalisation removes. Particles where ``G^n`` is
zero get zero weight in the thesis variants (``1/G`` is undefined there).

Evidence: the mixture variant's final weights ``ϱ/q^{T-1}`` are importance weights
of a normalised proposal, so its posteriors carry ``log_evidence`` and
``log_evidence_se``, relative to the box (:mod:`mrfpe.samplers.kit.evidence`;
with ``kernel="covariance"`` the box mass of the untruncated mixture is
estimated from extra draws after the run). The thesis variants divide by an
unnormalised ``G^{T-1}`` that their draws only approximately follow: no
normaliser is defined and none is reported.

The MAP trace is best-so-far under the *full* target: each iteration
evaluates the full target at its best particle under ``G^n`` (one evaluation,
1/N per particle), and the last step offers every finally reweighted particle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import numpy as np
import xarray as xr

from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import (
    GRID_READINGS,
    RESAMPLING_METHODS,
    THESIS2_POWER,
    THESIS_POWER,
    History,
    Run,
    box_log_evidence,
    check_bool,
    check_seed,
    check_target,
    covariance_kernel,
    ess,
    grid,
    jitter,
    jitter_mixture,
    log_box_volume,
    log_kernel_mass,
    log_mixture_box_mass,
    log_mixture_density,
    log_ratio,
    normalise_log_weights,
    partition_or_none,
    resample,
    softened,
    space_filling,
)

__all__ = ["PMC", "THESIS_POWER", "Context", "PMCState", "final_log_weight", "init_state",
           "mixture_log_evidence", "mixture_step", "thesis1_step", "thesis2_literal_step",
           "thesis2_step"]


class Context(NamedTuple):
    """What a step reads but never changes: the run log, the random stream and the box."""

    run: Run
    rng: np.random.Generator
    bounds: np.ndarray


class PMCState(NamedTuple):
    """The particle set after an iteration (immutable; each step returns a new one).

    Attributes
    ----------
    x : (N, d) particles.
    log_weight : (N,) their weights under this iteration (mixture: ``l·log G^n − log q^n``;
        PMC (II): ``log c^n``, 6.67; PMC (I): ``log π^n``, 6.66).
    log_den : what the full target is divided by for the final weights
        (``log q^n``, ``log G^n``), or None for the target itself (mixture, iteration 0).
    power : the softening power in use (mixture ``"auto"`` anneals it).
    resampled : whether this iteration resampled (mixture with ``ess_threshold``).
    log_target : full target at ``x`` when the step evaluated it (PMC (I)), else None.
    x_next, log_target_next : PMC (I)'s step-3 resampled set, the next iteration's input.
    mixture : mixture with ``kernel="covariance"``: ``(centres, log_w, chol)`` of the
        untruncated mixture ``log_den`` is the density of (for its box mass, the evidence).
    """

    x: np.ndarray
    log_weight: np.ndarray | None = None
    log_den: np.ndarray | None = None
    power: float | str = THESIS_POWER
    resampled: bool = True
    log_target: np.ndarray | None = None
    x_next: np.ndarray | None = None
    log_target_next: np.ndarray | None = None
    mixture: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def init_state(x: np.ndarray, power: float | str) -> PMCState:
    """The state before iteration 0: the initial set ``x`` (the grid), nothing weighted yet."""
    return PMCState(x=x, power=power)


def final_log_weight(state: PMCState, log_target: np.ndarray) -> np.ndarray:
    """The final reweighting with the full target: ``log ϱ(x) − log_den``."""
    return log_target if state.log_den is None else log_ratio(log_target, state.log_den)


def mixture_log_evidence(state: PMCState, log_weight: np.ndarray, bounds: np.ndarray,
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


# Each step maps (config, context, state, iteration n, importance function G^n) to the new
# state and the G^n values at the new particles (for the cheap MAP candidate).
Step = Callable[[Any, Context, PMCState, int, Any], tuple[PMCState, np.ndarray]]


def mixture_step(pmc: PMC, ctx: Context, state: PMCState, n: int,
                 g: Any) -> tuple[PMCState, np.ndarray]:
    """Cappé et al.'s PMC: resample, jitter, weight ``G^n / q^n`` (deterministic mixture)."""
    run, x = ctx.run, state.x
    if n == 0:  # evenly spaced grid represents the uniform proposal: weight = G^0
        raw = run.evaluate(g, x)
        power, lw = pmc._soften(raw, 0.0, 0.0)
        return state._replace(log_weight=lw, power=power, log_den=None), raw
    lw_prev = state.log_weight
    ok = pmc.ess_threshold is None or ess(lw_prev) < pmc.ess_threshold * lw_prev.size
    idx = (resample(lw_prev, pmc.n_samples, pmc.resampling, ctx.rng) if ok
           else np.arange(x.shape[0]))
    mixture = None
    if pmc.kernel == "covariance":  # full kernel, out-of-box draws take a fresh ancestor
        chol = covariance_kernel(x, lw_prev)
        x_new, lq = jitter_mixture(x, idx, chol, ctx.bounds, ctx.rng)
        anc, counts = np.unique(idx, return_counts=True)
        mixture = (x[anc], np.log(counts / idx.size), chol)
    else:  # diagonal kernels truncated to the box, with their exact normalisers
        anc, counts = np.unique(idx, return_counts=True)
        sigma = pmc._kernel(n, x, lw_prev)
        x_new = jitter(x[idx], sigma, ctx.bounds, ctx.rng)
        log_w = np.log(counts / idx.size) - log_kernel_mass(x[anc], sigma, ctx.bounds)
        lq = log_mixture_density(x_new, x[anc], log_w, sigma)
    raw = run.evaluate(g, x_new)
    power, lw = pmc._soften(raw, lq, state.power)
    return PMCState(x=x_new, log_weight=lw, log_den=lq, power=power, resampled=bool(ok),
                    mixture=mixture), raw


def thesis2_step(cfg: Any, ctx: Context, state: PMCState, n: int,
                 g: Any, *, literal: bool = False) -> tuple[PMCState, np.ndarray]:
    """PMC (II), 6.6.2: resample with ``w = c^{n-1} G^n(a^{n-1})`` (6.67), jitter,
    ``c^n = 1 / G^n(a^n)``.

    ``literal=False`` (variant ``"thesis2"``) takes ``c^{n-1}`` as the ``1/N`` that
    resampling returns, so ``w = G^n(a^{n-1})`` and the selections compound;
    ``literal=True`` (``"thesis2_literal"``) as ``1/G^{n-1}(a^{n-1})``, so the set
    keeps representing the uniform distribution (and ``k = 1`` gives ``w = 1``).
    ``cfg`` provides ``n_samples``, ``resampling`` and ``sigma(n)`` (PMC and PPF do).
    """
    run, x = ctx.run, state.x
    w = run.evaluate(g, x)  # u^0 grid weighted by G^0 (6.6.2, n = 0, step 1)
    if n > 0 and literal:
        w = state.log_weight + w  # 6.67 with c^{n-1} = 1/G^{n-1}(a^{n-1})
    idx = resample(w, cfg.n_samples, cfg.resampling, ctx.rng)
    a = jitter(x[idx], cfg.sigma(n), ctx.bounds, ctx.rng)
    lg = run.evaluate(g, a)
    lc = log_ratio(0.0, lg)  # c^n = 1/G^n(a^n), zero where G^n = 0
    return state._replace(x=a, log_weight=lc, log_den=lg), lg


def thesis2_literal_step(cfg: Any, ctx: Context, state: PMCState, n: int,
                         g: Any) -> tuple[PMCState, np.ndarray]:
    """PMC (II) with 6.67 read literally (:func:`thesis2_step` with ``literal=True``)."""
    return thesis2_step(cfg, ctx, state, n, g, literal=True)


def thesis1_step(cfg: Any, ctx: Context, state: PMCState, n: int,
                 g: Any) -> tuple[PMCState, np.ndarray]:
    """PMC (I), 6.6.1: ``v = π^{n-1} G^n(θ^{n-1}) / ePL(θ^{n-1})`` (6.66), resample with
    jitter, ``π^n = ePL(θ^n) / G^n(θ^n)``, resample again (step 3)."""
    run = ctx.run
    x = state.x if state.x_next is None else state.x_next  # previous step-3 resampled set
    if n == 0:  # v^0 = G^0(u^0) on the grid
        v = run.evaluate(g, x)
    else:  # π^{n-1} equal after resampling
        v = log_ratio(run.evaluate(g, x), state.log_target_next)
    idx = resample(v, cfg.n_samples, cfg.resampling, ctx.rng)
    th = jitter(x[idx], cfg.sigma(n), ctx.bounds, ctx.rng)
    lg = run.evaluate(g, th)
    lt = run.evaluate(run.target, th)
    run.offer(th, lt)
    lpi = log_ratio(lt, lg)
    res = resample(lpi, cfg.n_samples, cfg.resampling, ctx.rng)
    return state._replace(x=th, log_weight=lpi, log_den=lg, log_target=lt, x_next=th[res],
                          log_target_next=lt[res]), lg


#: Initial sets: the grid of cell centres, the grid from face to face (both "evenly
#: spaced", 6.6), a scrambled Halton design.
INITIAL_SETS = (*GRID_READINGS, "halton")

STEPS: dict[str, Step] = {"mixture": mixture_step, "thesis2": thesis2_step,
                          "thesis2_literal": thesis2_literal_step, "thesis1": thesis1_step}


class PMC(Sampler):
    """Population Monte Carlo: Cappé et al.'s mixture weights or the thesis's PMC (I)/(II).

    Configuration (the thesis's settings, 6.6 and 7.4, where it gives them):
    ``n_samples`` = 1000 particles, ``n_iterations`` = 20, ``variant`` ("mixture",
    "thesis2", "thesis2_literal", "thesis1"), ``k`` = 3 sub-lattices of kind ``partition`` cycled as
    importance functions (7.9), softening ``power`` (5.69–5.72), ``sigma0`` = 0.07
    initial jitter decreasing linearly to 0, ``kernel`` shape, ``resampling``
    scheme (see :mod:`mrfpe.resampling`),
    ``ess_threshold`` (mixture only: resample only when ESS < threshold·N),
    ``initial`` set (``"grid"``: cell centres; ``"grid_faces"``: evenly spaced from
    face to face, :func:`~mrfpe.samplers.kit.grid`; ``"halton"``) and
    ``keep_history`` (store every iteration's weighted set).

    ``power``, ``kernel`` and ``resampling`` = None take the variant's
    defaults: for "mixture" ``power="auto"`` (adaptive annealing, ``auto_ess``),
    ``kernel="covariance"`` (the cloud's weighted covariance), ``initial="halton"``
    and systematic
    resampling (less drift, so a second mode survives to the final reweighting);
    for the thesis variants a fixed power (:data:`THESIS2_POWER` for "thesis2",
    :data:`THESIS_POWER` for the others), the spherical ``σ_n``,
    the evenly spaced grid from face to face (``"grid_faces"``: the reading of "evenly
    spaced" under which PMC (II) reproduces Table 7.1's N = 125 and 64 columns, where the
    cell centres do not; ``docs/results/pmc_convergence_faces/``) and multinomial
    resampling exactly as 6.6. The thesis gives no softening
    power, and on a 100x100 PL the spherical kernel cannot follow a target
    that is ~100x sharper in one parameter than along a ridge in the others:
    ``benchmarks/bench_pmc.py`` measures the choice.
    """

    name = "pmc"
    # Defaults otherwise; 5 iterations keep the conformance suite fast.
    conformance: ClassVar[dict] = {"quick_config": {"n_iterations": 5}}

    def __init__(self, n_samples: int = 1000, n_iterations: int = 20, *,
                 variant: str = "mixture", k: int = 3, partition: str = "strided",
                 power: float | str | None = None, auto_ess: float = 0.5,
                 sigma0: float = 0.07, kernel: str | None = None, resampling: str | None = None,
                 ess_threshold: float | None = None, initial: str | None = None,
                 keep_history: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples, 2)
        self.n_iterations = check_positive_int("n_iterations", n_iterations, 1)
        self.variant = check_choice("variant", variant, tuple(STEPS))
        self.k = check_positive_int("k", k, 1)
        self.partition = check_choice("partition", partition, ("strided", "block"))
        if power is None:  # the variant's default (see the class docstring)
            power = {"mixture": "auto", "thesis2": THESIS2_POWER}.get(variant, THESIS_POWER)
        if isinstance(power, str):
            check_choice("power", power, ("auto",))
            if variant != "mixture":
                raise ValueError("power='auto' applies to variant='mixture' only (the thesis "
                                 f"variants use a fixed softening); got variant={variant!r}")
        else:
            power = check_range("power", power, 0.0, np.inf, low_open=True, high_open=True)
        self.power = power
        self.auto_ess = check_range("auto_ess", auto_ess, 0.0, 1.0, low_open=True, high_open=True)
        self.sigma0 = check_range("sigma0", sigma0, 0.0, np.inf, low_open=True, high_open=True)
        if kernel is None:
            kernel = "covariance" if variant == "mixture" else "isotropic"
        self.kernel = check_choice("kernel", kernel, ("isotropic", "adaptive", "covariance"))
        if kernel != "isotropic" and variant != "mixture":
            raise ValueError(f"kernel={kernel!r} applies to variant='mixture' only (the thesis "
                             f"variants use the spherical σ_n); got variant={variant!r}")
        if initial is None:
            initial = "halton" if variant == "mixture" else "grid_faces"
        self.initial = check_choice("initial", initial, INITIAL_SETS)
        if resampling is None:
            resampling = "systematic" if variant == "mixture" else "multinomial"
        self.resampling = check_choice("resampling", resampling, RESAMPLING_METHODS)
        if ess_threshold is not None:
            ess_threshold = check_range("ess_threshold", ess_threshold, 0.0, 1.0)
            if variant != "mixture":
                raise ValueError("ess_threshold applies to variant='mixture' only (the thesis "
                                 f"variants resample every iteration); got variant={variant!r}")
        self.ess_threshold = ess_threshold
        self.keep_history = check_bool("keep_history", keep_history)

    # -- helpers -------------------------------------------------------------
    def _importance_functions(self, target) -> list:
        parts = partition_or_none(target, self.k, self.partition) or [target]
        if self.variant == "mixture":  # softened below as l · log PL^n (5.69), l fixed or auto
            return parts
        return [softened(p, self.power) for p in parts]

    def _soften(self, log_g: np.ndarray, log_q: np.ndarray | float,
                prev: float) -> tuple[float, np.ndarray]:
        """Power ``l`` and log weights ``l · log G^n - log q`` (5.69–5.72).

        ``power="auto"`` anneals: ``l`` is the largest value in ``[prev, 1]``
        whose weights keep ``ESS(l) >= auto_ess · ESS(prev)`` (bisection on
        log l), so the softening adapts to the target's scale and sharpens as
        the cloud concentrates (adaptive tempering, as in SMC samplers).
        """
        def weights(l: float) -> np.ndarray:
            return log_ratio(l * log_g, log_q)

        if self.power != "auto":
            return float(self.power), weights(float(self.power))
        prev = max(prev, 1e-12)
        goal = self.auto_ess * ess(weights(prev))
        if not np.isfinite(log_g).any() or ess(weights(1.0)) >= goal:
            return 1.0, weights(1.0)
        lo, hi = np.log(prev), 0.0
        if ess(weights(prev)) < goal:  # cannot happen for auto_ess <= 1; kept for safety
            return prev, weights(prev)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ess(weights(np.exp(mid))) >= goal else (lo, mid)
        return float(np.exp(lo)), weights(float(np.exp(lo)))

    def sigma(self, n: int) -> float:
        """The thesis's jitter schedule ``σ_n = σ₀ (1 − n/T)`` (6.6)."""
        return self.sigma0 * (1.0 - n / self.n_iterations)

    def _kernel(self, n: int, x: np.ndarray, lw: np.ndarray) -> float | np.ndarray:
        """Jitter scale at iteration n: the thesis's spherical ``σ_n``, or (``"adaptive"``)
        per parameter ``min(σ_n, h · sd_j)`` with ``sd_j`` the weighted sd of the cloud
        and ``h = (4/((d+2) N))^{1/(d+4)}`` (Silverman's factor), so the kernel shrinks
        in directions the target already pins down."""
        sigma = self.sigma(n)
        if self.kernel == "isotropic":
            return sigma
        w = np.exp(normalise_log_weights(lw))
        sd = np.sqrt(np.maximum(w @ (x - w @ x) ** 2, 0.0))
        d = x.shape[1]
        h = (4.0 / ((d + 2) * x.shape[0])) ** (1.0 / (d + 4))
        return np.clip(h * sd, 1e-6 * sigma, sigma)

    # -- run -----------------------------------------------------------------
    def run(self, target: Any, *, seed: int | None = None, progress: bool = False,
            callback: Callback | None = None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = check_target(target)
        check_seed(seed)
        G = self._importance_functions(target)
        T = self.n_iterations
        run = Run(target, T, progress=progress, callback=callback, desc=f"pmc/{self.variant}",
                  rows=self.n_samples * (T + 4 if self.keep_history else 8))
        ctx = Context(run, np.random.default_rng(seed), bounds)
        step, history = STEPS[self.variant], History(self.keep_history)
        start = (space_filling(bounds, self.n_samples, ctx.rng) if self.initial == "halton"
                 else grid(bounds, self.n_samples, faces=self.initial == "grid_faces"))
        state = init_state(start, self.power)
        for n in range(T):
            state, lg = step(self, ctx, state, n, G[n % len(G)])
            lw = state.log_weight
            if n == T - 1:  # final reweighting with the full target
                lt = state.log_target
                lt = run.evaluate(target, state.x) if lt is None else lt
                lw = final_log_weight(state, lt)
                run.offer(state.x, lt)
            elif self.variant != "thesis1":  # thesis1 already offered full-target values
                run.offer_candidate(state.x, lg)
            history.record(state.x, lw)
            run.step(n, ess(lw), sigma=self.sigma(n), resampled=state.resampled,
                     power=state.power)
        # the thesis variants' final weights ϱ/G divide by an unnormalised G^{T-1} whose
        # draws only approximately follow it: no normaliser is defined, none reported
        ev = (mixture_log_evidence(state, lw, bounds, ctx.rng) if self.variant == "mixture"
              else {})
        return run.finish(state.x, lt, lw, sampler=self.name, config=self.get_config(),
                          seed=seed, **ev, **history.build_kwargs())
