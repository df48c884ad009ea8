"""The posterior Dataset every sampler returns (DESIGN.md, "Posterior").

Schema
------
Dims ``sample``, ``param``, ``step``.

Variables: ``theta(sample, param)`` (float64, finite), ``log_weight(sample)``
(normalised: logsumexp = 0; at least one finite), ``log_target(sample)``,
``map_theta(step, param)``, ``map_log_target(step)`` (best so far), ``ess(step)``
(weighted sets: Kish, per step; MCMC: ArviZ's chain ESS of the states kept so far
at :data:`~mrfpe.samplers.kit.ESS_CHECKPOINTS` checkpoints, NaN elsewhere);
optional ``history_theta(step, sample, param)``,
``history_log_weight(step, sample)`` and ``chain(sample)`` (int64 chain label of
each sample, for MCMC: equal-length chains, draw order kept within a chain).

Attributes: ``sampler``, ``config`` (JSON), ``seed`` (−1 for None), ``target``
(JSON), ``mrfpe_version``, ``n_target_evals``, ``wall_time_s``; ``kind``
(``"draws"``, a sample of the posterior, or ``"optima"``, the optima of a
multi-start optimiser); optional ``chain_type`` (``"ensemble"`` for interacting
walkers, judged by the ensemble's integrated autocorrelation time τ: reliable once
the kept chain spans 50 τ; absent: independent chains); the diagnostics of
:func:`diagnose` as ``diag_ess``,
``diag_ess_kish``, ``diag_ess_chain``, ``diag_pareto_k``, ``diag_rhat`` (floats, NaN
where not applicable), ``diag_reliable`` (1 or 0) and ``diag_messages`` (the reasons,
one per line); ``target_calibrated`` (1: the target is a likelihood, 0: a composite
likelihood, so the result is a pseudo-posterior; -1: not declared) and
``diag_caveats`` (:func:`caveats`: what the result cannot say whatever its Monte Carlo
error -- a pseudo-posterior, a parameter held by a face of the box -- one per line;
they do not change ``diag_reliable``); every attribute is of a type netCDF stores, so a
posterior writes with plain ``Dataset.to_netcdf`` and reads back with ``xarray.open_dataset``
(:func:`save`/:func:`load` keep exact types and NaN as well); optional
``log_evidence`` and ``log_evidence_se`` (floats): the log normaliser
of the target *relative to the box*, ``log(∫_box p / vol(box))`` (the evidence under
the uniform prior on the bounds; :mod:`mrfpe.samplers.kit.evidence`), absent where
a sampler defines none; for a pseudolikelihood target the normaliser of the
pseudolikelihood, not a model evidence.

Reliability thresholds (:mod:`mrfpe.posterior.diagnostics`): ESS ≥ 100, Pareto
k̂ ≤ min(1 − 1/log10 S, 0.7) (Vehtari et al. 2024), R̂ ≤ 1.01 with several chains
(Vehtari et al. 2021); :func:`build` warns once with :class:`PosteriorWarning`
when a set of draws fails one.

Modules
-------
:mod:`~mrfpe.posterior.schema` (:func:`build`, :func:`validate`),
:mod:`~mrfpe.posterior.diagnostics` (:func:`diagnose`, :class:`PosteriorWarning`),
:mod:`~mrfpe.posterior.caveats` (:func:`caveats`),
:mod:`~mrfpe.posterior.statistics` (:func:`weights`, :func:`weighted_mean`,
:func:`weighted_cov`, :func:`weighted_quantiles`, :func:`map_estimate`,
:func:`resample`), :mod:`~mrfpe.posterior.io` (exact netCDF :func:`save` /
:func:`load`), :mod:`~mrfpe.posterior.report` (:func:`summary`) and
:mod:`~mrfpe.posterior.arviz` (:func:`to_arviz`). Kish's :func:`ess`,
:func:`perplexity`, :func:`normalise_log_weights` and :func:`log_evidence` come
from the leaf module :mod:`mrfpe.resampling`. Everything is re-exported here.
"""

from __future__ import annotations

from mrfpe.posterior.arviz import to_arviz
from mrfpe.posterior.caveats import caveats
from mrfpe.posterior.diagnostics import PosteriorWarning, diagnose, stored_messages
from mrfpe.posterior.io import load, save
from mrfpe.posterior.report import summary
from mrfpe.posterior.schema import build, validate
from mrfpe.posterior.statistics import (
    map_estimate,
    resample,
    weighted_cov,
    weighted_mean,
    weighted_quantiles,
    weights,
)
from mrfpe.resampling import ess, log_evidence, normalise_log_weights, perplexity

__all__ = [
    "PosteriorWarning", "build", "caveats", "diagnose", "ess", "load", "log_evidence",
    "map_estimate", "normalise_log_weights", "perplexity", "resample", "save",
    "stored_messages", "summary", "to_arviz",
    "validate", "weighted_cov", "weighted_mean", "weighted_quantiles", "weights",
]
