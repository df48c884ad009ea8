"""Sample-importance-resample on a static target (thesis 5.2.1 and 5.2.2).

``variant="classic"`` (5.25–5.28), the bootstrap filter: the proposal ``g^t`` is
the previous set resampled (5.28, the thesis's multinomial by default) and
diffused by Gaussian noise ``σ_t`` (the stochastic diffusion of 5.1), so the
weight 5.26 reduces to the observation density. A static target is seen as
``T`` identical observations tempered by ``1/T`` — ``p(Z^t | θ) = ϱ(θ)^{1/T}`` —
so that after the last step the weighted set represents ``ϱ`` itself. Step 0
weights the evenly spaced grid (the uniform ``p(X^0)``). Every step evaluates
the full target.

The evenly spaced set is ``initial``: ``"grid_faces"`` (from face to face, the
default with the thesis's weights, as for PMC's thesis variants: the reading of
"evenly spaced" that reproduces Table 7.1) or ``"grid"`` (cell centres, the default
with the mixture weights); :func:`~mrfpe.samplers.kit.grid`.

``variant="alternative"`` (5.29–5.31), importance reweighting: at every step
the fixed evenly spaced set ``x^U`` is weighted by the importance function
``g^t`` (5.29), resampled with noise ``σ_t``, and reweighted by
``ϱ(x) / g^t(x)`` (5.30, flat prior). ``g^t`` are the softened sub-lattice
targets cycled ``t mod k`` (as PMC's 7.9) when the target offers
``partition``, else the softened full target. The steps are independent
draws; the last one is returned. As in the thesis the density of ``g^t`` is
used for the jittered particles (the noise is not accounted for), so with
``σ → 0`` the final set sits on the grid: a coarse estimate, kept exact for studies.

``σ_t = σ₀ (1 − t/T)``; a jittered particle that leaves the bounds is redrawn
from the same kernel (the Gaussian truncated to the box).

Weights (``weights``): ``"thesis"`` is the above, bit-for-bit — biased, because the
diffusion is never accounted for (on a 3-D Gaussian the weighted sd is 1.1–1.3×
the truth). ``"mixture"`` (the default) uses deterministic-mixture
weights (Cappé et al. 2004): classic step t weights each particle by
``ϱ^{(t+1)/T}(x) / q_t(x)``, with ``q_t`` the density of the jittered resample it was
drawn from and the kernel following the cloud's weighted covariance
(:func:`~mrfpe.samplers.kit.covariance_kernel`; σ₀ then no longer applies), so the
last step is exact importance sampling of ϱ; the alternative variant divides by
the mixture over the grid with the σ_t kernel instead of by ``g^t``.
The MAP trace is best-so-far under the full target.

Evidence: with ``weights="mixture"`` the last step's weights ``ϱ/q`` are importance
weights of a normalised proposal, so the posterior carries ``log_evidence`` and
``log_evidence_se`` relative to the box (:mod:`mrfpe.samplers.kit.evidence`); the
thesis weights define no normaliser and report none.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import xarray as xr

from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import (
    RESAMPLING_METHODS,
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
    grid_reading,
    jitter,
    jitter_mixture,
    log_box_volume,
    log_mixture_box_mass,
    log_ratio,
    log_resampling_mixture,
    partition_or_none,
    resample,
    resampling_components,
    softened,
)

__all__ = ["SIR"]


class SIR(Sampler):
    """Sample-importance-resample (thesis 5.2.1 classic bootstrap, 5.2.2 alternative)."""

    name = "sir"
    conformance: ClassVar[dict] = {"quick_config": {"n_samples": 1000, "n_iterations": 8}}

    def __init__(self, n_samples: int = 1000, n_iterations: int = 20, *,
                 variant: str = "classic", sigma0: float = 0.07,
                 resampling: str = "multinomial", k: int = 3, partition: str = "strided",
                 power: float = THESIS_POWER, weights: str = "mixture",
                 initial: str | None = None, keep_history: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples, 2)
        self.n_iterations = check_positive_int("n_iterations", n_iterations, 1)
        self.variant = check_choice("variant", variant, ("classic", "alternative"))
        self.sigma0 = check_range("sigma0", sigma0, 0.0, np.inf, low_open=True, high_open=True)
        self.resampling = check_choice("resampling", resampling, RESAMPLING_METHODS)
        self.k = check_positive_int("k", k, 1)
        self.partition = check_choice("partition", partition, ("strided", "block"))
        self.power = check_range("power", power, 0.0, np.inf, low_open=True, high_open=True)
        self.weights = check_choice("weights", weights, ("mixture", "thesis"))
        self.initial = grid_reading(initial, thesis=self.weights == "thesis")
        self.keep_history = check_bool("keep_history", keep_history)

    def sigma(self, t: int) -> float:
        """Jitter of step t: ``σ_t = σ₀ (1 − t/T)``."""
        return self.sigma0 * (1.0 - t / self.n_iterations)

    def run(self, target: Any, *, seed: int | None = None, progress: bool = False,
            callback: Callback | None = None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = check_target(target)
        check_seed(seed)
        rng = np.random.default_rng(seed)
        run = Run(target, self.n_iterations, progress=progress, callback=callback,
                  desc=f"sir/{self.variant}",
                  rows=self.n_samples * (self.n_iterations + 4 if self.keep_history else 8))
        x = grid(bounds, self.n_samples, faces=self.initial == "grid_faces")  # p(X^0)
        step = self._classic_step if self.variant == "classic" else self._alternative_step(
            target, run, x)
        history = History(self.keep_history)
        lw = np.zeros(self.n_samples)
        for t in range(self.n_iterations):
            x, lt, lw, mixture = step(t, x, lw, target, run, rng, bounds)
            run.offer(x, lt)
            history.record(x, lw)
            run.step(t, ess(lw), sigma=self.sigma(t))
        ev = self._log_evidence(lw, mixture, bounds, rng)
        bias = None if self.weights == "mixture" else (
            "weights='thesis' (5.26, 5.30 as printed) ignore the jitter's density, so the "
            "weighted set is not a sample of the target (on a 3-D Gaussian its sd is 1.1-1.3x "
            "the truth); weights='mixture' (the default) corrects this")
        return run.finish(x, lt, lw, sampler=self.name, config=self.get_config(), seed=seed,
                          bias=bias, **ev, **history.build_kwargs())

    def _log_evidence(self, lw, mixture, bounds, rng) -> dict[str, float]:
        """Relative to the box (:mod:`mrfpe.samplers.kit.evidence`), for the mixture
        weights only: the last step's ``ϱ/q`` are importance weights of a normalised
        proposal (up to the covariance mixture's box mass ``M``, estimated after the
        run). The thesis weights (``ϱ^{1/T}``, ``ϱ/g^t``) are not: none is reported."""
        if self.weights != "mixture" or not np.isfinite(lw).any():
            return {}
        if self.n_iterations == 1 and self.variant == "classic":  # ϱ on the uniform grid
            lw = lw + log_box_volume(bounds)
        mass, mass_se = (0.0, 0.0) if mixture is None else log_mixture_box_mass(
            *mixture, bounds, rng)
        lz, se = box_log_evidence(lw, bounds, mass, mass_se)
        return {"log_evidence": lz, "log_evidence_se": se}

    def _classic_step(self, t, x, lw, target, run, rng, bounds):
        """5.25–5.28: resample (5.28), diffuse, weight by ``ϱ^{1/T}`` (5.26, bootstrap).

        ``weights="mixture"``: step t targets ``ϱ^{(t+1)/T}`` and divides by the density
        ``q_t`` of the jittered resample it drew from, so the diffusion is accounted for.
        """
        if t == 0:
            lt = run.evaluate(target, x)
            return x, lt, lt / self.n_iterations, None  # -inf stays -inf
        idx = resample(lw, self.n_samples, self.resampling, rng)
        if self.weights == "thesis":
            x_new = jitter(x[idx], self.sigma(t), bounds, rng)
            lt = run.evaluate(target, x_new)
            return x_new, lt, lt / self.n_iterations, None
        # the kernel follows the cloud (kit.covariance_kernel), not the σ_t schedule: a
        # kernel much narrower than the target makes q spiky and the weights degenerate
        chol = covariance_kernel(x, lw)
        x_new, lq = jitter_mixture(x, idx, chol, bounds, rng)
        lt = run.evaluate(target, x_new)
        mixture = (*resampling_components(x, idx), chol)  # for the evidence's box mass
        return x_new, lt, log_ratio((t + 1) / self.n_iterations * lt, lq), mixture

    def _alternative_step(self, target, run, u):
        """5.29–5.31 on the fixed set ``u``: ``g^t`` evaluated there once per function."""
        parts = partition_or_none(target, self.k, self.partition) or [target]
        G = [softened(p, self.power) for p in parts]
        g_grid = [run.evaluate(g, u) for g in G]  # 5.29 on the fixed set: once per g

        def step(t, x, lw, target, run, rng, bounds):
            i = t % len(G)
            idx = resample(g_grid[i], self.n_samples, self.resampling, rng)  # step 3
            x = jitter(u[idx], self.sigma(t), bounds, rng)
            lt = run.evaluate(target, x)
            if self.weights == "mixture":  # the density x was drawn from, jitter included
                return x, lt, log_ratio(lt, log_resampling_mixture(x, u, idx, self.sigma(t),
                                                                   bounds)), None
            return x, lt, log_ratio(lt, run.evaluate(G[i], x)), None  # 5.30

        return step
