"""Population Monte Carlo with sub-lattice importance functions (thesis 5.6, 6.6, 7.9).

Importance functions ``G^n`` (7.9): when the target offers ``partition(k, kind)``
they are its ``k`` sub-lattice targets (5.67 blocks / 5.68 strided subsets),
softened with power ``l`` (5.69–5.72) and cycled ``n mod k``; otherwise the
softened full target. Iteration 0 weights an evenly spaced grid; every
resampling adds Gaussian jitter ``σ_n = σ₀ (1 − n/T)`` (σ₀ = 0.07, 6.6), and
after the last iteration the set is reweighted with the full target.

Variants
--------
``"mixture"`` (default, Cappé et al. 2004; deterministic-mixture weights):
    iteration n ≥ 1 resamples ancestors from the current weights, jitters them,
    and weights each new particle by ``G^n(x) / q^n(x)`` with
    ``q^n(x) = (1/N) Σ_i N_box(x; x_{I_i}, σ_n² I)`` the density of the jittered
    resampling mixture the particles were drawn from (log-sum-exp over the
    distinct ancestors, vectorised in chunks). The final weights are
    ``target(x) / q^{T-1}(x)``. One ``G^n`` evaluation per particle and iteration.
    By default the softening power anneals adaptively (``power="auto"``) and the
    kernel is diagonal, ``min(σ_n, h·sd_j)`` per parameter (``kernel="adaptive"``):
    extensions beyond the thesis, measured in ``benchmarks/bench_pmc.py``;
    ``power=<float>, kernel="isotropic"`` is the thesis's fixed softening and
    spherical ``σ_n``.
``"thesis2"`` (PMC (II), 6.6.2, exact): the set represents the uniform
    distribution: ``w = c^{n-1} G^n(a^{n-1})`` (6.67), resample with jitter,
    ``c^n = 1 / G^n(a^n)``; final weights ``ePL(a) / G^{T-1}(a)``.
``"thesis1"`` (PMC (I), 6.6.1, exact): the set represents the target at every
    iteration: ``v = π^{n-1} G^n(θ^{n-1}) / ePL(θ^{n-1})`` (6.66), resample with
    jitter, ``π^n = ePL(θ^n) / G^n(θ^n)``, resample (full-target evaluations
    every iteration).

Boundary choice: a jittered particle that leaves the bounds is redrawn from the
same kernel (no reflection), i.e. each kernel is the Gaussian truncated to the
box; the mixture density ``q`` uses the truncated kernels' normalising
constants, so the weights stay exact and no particle is wasted outside the
support. Particles where ``G^n`` is zero get zero weight in the thesis variants
(``1/G`` is undefined there).

The MAP trace is best-so-far under the *full* target: each iteration
evaluates the full target at its best particle under ``G^n`` (one evaluation,
1/N per particle), and the last step offers every finally reweighted particle.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import xarray as xr

from mrfpe.posterior import ess, normalise_log_weights
from mrfpe.resampling import METHODS
from mrfpe.resampling import resample as _resample
from mrfpe.samplers.base import Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import (
    THESIS_POWER,
    Run,
    check_seed,
    check_target,
    grid,
    jitter,
    log_kernel_mass,
    log_mixture_density,
    log_ratio,
    partition_or_none,
    softened,
)

__all__ = ["PMC", "THESIS_POWER"]


class PMC(Sampler):
    """Population Monte Carlo: Cappé et al.'s mixture weights or the thesis's PMC (I)/(II).

    Configuration (the thesis's settings, 6.6 and 7.4, where it gives them):
    ``n_samples`` = 1000 particles, ``n_iterations`` = 20, ``variant`` ("mixture",
    "thesis2", "thesis1"), ``k`` = 3 sub-lattices of kind ``partition`` cycled as
    importance functions (7.9), softening ``power`` (5.69–5.72), ``sigma0`` = 0.07
    initial jitter decreasing linearly to 0, ``kernel`` shape, ``resampling``
    scheme (see :mod:`mrfpe.resampling`),
    ``ess_threshold`` (mixture only: resample only when ESS < threshold·N) and
    ``keep_history`` (store every iteration's weighted set).

    ``power``, ``kernel`` and ``resampling`` = None take the variant's
    defaults: for "mixture" ``power="auto"`` (adaptive annealing, ``auto_ess``),
    ``kernel="adaptive"`` (per-parameter ``min(σ_n, h·sd_j)``) and systematic
    resampling (less drift, so a second mode survives to the final reweighting);
    for the thesis variants the fixed :data:`THESIS_POWER`, the spherical ``σ_n``
    and multinomial resampling exactly as 6.6. The thesis gives no softening
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
                 ess_threshold: float | None = None, keep_history: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples, 2)
        self.n_iterations = check_positive_int("n_iterations", n_iterations, 1)
        self.variant = check_choice("variant", variant, ("mixture", "thesis2", "thesis1"))
        self.k = check_positive_int("k", k, 1)
        self.partition = check_choice("partition", partition, ("strided", "block"))
        if power is None:  # the variant's default (see the class docstring)
            power = "auto" if variant == "mixture" else THESIS_POWER
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
            kernel = "adaptive" if variant == "mixture" else "isotropic"
        self.kernel = check_choice("kernel", kernel, ("isotropic", "adaptive"))
        if kernel == "adaptive" and variant != "mixture":
            raise ValueError("kernel='adaptive' applies to variant='mixture' only (the thesis "
                             f"variants use the spherical σ_n); got variant={variant!r}")
        if resampling is None:
            resampling = "systematic" if variant == "mixture" else "multinomial"
        self.resampling = check_choice("resampling", resampling, METHODS)
        if ess_threshold is not None:
            ess_threshold = check_range("ess_threshold", ess_threshold, 0.0, 1.0)
            if variant != "mixture":
                raise ValueError("ess_threshold applies to variant='mixture' only (the thesis "
                                 f"variants resample every iteration); got variant={variant!r}")
        self.ess_threshold = ess_threshold
        if not isinstance(keep_history, bool | np.bool_):
            raise ValueError(f"keep_history must be a bool; got {keep_history!r}")
        self.keep_history = bool(keep_history)

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

    def _sigma(self, n: int) -> float:
        return self.sigma0 * (1.0 - n / self.n_iterations)

    def _kernel(self, n: int, x: np.ndarray, lw: np.ndarray) -> float | np.ndarray:
        """Jitter scale at iteration n: the thesis's spherical ``σ_n``, or (``"adaptive"``)
        per parameter ``min(σ_n, h · sd_j)`` with ``sd_j`` the weighted sd of the cloud
        and ``h = (4/((d+2) N))^{1/(d+4)}`` (Silverman's factor), so the kernel shrinks
        in directions the target already pins down."""
        sigma = self._sigma(n)
        if self.kernel == "isotropic":
            return sigma
        w = np.exp(normalise_log_weights(lw))
        sd = np.sqrt(np.maximum(w @ (x - w @ x) ** 2, 0.0))
        d = x.shape[1]
        h = (4.0 / ((d + 2) * x.shape[0])) ** (1.0 / (d + 4))
        return np.clip(h * sd, 1e-6 * sigma, sigma)

    def _jitter(self, x: np.ndarray, idx: np.ndarray, sigma, rng) -> np.ndarray:
        return jitter(x[idx], sigma, self._bounds, rng)

    # -- run -----------------------------------------------------------------
    def run(self, target, *, seed: int | None = None, progress: bool = False,
            callback=None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = self._bounds = check_target(target)
        check_seed(seed)
        rng = np.random.default_rng(seed)
        G = self._importance_functions(target)
        T, N = self.n_iterations, self.n_samples
        run = Run(target, T, progress=progress, callback=callback, desc=f"pmc/{self.variant}")
        hist_x, hist_w = [], []
        step = {"mixture": self._mixture_step, "thesis2": self._thesis2_step,
                "thesis1": self._thesis1_step}[self.variant]
        state: dict = {"x": grid(bounds, N)}
        for n in range(T):
            g = G[n % len(G)]
            lw, lg = step(n, g, state, run, rng)
            last = n == T - 1
            if last:  # final reweighting with the full target
                lt = state["lt"] if "lt" in state else run.evaluate(target, state["x"])
                lw = state["final"](lt)
                run.offer(state["x"], lt)
            elif self.variant != "thesis1":  # thesis1 already offered full-target values
                run.offer_candidate(state["x"], lg)
            if self.keep_history:
                hist_x.append(state["x"].copy())
                hist_w.append(normalise_log_weights(lw))
            run.step(n, ess(lw), sigma=self._sigma(n), resampled=state.get("resampled", True),
                     power=state.get("power", self.power))
        hx = np.asarray(hist_x) if self.keep_history else None
        hw = np.asarray(hist_w) if self.keep_history else None
        return run.finish(state["x"], lt, lw, sampler=self.name, config=self.get_config(),
                          seed=seed, history_theta=hx, history_log_weight=hw)

    # Each step updates ``state["x"]`` (the particles after iteration n), stores in
    # ``state["final"]`` how full-target values become final log weights, and returns
    # (log weights of the set under this iteration, G^n values used for the MAP candidate).
    def _mixture_step(self, n, g, state, run, rng):
        x = state["x"]
        state.pop("lt", None)
        if n == 0:  # evenly spaced grid represents the uniform proposal: weight = G^0
            raw = run.evaluate(g, x)
            state["power"], lw = self._soften(raw, 0.0, 0.0)
            state.update(lw=lw, final=lambda lt: lt)
            return lw, raw
        lw_prev = state["lw"]
        sigma = self._kernel(n, x, lw_prev)
        ok = (self.ess_threshold is None
              or ess(lw_prev) < self.ess_threshold * lw_prev.size)
        idx = _resample(lw_prev, self.n_samples, self.resampling, rng) if ok else \
            np.arange(x.shape[0])
        state["resampled"] = bool(ok)
        anc, counts = np.unique(idx, return_counts=True)
        x_new = self._jitter(x, idx, sigma, rng)
        log_w = np.log(counts / idx.size) - log_kernel_mass(x[anc], sigma, self._bounds)
        lq = log_mixture_density(x_new, x[anc], log_w, sigma)
        raw = run.evaluate(g, x_new)
        state["power"], lw = self._soften(raw, lq, state["power"])
        state.update(x=x_new, lw=lw, final=lambda lt: log_ratio(lt, lq))
        return lw, raw

    def _thesis2_step(self, n, g, state, run, rng):
        x = state["x"]
        if n == 0:  # u^0 grid weighted by G^0 (6.6.2, n = 0, step 1)
            w = run.evaluate(g, x)
        else:  # 6.67: w = c^{n-1} G^n(a^{n-1})
            w = state["lc"] + run.evaluate(g, x)
        idx = _resample(w, self.n_samples, self.resampling, rng)
        a = self._jitter(x, idx, self._sigma(n), rng)
        lg = run.evaluate(g, a)
        lc = log_ratio(0.0, lg)  # c^n = 1/G^n(a^n), zero where G^n = 0
        state.update(x=a, lc=lc, final=lambda lt: log_ratio(lt, lg))
        return lc, lg

    def _thesis1_step(self, n, g, state, run, rng):
        x = state.get("x_next", state["x"])  # the resampled set of the previous iteration
        if n == 0:  # v^0 = G^0(u^0) on the grid
            v = run.evaluate(g, x)
        else:  # 6.66: v = π^{n-1} G^n(θ^{n-1}) / ePL(θ^{n-1}); π^{n-1} equal after resampling
            lt_prev = state["lt_res"]
            v = log_ratio(run.evaluate(g, x), lt_prev)
        idx = _resample(v, self.n_samples, self.resampling, rng)
        th = self._jitter(x, idx, self._sigma(n), rng)
        lg = run.evaluate(g, th)
        lt = run.evaluate(run.target, th)
        run.offer(th, lt)
        lpi = log_ratio(lt, lg)
        # step 3: {θ^n, π^n} = resampleParticles({θ^n, π^n}) — kept as the next input
        res = _resample(lpi, self.n_samples, self.resampling, rng)
        state.update(x=th, x_next=th[res], lt=lt, lt_res=lt[res], final=lambda _lt: lpi)
        return lpi, lg
