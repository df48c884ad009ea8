"""Sample-importance-resample on a static target (thesis 5.2.1 and 5.2.2).

``variant="classic"`` (5.25–5.28), the bootstrap filter: the proposal ``g^t`` is
the previous set resampled (5.28, the thesis's multinomial by default) and
diffused by Gaussian noise ``σ_t`` (the stochastic diffusion of 5.1), so the
weight 5.26 reduces to the observation density. A static target is seen as
``T`` identical observations tempered by ``1/T`` — ``p(Z^t | θ) = ϱ(θ)^{1/T}`` —
so that after the last step the weighted set represents ``ϱ`` itself. Step 0
weights the evenly spaced grid (the uniform ``p(X^0)``). Every step evaluates
the full target.

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
The MAP trace is best-so-far under the full target.
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
    log_ratio,
    partition_or_none,
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
                 power: float = THESIS_POWER, keep_history: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples, 2)
        self.n_iterations = check_positive_int("n_iterations", n_iterations, 1)
        self.variant = check_choice("variant", variant, ("classic", "alternative"))
        self.sigma0 = check_range("sigma0", sigma0, 0.0, np.inf, low_open=True, high_open=True)
        self.resampling = check_choice("resampling", resampling, METHODS)
        self.k = check_positive_int("k", k, 1)
        self.partition = check_choice("partition", partition, ("strided", "block"))
        self.power = check_range("power", power, 0.0, np.inf, low_open=True, high_open=True)
        if not isinstance(keep_history, bool | np.bool_):
            raise ValueError(f"keep_history must be a bool; got {keep_history!r}")
        self.keep_history = bool(keep_history)

    def _sigma(self, t: int) -> float:
        return self.sigma0 * (1.0 - t / self.n_iterations)

    def run(self, target, *, seed: int | None = None, progress: bool = False,
            callback=None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = check_target(target)
        check_seed(seed)
        rng = np.random.default_rng(seed)
        T, N = self.n_iterations, self.n_samples
        run = Run(target, T, progress=progress, callback=callback, desc=f"sir/{self.variant}")
        u = grid(bounds, N)
        if self.variant == "alternative":
            parts = partition_or_none(target, self.k, self.partition) or [target]
            G = [softened(p, self.power) for p in parts]
            g_grid = [run.evaluate(g, u) for g in G]  # 5.29 on the fixed set: once per g
        hist_x, hist_w = [], []
        x, lw = u, np.zeros(N)
        for t in range(T):
            if self.variant == "classic":
                if t > 0:  # g^t: resample (5.28) then diffuse
                    idx = _resample(lw, N, self.resampling, rng)
                    x = jitter(x[idx], self._sigma(t), bounds, rng)
                lt = run.evaluate(target, x)
                lw = lt / T  # 5.26 with the bootstrap proposal: ϱ^{1/T}; -inf stays -inf
            else:
                g = G[t % len(G)]
                idx = _resample(g_grid[t % len(G)], N, self.resampling, rng)  # step 3
                x = jitter(u[idx], self._sigma(t), bounds, rng)
                lt = run.evaluate(target, x)
                lw = log_ratio(lt, run.evaluate(g, x))  # 5.30
            run.offer(x, lt)
            if self.keep_history:
                hist_x.append(x.copy())
                hist_w.append(normalise_log_weights(lw))
            run.step(t, ess(lw), sigma=self._sigma(t))
        return run.finish(x, lt, lw, sampler=self.name, config=self.get_config(), seed=seed,
                          history_theta=np.asarray(hist_x) if self.keep_history else None,
                          history_log_weight=np.asarray(hist_w) if self.keep_history else None)
