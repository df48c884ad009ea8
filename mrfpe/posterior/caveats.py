"""What a posterior cannot say, whatever its Monte Carlo error: :func:`caveats`.

:func:`mrfpe.posterior.diagnose` judges how well a sample represents its *target*; a
sample can be reliable in that sense and still not be the posterior a user means:

* a **pseudo-posterior** -- the target declares itself a composite likelihood
  (``Target.calibrated = False``: Besag's pseudolikelihood, codings, blocks, the thesis's
  BRDF pseudolikelihoods), so ``exp(log_prob)``'s location and spread are not the
  Bayesian posterior's (on a 10 x 10 Ising lattice exp(PL) was up to 2 exact sds off and
  twice too wide: ``docs/results/calibrated_posteriors``);
* a posterior **cut by the box** -- its density at a face of the target's bounds is at
  least half the box's average density (the mass within :data:`FACE_WIDTH` of the range
  from the face, over that width): the flat prior's edge, not the data, bounds that
  parameter, and moving the bound moves the result (data all in one state put the Ising
  coupling's maximum likelihood at infinity), unless the bound is a physical limit (a
  reflectance of 0). A posterior well inside its box has almost no mass there.

Each caveat is one line naming what it concerns. :func:`mrfpe.posterior.build` stores
them in the attribute ``diag_caveats`` (one per line) and ``target_calibrated`` (1, 0, or
-1 when the target does not say); :func:`mrfpe.posterior.summary` prints them. They do
not change ``diag_reliable``, which keeps its meaning: the Monte Carlo estimate of the
target is trustworthy.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.posterior.statistics import weights

__all__ = ["FACE_DENSITY", "FACE_WIDTH", "calibration_flag", "caveats"]

#: A face cuts the posterior where its density there is this share of the box's average.
FACE_DENSITY = 0.5
#: The band next to a face over which that density is measured, a fraction of the range.
FACE_WIDTH = 0.02


def calibration_flag(target: Any) -> int:
    """``target.calibrated`` as netCDF stores it: 1 (True), 0 (False), -1 (not declared)."""
    flag = getattr(target, "calibrated", None)
    return -1 if flag is None else int(bool(flag))


def _bounds(post: xr.Dataset) -> np.ndarray | None:
    try:
        b = np.asarray(json.loads(post.attrs.get("target", "{}")).get("bounds"), float)
    except (TypeError, ValueError):
        return None
    return b if b.shape == (post.sizes["param"], 2) and np.all(np.isfinite(b)) else None


def _face_caveats(post: xr.Dataset) -> list[str]:
    bounds = _bounds(post)
    if bounds is None or post.attrs.get("kind", "draws") != "draws":
        return []
    theta, w = np.asarray(post["theta"].values, float), weights(post)
    out = []
    for j, name in enumerate(str(p) for p in post["param"].values):
        lo, hi = bounds[j]
        width = FACE_WIDTH * (hi - lo)
        for side, at, near in (("lower", lo, theta[:, j] <= lo + width),
                               ("upper", hi, theta[:, j] >= hi - width)):
            mass = float(w[near].sum())
            if mass >= FACE_DENSITY * FACE_WIDTH:
                out.append(f"cut by the box: {name}'s posterior density at its {side} bound "
                           f"{at:g} is {mass / FACE_WIDTH:.1f} x its average over the box "
                           f"({mass:.1%} of the mass within {FACE_WIDTH:.0%} of the range): the "
                           f"bound, not the data, limits {name} (unless {at:g} is a physical "
                           f"limit), and another bound would give another result")
    return out


def caveats(post: xr.Dataset) -> list[str]:
    """The caveats of a posterior Dataset (module docstring), one line each."""
    out = []
    if int(post.attrs.get("target_calibrated", -1)) == 0:
        out.append("pseudo-posterior: the target is a composite likelihood (a "
                   "pseudolikelihood), so this is exp(PL) normalised, not the Bayesian "
                   "posterior; its location and spread differ from the posterior's (for "
                   "that: the model's 'pl_adjusted' target, or exchange on 'likelihood')")
    return out + _face_caveats(post)
