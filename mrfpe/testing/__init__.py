"""Conformance checks shipped for plugin authors (like scikit-learn's ``check_estimator``).

- :mod:`mrfpe.testing.samplers`: :func:`check_sampler`, :func:`run_check` and the checks;
- :mod:`mrfpe.testing.accuracy`: the two checks no declaration can skip or loosen
  (:func:`check_gaussian_moments` with ESS-derived tolerances, :func:`check_diagnostics`);
- :mod:`mrfpe.testing.targets`: the analytic targets they run on;
- :mod:`mrfpe.testing.model_checks`: :func:`check_model` for declared models;
- :mod:`mrfpe.testing.emission_checks`: :func:`check_emission` for emissions of hidden MRFs.

Everything is re-exported here, so ``from mrfpe.testing import check_sampler`` works.
"""

from __future__ import annotations

from mrfpe.testing.emission_checks import EMISSION_CHECKS, check_emission
from mrfpe.testing.model_checks import check_model
from mrfpe.testing.samplers import (
    CHECKS,
    check_bounds,
    check_callback,
    check_config,
    check_diagnostics,
    check_gaussian_moments,
    check_interface,
    check_map_trace,
    check_mostly_minus_inf,
    check_netcdf_roundtrip,
    check_reproducible,
    check_sampler,
    check_schema,
    check_two_modes,
    moment_tolerances,
    run_check,
)
from mrfpe.testing.targets import (
    BoxGaussian,
    CorrelatedGaussian,
    MostlyMinusInf,
    TwoModes,
    box_gaussian,
)

__all__ = [
    "CHECKS",
    "EMISSION_CHECKS",
    "BoxGaussian",
    "CorrelatedGaussian",
    "MostlyMinusInf",
    "TwoModes",
    "box_gaussian",
    "check_bounds",
    "check_callback",
    "check_config",
    "check_diagnostics",
    "check_emission",
    "check_gaussian_moments",
    "check_interface",
    "check_map_trace",
    "check_model",
    "check_mostly_minus_inf",
    "check_netcdf_roundtrip",
    "check_reproducible",
    "check_sampler",
    "check_schema",
    "check_two_modes",
    "moment_tolerances",
    "run_check",
]

# Target and distance conformance checks (mrfpe.testing.target_checks, .distance_checks).
from mrfpe.testing.distance_checks import DISTANCE_CHECKS, check_distance
from mrfpe.testing.target_checks import TARGET_CHECKS, check_target

__all__ += ["DISTANCE_CHECKS", "TARGET_CHECKS", "check_distance", "check_target"]
