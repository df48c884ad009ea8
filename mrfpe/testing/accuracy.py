"""The accuracy checks: moments within ESS-derived tolerances, and stored diagnostics.

Neither can be declared away or loosened by a sampler's ``conformance`` dict
(:data:`mrfpe.testing.samplers.UNDECLARABLE`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe import posterior as _post
from mrfpe.testing._runs import _cached_run, _fail, _resolve
from mrfpe.testing.targets import CorrelatedGaussian

__all__ = ["CORR_MAX", "MEAN_MAX", "MOMENT_FLOOR", "MOMENT_Z", "SD_RATIO_BOUNDS",
           "check_diagnostics", "check_gaussian_moments", "moment_tolerances"]


#: Monte Carlo standard errors a moment may be off by (z) and a floor in units of the
#: true sd, for the ESS-derived tolerances of :func:`check_gaussian_moments`.
MOMENT_Z = 4.0
MOMENT_FLOOR = 0.05
#: Absolute bounds, whatever the ESS: |mean error| <= 0.25 sd, sd ratio in [0.85, 1.15],
#: |correlation error| <= 0.3.
MEAN_MAX = 0.25
SD_RATIO_BOUNDS = (0.85, 1.15)
CORR_MAX = 0.3


def moment_tolerances(ess: float, corr: np.ndarray, *, z: float = MOMENT_Z,
                      floor: float = MOMENT_FLOOR) -> tuple[float, float, np.ndarray]:
    """Tolerances of :func:`check_gaussian_moments` for a posterior of effective size ``ess``.

    A few Monte Carlo standard errors of a Gaussian's moment estimates from ``ess``
    independent draws, plus ``floor``, capped by the absolute bounds:

    - mean error (in sd): ``min(z / √ESS + floor, MEAN_MAX)``;
    - sd ratio: ``|ratio - 1| <= min(z / √(2 ESS) + floor, 0.15)``;
    - correlation: ``|r - ρ| <= min(z (1 - ρ²) / √ESS + floor, CORR_MAX)``.

    Returns ``(mean_tol, sd_tol, corr_tol)``.
    """
    e = max(float(ess), 1.0) if np.isfinite(ess) else 1.0
    mean_tol = min(z / np.sqrt(e) + floor, MEAN_MAX)
    sd_tol = min(z / np.sqrt(2 * e) + floor, SD_RATIO_BOUNDS[1] - 1, 1 - SD_RATIO_BOUNDS[0])
    corr_tol = np.minimum(z * (1 - corr**2) / np.sqrt(e) + floor, CORR_MAX)
    return float(mean_tol), float(sd_tol), corr_tol


def check_gaussian_moments(sampler: Any, config: dict | None = None, *, z: float = MOMENT_Z,
                           floor: float = MOMENT_FLOOR) -> str | None:
    """On :class:`CorrelatedGaussian` the weighted mean, sd and correlations are accurate.

    The tolerances (:func:`moment_tolerances`) follow from the posterior's own
    effective sample size (:func:`mrfpe.posterior.diagnose`): a sampler that
    claims a large ESS must be correspondingly accurate, and whatever it claims
    the mean must lie within 0.25 sd of the truth and each sd within 0.85–1.15
    times the true one. ``z`` and ``floor`` may be changed by a direct call
    only; a ``conformance`` declaration can neither loosen nor skip this check.

    Returns ``"optima"`` (not applicable) for a posterior of ``kind="optima"``,
    the only way to be exempt: a multi-start optimiser's optima do not sample
    the moments.
    """
    cls, name = _resolve(sampler)
    post = _cached_run(cls, config, CorrelatedGaussian, 0)
    if post.attrs.get("kind", "draws") == "optima":
        return "optima (kind='optima': not a posterior sample)"
    t = CorrelatedGaussian()
    ess = _post.diagnose(post)["ess"]
    mean_tol, sd_tol, corr_tol = moment_tolerances(ess, t.corr, z=z, floor=floor)
    where = f"(ESS {ess:.0f}: tolerances mean {mean_tol:.3f} sd, sd ratio 1 ± {sd_tol:.3f})"
    m, c = _post.weighted_mean(post), _post.weighted_cov(post)
    err = np.abs(m - t.mean) / t.sd
    if np.any(err > mean_tol):
        raise _fail(name, "check_gaussian_moments", f"weighted mean {m.round(4)} vs true "
                    f"{t.mean}: errors {err.round(2)} sd > {mean_tol:.3f} sd {where}")
    sd = np.sqrt(np.clip(np.diag(c), 0, None))
    ratio = sd / t.sd
    if np.any(np.abs(ratio - 1) > sd_tol):
        raise _fail(name, "check_gaussian_moments", f"weighted sd {sd.round(4)} vs true "
                    f"{t.sd}: ratios {ratio.round(3)} outside 1 ± {sd_tol:.3f} {where}")
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = c / np.outer(sd, sd)
    if not np.all(np.abs(corr - t.corr) <= corr_tol):
        raise _fail(name, "check_gaussian_moments", f"weighted correlation\n{corr.round(2)}\n"
                    f"vs true\n{t.corr}\ndiffers by more than\n{corr_tol.round(3)} {where}")
    return None


def check_diagnostics(sampler: Any, config: dict | None = None) -> None:
    """The posterior carries its diagnostics: ``kind`` and the ``diag_*`` attributes of
    :func:`mrfpe.posterior.diagnose`, of the right types and equal to a fresh
    diagnosis, and an unreliable set of draws says why (``diag_messages``). An MCMC
    sampler's ``chain(sample)``, if present, has at least one chain per label."""
    cls, name = _resolve(sampler)
    from mrfpe.posterior.diagnostics import ATTRS, KINDS, diagnostics_attrs

    post = _cached_run(cls, config, CorrelatedGaussian, 0)
    kind = post.attrs.get("kind")
    if kind not in KINDS:
        raise _fail(name, "check_diagnostics", f"attrs['kind'] = {kind!r}, not one of {KINDS}")
    missing = [k for k in ATTRS if k not in post.attrs]
    if missing:
        raise _fail(name, "check_diagnostics", f"posterior lacks the attributes {missing}; "
                    "build it with mrfpe.posterior.build")
    try:
        fresh = diagnostics_attrs(_post.diagnose(post))
    except ValueError as exc:
        raise _fail(name, "check_diagnostics", f"diagnose raised: {exc}") from exc
    for k, v in fresh.items():
        got = post.attrs[k]
        same = (got == v if not isinstance(v, float) else
                (np.isnan(v) and isinstance(got, float) and np.isnan(got))
                or np.isclose(got, v, rtol=1e-9, atol=0))
        if not same:
            raise _fail(name, "check_diagnostics", f"attrs[{k!r}] = {got!r} but diagnose "
                        f"gives {v!r}")
    if not post.attrs["diag_reliable"] and not post.attrs["diag_messages"]:
        raise _fail(name, "check_diagnostics", "unreliable without a message saying why")
