"""Hand a posterior to ArviZ: :func:`to_arviz`."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import xarray as xr

from mrfpe._arviz import arviz
from mrfpe.posterior.diagnostics import chain_layout
from mrfpe.posterior.statistics import resample
from mrfpe.resampling import check_log_weights

__all__ = ["to_arviz"]


def _equal(log_weight: np.ndarray) -> bool:
    return bool(np.ptp(log_weight) <= 1e-12 * max(1.0, float(np.max(np.abs(log_weight)))))


def to_arviz(post: Any, *, resample_to_equal: bool = True, seed: int | None = 0):
    """Convert to ``arviz.InferenceData`` whose statistics honour the weights.

    ArviZ has no notion of importance weights: every draw counts equally. So by
    default (``resample_to_equal=True``) a weighted posterior is resampled to
    equal weights first — systematic resampling of ``S`` draws with ``seed``
    (:func:`mrfpe.posterior.resample`) — and ArviZ's means, quantiles, HDIs and
    plots then estimate the weighted posterior's. The copies of one sample sit
    next to each other, so ArviZ's own ESS on them is not the posterior's: use
    :func:`mrfpe.posterior.diagnose` (its results are in the copied ``diag_*``
    attributes). An equal-weight posterior is passed through unresampled.

    ``resample_to_equal=False`` exports the draws as they are; the weights are then
    only kept as the ``sample_stats`` variable ``log_weight`` (normalised) and
    ArviZ's statistics IGNORE them. The attribute ``mrfpe_weights`` of the
    ``posterior`` group says which of ``"equal"``, ``"resampled"`` or ``"ignored"``
    applies.

    Layout: ``theta(chain, draw, param)`` in ``posterior``, ``log_weight`` and
    ``lp`` (the target log density) in ``sample_stats``. A posterior with
    ``chain(sample)`` and equal weights (MCMC) gets one ArviZ chain per chain, in
    draw order; otherwise there is one chain. The MAP trace and the ESS per step
    go to an extra ``trace`` group, variables over neither ``sample`` nor ``step`` (a
    sampler's summaries, such as the ``hidden`` sampler's ``label_probability``) to an
    extra ``summary`` group; the attributes are copied.

    Raises
    ------
    ValueError
        If ``post`` is not a posterior Dataset or has zero total weight.
    """
    az = arviz()

    if not isinstance(post, xr.Dataset) or any(
            v not in post for v in ("theta", "log_weight", "log_target")):
        raise ValueError("post must be a posterior xarray.Dataset with theta, log_weight and "
                         f"log_target; got {type(post).__name__}")
    label = f"the posterior of {post.attrs.get('sampler', '?')}"
    check_log_weights(post["log_weight"].values, f"{label}: log_weight")
    equal = _equal(post["log_weight"].values)
    if equal:
        src, how = post, "equal"
    elif resample_to_equal:
        src, how = resample(post, seed=seed), "resampled"
    else:
        src, how = post, "ignored"
    if "chain" in src:
        layout, chains = chain_layout(src)
    else:
        layout, chains = np.arange(src.sizes["sample"])[None], np.array([0])
    coords = {"param": [str(p) for p in src["param"].values], "chain": chains,
              "draw": np.arange(layout.shape[1])}
    posterior = xr.Dataset({"theta": (("chain", "draw", "param"), src["theta"].values[layout])},
                           coords=coords, attrs={**src.attrs, "mrfpe_weights": how})
    stats = xr.Dataset({"log_weight": (("chain", "draw"), src["log_weight"].values[layout]),
                        "lp": (("chain", "draw"), src["log_target"].values[layout])},
                       coords={k: coords[k] for k in ("chain", "draw")})
    trace = src[["map_theta", "map_log_target", "ess"]]
    groups = {"posterior": posterior, "sample_stats": stats, "trace": trace}
    summary = [k for k, v in src.data_vars.items() if not {"sample", "step"} & set(v.dims)]
    if summary:  # a sampler's summaries (e.g. the hidden sampler's label probabilities)
        groups["summary"] = src[summary]
    with warnings.catch_warnings():  # arviz warns about the non-standard groups
        warnings.simplefilter("ignore", UserWarning)
        return az.InferenceData(**groups)
