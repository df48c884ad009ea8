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

The iterations are steps (:mod:`mrfpe.samplers.pmc_steps`): each variant is an
``init``/``step`` pair over frozen :class:`~mrfpe.samplers.pmc_steps.PMCParams`
and its own immutable state, and :meth:`PMC.run` is the driver; it changes
nothing on the sampler object.
"""

from __future__ import annotations

from typing import Any, ClassVar

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
    check_bool,
    check_seed,
    check_target,
    grid,
    space_filling,
)
from mrfpe.samplers.pmc_steps import (
    ALGORITHMS,
    PMCParams,
    StepInfo,
    importance_functions,
    iterate,
    mixture_log_evidence,
)

__all__ = ["PMC"]

#: Initial sets: the grid of cell centres, the grid from face to face (both "evenly
#: spaced", 6.6), a scrambled Halton design.
INITIAL_SETS = (*GRID_READINGS, "halton")


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
        self.variant = check_choice("variant", variant, tuple(ALGORITHMS))
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

    def params(self) -> PMCParams:
        """The frozen parameters the steps read (:class:`~mrfpe.samplers.pmc_steps.PMCParams`)."""
        return PMCParams(self.n_samples, self.n_iterations, self.sigma0, self.resampling,
                         self.power, self.auto_ess, self.kernel, self.ess_threshold)

    def sigma(self, n: int) -> float:
        """The thesis's jitter schedule ``σ_n = σ₀ (1 − n/T)`` (6.6)."""
        return self.params().sigma(n)

    def run(self, target: Any, *, seed: int | None = None, progress: bool = False,
            callback: Callback | None = None) -> xr.Dataset:
        """Sample ``target``; returns the posterior Dataset (DESIGN.md)."""
        bounds = check_target(target)
        check_seed(seed)
        params = self.params()
        # the mixture softens its weights, l · log G^n (5.69), with l fixed or annealed
        G = importance_functions(target, self.k, self.partition,
                                 None if self.variant == "mixture" else self.power)
        T = self.n_iterations
        run = Run(target, T, progress=progress, callback=callback, desc=f"pmc/{self.variant}",
                  rows=self.n_samples * (T + 4 if self.keep_history else 8))
        rng = np.random.default_rng(seed)
        start = (space_filling(bounds, self.n_samples, rng) if self.initial == "halton"
                 else grid(bounds, self.n_samples, faces=self.initial == "grid_faces"))
        history = History(self.keep_history)

        def report(n: int, info: StepInfo) -> dict[str, Any]:
            return {"sigma": params.sigma(n), "resampled": info.resampled, "power": info.power}

        state, lt, lw = iterate(run, ALGORITHMS[self.variant], params, start, rng, G, target,
                                bounds, history, report)
        # the thesis variants' final weights ϱ/G divide by an unnormalised G^{T-1} whose
        # draws only approximately follow it: no normaliser is defined, none reported
        ev = (mixture_log_evidence(state, lw, bounds, rng) if self.variant == "mixture"
              else {})
        return run.finish(state.x, lt, lw, sampler=self.name, config=self.get_config(),
                          seed=seed, **ev, **history.build_kwargs())
