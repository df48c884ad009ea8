"""The sampler author's kit: the helpers every built-in sampler uses, public for plugins.

A plugin sampler written with the kit looks exactly like a built-in one::

    from mrfpe.samplers import kit

    bounds = kit.check_target(target)       # validate the Target contract
    kit.check_seed(seed)
    run = kit.Run(target, n_steps, progress=progress, callback=callback)
    x = kit.grid(bounds, n)                 # or kit.draw_in_support(...)
    lw = run.evaluate(target, x)            # counted, NaN -> -inf
    idx = kit.resample(lw, n, "systematic", rng)
    history = kit.History(keep_history)     # optional per-step record
    for step in range(n_steps):
        ...
        history.record(x, lw)
        run.step(step, kit.ess(lw))          # MAP/ESS trace, progress bar, callback
    return run.finish(x, lt, lw, sampler=..., config=..., seed=seed,
                      **history.build_kwargs())

A complete weighted sampler on the kit is the worked example of
``docs/samplers.md`` (tested in CI as documentation). Everything here is
public and stable; plugins should import nothing else from mrfpe but
:mod:`mrfpe.samplers.base` (the optional :class:`~mrfpe.samplers.base.Sampler`
base class) and :mod:`mrfpe.posterior`.

Contents
--------
Run log
    :class:`Run` (evaluation counting, MAP trace, ESS trace, progress bar,
    callback, posterior assembly; :meth:`Run.finish` forwards any further
    :func:`mrfpe.posterior.build` keyword: the diagnostics hook).
Records
    :class:`History` (every step's weighted set, for ``keep_history``),
    :func:`start_chains` (an MCMC run's common opening: validation, the run log,
    starting states in the support and the kept-state record, a :class:`ChainStart`),
    :class:`KeptStates` (an MCMC run's post-burn-in, thinned states; its
    :meth:`~KeptStates.trace_ess` is the ``ess`` trace entry: ArviZ's chain ESS at
    :data:`ESS_CHECKPOINTS` evenly spaced kept steps, NaN elsewhere).
Validators
    :func:`check_target`, :func:`check_seed`, :func:`check_positive_int`,
    :func:`check_range`, :func:`check_choice`, :func:`check_bool`,
    :func:`check_chain_length`.
Random walks
    :func:`random_walk_proposal` (Gaussian proposals and which lie in the box),
    :func:`evaluate_inside` (the target at those only: the others are rejected
    without evaluation), :func:`in_box`, :func:`metropolis_accept` (the Metropolis
    rule), :class:`AdaptiveRandomWalk` (the proposal's scale and shape, adapted
    during burn-in only).
Starting points
    :func:`grid` (the thesis's evenly spaced set), :func:`space_filling`
    (scrambled Halton points, any dimension), :func:`draw_in_support`.
Jitter kernels
    :func:`jitter` (Gaussian truncated to the box), :func:`log_kernel_mass`
    (its normalisers), :func:`log_mixture_density`, :func:`log_resampling_mixture`
    (the density a jittered resample was drawn from), :func:`resampling_components`
    (that mixture's distinct ancestors and shares); for full-covariance kernels
    :func:`jitter_resampled` (out-of-box draws take a fresh ancestor, so the
    normaliser is global), :func:`log_mixture_density_chol`,
    :func:`covariance_kernel` (a kernel shaped like the weighted cloud) and
    :func:`jitter_mixture` (jitter and the mixture density in one call).

Evidence
    :func:`box_log_evidence` (``log_evidence`` relative to the box, the convention of
    every importance sampler), :func:`log_box_volume`, :func:`log_mixture_box_mass`
    (the box mass of an untruncated covariance mixture), :data:`MASS_DRAWS`.
Importance functions
    :func:`partition_or_none`, :func:`softened`, :data:`THESIS_POWER`,
    :data:`THESIS2_POWER`.
Weights and resampling
    :func:`resample`, :data:`RESAMPLING_METHODS`, :func:`ess`,
    :func:`normalise_log_weights`, :func:`log_ratio`, :func:`perplexity`.
Concurrent optimisations
    :func:`map_batched` (multi-start local optimisers whose inner loop asks for one
    point at a time: threads, one batched evaluation when all wait).
Compilation
    :func:`warm_target` (evaluate a target once, compiling its kernels, before a
    progress bar or a clock starts; :class:`Run` calls it when ``progress=True``).
"""

from __future__ import annotations

from mrfpe.mixture import log_mixture_density
from mrfpe.resampling import METHODS as RESAMPLING_METHODS
from mrfpe.resampling import ess, log_ratio, normalise_log_weights, perplexity, resample
from mrfpe.samplers.kit.batching import map_batched
from mrfpe.samplers.kit.chains import (
    ESS_CHECKPOINTS,
    ChainStart,
    KeptStates,
    check_chain_length,
    start_chains,
)
from mrfpe.samplers.kit.draws import (
    GRID_READINGS,
    draw_in_support,
    grid,
    grid_reading,
    space_filling,
)
from mrfpe.samplers.kit.evidence import (
    MASS_DRAWS,
    box_log_evidence,
    log_box_volume,
    log_mixture_box_mass,
)
from mrfpe.samplers.kit.history import History
from mrfpe.samplers.kit.importance import THESIS2_POWER, THESIS_POWER, partition_or_none, softened
from mrfpe.samplers.kit.jitter import (
    covariance_kernel,
    jitter,
    jitter_mixture,
    jitter_resampled,
    log_kernel_mass,
    log_mixture_density_chol,
    log_resampling_mixture,
    resampling_components,
)
from mrfpe.samplers.kit.random_walk import (
    AdaptiveRandomWalk,
    evaluate_inside,
    in_box,
    metropolis_accept,
    random_walk_proposal,
)
from mrfpe.samplers.kit.runlog import Run
from mrfpe.samplers.kit.warm import warm_target
from mrfpe.validation import (
    check_bool,
    check_choice,
    check_positive_int,
    check_range,
    check_seed,
    check_target,
)

__all__ = [
    "ESS_CHECKPOINTS",
    "GRID_READINGS",
    "MASS_DRAWS",
    "RESAMPLING_METHODS",
    "THESIS2_POWER",
    "THESIS_POWER",
    "AdaptiveRandomWalk",
    "ChainStart",
    "History",
    "KeptStates",
    "Run",
    "box_log_evidence",
    "check_bool",
    "check_chain_length",
    "check_choice",
    "check_positive_int",
    "check_range",
    "check_seed",
    "check_target",
    "covariance_kernel",
    "draw_in_support",
    "ess",
    "evaluate_inside",
    "grid",
    "grid_reading",
    "in_box",
    "jitter",
    "jitter_mixture",
    "jitter_resampled",
    "log_box_volume",
    "log_kernel_mass",
    "log_mixture_box_mass",
    "log_mixture_density",
    "log_mixture_density_chol",
    "log_ratio",
    "log_resampling_mixture",
    "map_batched",
    "metropolis_accept",
    "normalise_log_weights",
    "partition_or_none",
    "perplexity",
    "random_walk_proposal",
    "resample",
    "resampling_components",
    "softened",
    "space_filling",
    "start_chains",
    "warm_target",
]
