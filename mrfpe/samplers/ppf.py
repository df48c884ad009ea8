"""Partitioned particle filtering over one time step (thesis 5.3, 5.32–5.35).

The initial set is the evenly spaced grid representing the uniform
``p(X^0)`` (equal weights): ``initial="grid_faces"`` (from face to face, the
default with the thesis's weights, as for PMC's thesis variants) or ``"grid"`` (the
cell centres, the default with the mixture weights); :func:`~mrfpe.samplers.kit.grid`.
For each partition ``n = 1..P``: multiply the weights by the importance
function (5.33) ``π ← π g^n(x)``, resample with Gaussian noise ``σ_n`` (the
thesis's multinomial resampling by default), and divide by the importance
function at the new positions (5.34) ``π ← π / g^n(x)``, so the set again
represents the uniform distribution,
concentrated where the ``g^n`` are large. Finally (5.35) ``π ← π ϱ(x)``
with the full target.

The importance functions are the target's sub-lattice targets when it offers
``partition`` (``P`` partitions, 5.67 blocks / 5.68 strided), softened with
power ``l`` (5.69–5.72); otherwise ``P`` stages of the softened full target.
Over one time step this is PMC (II) with ``P`` iterations (thesis 5.6):
``PPF(n_partitions=P, k=P)`` and ``PMC(variant="thesis2_literal", n_iterations=P, k=P)``
give the same numbers, which the tests check.

Weights (``weights``): ``"thesis"`` is the above, bit-for-bit (with the thesis's
fixed power, :data:`~mrfpe.samplers.kit.THESIS_POWER`). It is biased: ``1/g^n``
ignores the jitter, so on a 3-D Gaussian its final ESS is ~10 of 1000 and the mean
~1 sd off, with the same sign over seeds. ``"mixture"`` (the default)
accounts for the jitter: by 5.6 PPF over one time step is PMC, so each partition
runs PMC's deterministic-mixture step (:func:`mrfpe.samplers.pmc_steps.mixture_step`:
weights ``g^n(x)^l / q^n(x)`` with ``q^n`` the jittered resample's density, a kernel
following the cloud's covariance, the power annealed, ``power="auto"``) from the
same grid, and the final weights are ``ϱ(x) / q(x)``; they give ``log_evidence`` and
``log_evidence_se`` as PMC's do (:func:`mrfpe.samplers.pmc_steps.mixture_log_evidence`).
The thesis weights run PMC (II)'s literal step
(:func:`mrfpe.samplers.pmc_steps.thesis2_literal_step`); both through the same
driver as PMC (:func:`mrfpe.samplers.pmc_steps.iterate`).

``σ_n = σ₀ (1 − n/P)``; a jittered particle that leaves the bounds is redrawn
from the same kernel. Particles where ``g^n`` vanishes get zero weight. The MAP
trace is best-so-far under the full target (one evaluation per stage at the best
particle under ``g^n``; all particles at the end).
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
    check_bool,
    check_seed,
    check_target,
    grid,
    grid_reading,
)
from mrfpe.samplers.pmc_steps import (
    ALGORITHMS,
    PMCParams,
    StepInfo,
    importance_functions,
    iterate,
    mixture_log_evidence,
)

__all__ = ["PPF"]


class PPF(Sampler):
    """Partitioned particle filter over one time step (thesis 5.3), sub-lattice partitions."""

    name = "ppf"
    # Conformance: the analytic targets have O(10) log densities, so power 0.3 plays the role
    # of the softening a 100x100 pseudolikelihood needs; one pass over k = 3 partitions.
    # The default mixture weights pass the standard moment tolerances; the thesis weights
    # (weights="thesis", 1/g^n ignoring the jitter) would not (final ESS ~10-50 of 1000).
    conformance: ClassVar[dict] = {"quick_config": {"n_partitions": 3, "power": 0.3}}

    def __init__(self, n_samples: int = 1000, n_partitions: int = 20, *, k: int = 3,
                 partition: str = "strided", power: float | str | None = None,
                 sigma0: float = 0.07, resampling: str = "multinomial",
                 weights: str = "mixture", initial: str | None = None,
                 keep_history: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples, 2)
        self.n_partitions = check_positive_int("n_partitions", n_partitions, 1)
        self.k = check_positive_int("k", k, 1)
        self.partition = check_choice("partition", partition, ("strided", "block"))
        self.weights = check_choice("weights", weights, ("mixture", "thesis"))
        self.initial = grid_reading(initial, thesis=self.weights == "thesis")
        if power is None:  # the weights' default: adaptive for "mixture", 5.69 fixed for thesis
            power = "auto" if self.weights == "mixture" else THESIS_POWER
        if isinstance(power, str):
            check_choice("power", power, ("auto",))
            if self.weights != "mixture":
                raise ValueError("power='auto' applies to weights='mixture' only")
        else:
            power = check_range("power", power, 0.0, np.inf, low_open=True, high_open=True)
        self.power = power
        self.sigma0 = check_range("sigma0", sigma0, 0.0, np.inf, low_open=True, high_open=True)
        self.resampling = check_choice("resampling", resampling, RESAMPLING_METHODS)
        self.keep_history = check_bool("keep_history", keep_history)

    def params(self) -> PMCParams:
        """The frozen parameters of the steps: ``P`` iterations of the jitter schedule, the
        mixture step's covariance kernel (the thesis's step uses the spherical ``σ_n``)."""
        kernel = "covariance" if self.weights == "mixture" else "isotropic"
        return PMCParams(self.n_samples, self.n_partitions, self.sigma0, self.resampling,
                         self.power, kernel=kernel)

    def sigma(self, n: int) -> float:
        """Jitter of partition n: ``σ_n = σ₀ (1 − n/P)``."""
        return self.params().sigma(n)

    def run(self, target: Any, *, seed: int | None = None, progress: bool = False,
            callback: Callback | None = None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = check_target(target)
        check_seed(seed)
        P, params = self.n_partitions, self.params()
        if self.weights == "thesis":
            # 5.33 (π ← π g^n), resample with noise, 5.34 (π ← π / g^n): PMC (II)'s step
            algorithm = ALGORITHMS["thesis2_literal"]
            G = importance_functions(target, self.k, self.partition, self.power)
        else:  # the jitter accounted for: PMC's deterministic-mixture step (thesis 5.6)
            algorithm = ALGORITHMS["mixture"]
            G = importance_functions(target, self.k, self.partition)
        run = Run(target, P, progress=progress, callback=callback, desc="ppf",
                  rows=self.n_samples * (P + 4 if self.keep_history else 8))
        rng = np.random.default_rng(seed)
        start = grid(bounds, self.n_samples, faces=self.initial == "grid_faces")  # p(X^0)
        history = History(self.keep_history)

        def report(n: int, info: StepInfo) -> dict[str, Any]:
            return {"sigma": params.sigma(n)}

        # the last iteration reweights with the full target, 5.35: π ← π ϱ(x)
        state, lt, lw = iterate(run, algorithm, params, start, rng, G, target, bounds,
                                history, report)
        # mixture weights are importance weights (PMC's evidence); the thesis's 1/g^n are not
        ev = (mixture_log_evidence(state, lw, bounds, rng) if self.weights == "mixture"
              else {})
        return run.finish(state.x, lt, lw, sampler=self.name, config=self.get_config(),
                          seed=seed, **ev, **history.build_kwargs())
