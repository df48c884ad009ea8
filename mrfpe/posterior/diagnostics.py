"""Is a posterior's sample set good enough to trust? :func:`diagnose` and :class:`PosteriorWarning`.

Three published diagnostics, each computed by a well-known library:

``ess`` — effective sample size.
    Weighted sets without chains: Kish's ``1 / Σ w̃²`` (:func:`mrfpe.resampling.ess`).
    Chains (the posterior has ``chain(sample)``): ArviZ's rank-normalised bulk and
    tail ESS (Vehtari et al. 2021), pooled over the chains, the smaller of the two
    for the worst parameter. Weighted chains (dynamic weighting): the chain ESS
    times Kish's efficiency ``ESS_kish / S`` (an approximation: the two losses
    multiply), and at least 1. A posterior whose samples are autocorrelated but that carries no
    ``chain`` is taken at its Kish ESS, which assumes independent draws: MCMC
    samplers must pass ``chain`` to :func:`mrfpe.posterior.build`.
    Unreliable when ``ess < ESS_MIN`` (100).
``pareto_k`` — the Pareto k̂ of the importance weights (PSIS, Vehtari et al. 2024,
    ``arviz.psislw`` on the positive weights). NaN when the positive weights are all
    equal (no tail to fit); ``inf`` when there are too few samples to fit one.
    Unreliable when ``k̂ > min(1 - 1/log10(S), 0.7)`` (the paper's sample-size-
    dependent threshold; 0.7 from S ≈ 2150 on).
``rhat`` — ArviZ's rank-normalised split R̂ (Vehtari et al. 2021), the largest over the
    parameters, when there are at least two chains; NaN otherwise.
    Unreliable when ``rhat > RHAT_MAX`` (1.01) or not finite.

A posterior of ``kind="optima"`` (the optima of a multi-start optimiser) is not a
posterior sample at all: :func:`diagnose` says so and marks it unreliable, and
:func:`mrfpe.posterior.build` does not warn about it (the kind is declared).

:func:`mrfpe.posterior.build` stores the result as the attributes
``diag_ess``, ``diag_ess_kish``, ``diag_ess_chain``, ``diag_pareto_k``, ``diag_rhat``
(floats, NaN where not applicable), ``diag_reliable`` (bool) and ``diag_messages``
(list of str), see :data:`ATTRS`, and warns once with :class:`PosteriorWarning`
when a posterior of kind ``"draws"`` is unreliable.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.resampling import check_log_weights, ess, normalise_log_weights

__all__ = ["ATTRS", "ESS_MIN", "KINDS", "PARETO_K_MAX", "RHAT_MAX", "PosteriorWarning",
           "chain_ess", "chain_layout", "diagnose", "diagnostics_attrs", "pareto_k_threshold"]

#: Smallest effective sample size a posterior's estimates are trusted at.
ESS_MIN = 100.0
#: Largest Pareto k̂ of the importance weights (Vehtari et al. 2024), for large S.
PARETO_K_MAX = 0.7
#: Largest rank-normalised split R̂ (Vehtari et al. 2021).
RHAT_MAX = 1.01
#: The values of the ``kind`` attribute.
KINDS = ("draws", "optima")
#: The attributes :func:`diagnostics_attrs` returns, and their types.
ATTRS: dict[str, type] = {
    "diag_ess": float, "diag_ess_kish": float, "diag_ess_chain": float,
    "diag_pareto_k": float, "diag_rhat": float, "diag_reliable": bool, "diag_messages": list,
}


class PosteriorWarning(UserWarning):
    """A posterior's diagnostics say its estimates are unreliable (see :func:`diagnose`)."""


def pareto_k_threshold(n_samples: int) -> float:
    """The k̂ threshold ``min(1 - 1/log10(S), 0.7)`` of Vehtari et al. (2024)."""
    if n_samples <= 10:
        return 0.0
    return min(1.0 - 1.0 / math.log10(n_samples), PARETO_K_MAX)


def chain_layout(post: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices arranged as (chain, draw), and the chain labels.

    Draws keep their order within each chain (the order of ``sample``).

    Raises
    ------
    ValueError
        If ``post`` has no ``chain`` variable or its chains differ in length.
    """
    if "chain" not in post:
        raise ValueError("the posterior has no chain variable")
    labels = np.asarray(post["chain"].values)
    chains, counts = np.unique(labels, return_counts=True)
    if np.any(counts != counts[0]):
        raise ValueError(f"chain must label chains of equal length; got lengths "
                         f"{dict(zip(chains.tolist(), counts.tolist()))}")
    order = np.argsort(labels, kind="stable")
    return order.reshape(chains.size, counts[0]), chains


def chain_ess(x: np.ndarray) -> float:
    """ArviZ's rank-normalised bulk and tail ESS of chains ``x`` (chain, draw, param),
    pooled over the chains: the smaller of the two for the worst parameter (0 where
    ArviZ gives no finite value). What :func:`diagnose` reports as ``ess_chain``, and
    what the MCMC samplers' ``ess`` trace holds at its checkpoints."""
    import arviz as az

    ess_min = math.inf
    with warnings.catch_warnings():  # ArviZ warns on short or constant chains; we report
        warnings.simplefilter("ignore")
        for j in range(x.shape[2]):
            xj = x[:, :, j]
            e = min(float(az.ess(xj, method="bulk")), float(az.ess(xj, method="tail")))
            ess_min = min(ess_min, e if np.isfinite(e) else 0.0)
    return ess_min


def _chain_stats(theta: np.ndarray, layout: np.ndarray) -> tuple[float, float]:
    """(worst bulk/tail ESS over parameters, worst R̂ or NaN for one chain) from ArviZ."""
    import arviz as az

    x = theta[layout]  # (chain, draw, param)
    rhat_max = -math.inf
    if x.shape[0] >= 2:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for j in range(x.shape[2]):
                r = float(az.rhat(x[:, :, j]))
                rhat_max = max(rhat_max, r if np.isfinite(r) else math.inf)
    return chain_ess(x), (rhat_max if x.shape[0] >= 2 else math.nan)


def _pareto_k(log_w: np.ndarray, reff: float) -> float:
    """PSIS k̂ (ArviZ) of the positive weights; NaN when they are all equal."""
    pos = log_w[np.isfinite(log_w)]
    if pos.size == 0 or np.ptp(pos) <= 1e-12 * max(1.0, float(np.max(np.abs(pos)))):
        return math.nan
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, k = az.psislw(pos - np.max(pos), reff=min(max(reff, 1e-3), 1.0))
    return float(k)


def diagnose(post: Any) -> dict[str, Any]:
    """How far to trust a posterior's estimates (thresholds in the module docstring).

    Parameters
    ----------
    post : a posterior Dataset (``theta(sample, param)``, ``log_weight(sample)``,
        optionally ``chain(sample)`` and the attribute ``kind``).

    Returns
    -------
    dict with
        ``kind`` (``"draws"`` or ``"optima"``), ``n_samples``, ``n_chains`` (0 when
        the posterior has no ``chain``), ``ess`` (the ESS the verdict uses),
        ``ess_kish``, ``ess_chain`` (ArviZ bulk/tail ESS, NaN without chains),
        ``pareto_k`` (NaN for equal weights), ``pareto_k_threshold``, ``rhat``
        (NaN for fewer than two chains), ``reliable`` (bool) and ``messages``
        (list of str: why not, and what to change).

    Raises
    ------
    ValueError
        If ``post`` is not a posterior Dataset, its weights are degenerate (all
        ``-inf``/NaN), its ``kind`` is unknown or its chains differ in length.
    """
    if not isinstance(post, xr.Dataset) or "theta" not in post or "log_weight" not in post:
        raise ValueError("post must be a posterior xarray.Dataset with theta(sample, param) "
                         f"and log_weight(sample); got {type(post).__name__}")
    kind = post.attrs.get("kind", "draws")
    if kind not in KINDS:
        raise ValueError(f"post.attrs['kind'] must be one of {KINDS}; got {kind!r}")
    label = f"the posterior of {post.attrs.get('sampler', '?')!s}"
    lw = normalise_log_weights(check_log_weights(post["log_weight"].values,
                                                 f"{label}: log_weight"))
    theta = np.asarray(post["theta"].values, dtype=np.float64)
    S = theta.shape[0]
    ess_kish = ess(lw)
    n_chains, ess_chain, rhat = 0, math.nan, math.nan
    if "chain" in post:
        layout, chains = chain_layout(post)
        n_chains = int(chains.size)
        ess_chain, rhat = _chain_stats(theta, layout)
        ess_used = max(ess_chain * ess_kish / S, 1.0)
    else:
        ess_used = ess_kish
    reff = ess_chain / S if n_chains else 1.0
    k = _pareto_k(lw, reff)
    k_max = pareto_k_threshold(S)
    messages: list[str] = []
    if kind == "optima":
        messages.append("kind='optima': the sample set is the optima of a multi-start "
                        "optimiser, not draws from the posterior, so its weighted moments and "
                        "spread are not posterior estimates (use a sampler for those)")
    if not ess_used >= ESS_MIN:
        how = ("run longer chains (more n_steps) or more chains" if n_chains else
               "draw more samples, soften the target (a power < 1) or use a proposal "
               "closer to the target")
        messages.append(f"ESS {ess_used:.1f} < {ESS_MIN:g}: {how}")
    if not (math.isnan(k) or k <= k_max):
        messages.append(f"Pareto k̂ {k:.2f} > {k_max:.2f} (S = {S}): a few weights dominate; "
                        "soften the target (a power < 1), widen the proposal or draw more "
                        "samples")
    if n_chains >= 2 and not rhat <= RHAT_MAX:
        messages.append(f"R̂ {rhat:.3f} > {RHAT_MAX}: the chains disagree; run longer chains "
                        "with a longer burn_in")
    return {"kind": kind, "n_samples": int(S), "n_chains": n_chains, "ess": float(ess_used),
            "ess_kish": float(ess_kish), "ess_chain": float(ess_chain), "pareto_k": float(k),
            "pareto_k_threshold": float(k_max), "rhat": float(rhat),
            "reliable": not messages, "messages": messages}


def diagnostics_attrs(diag: dict[str, Any]) -> dict[str, Any]:
    """The ``diag_*`` attributes (:data:`ATTRS`) of a :func:`diagnose` result."""
    return {"diag_ess": diag["ess"], "diag_ess_kish": diag["ess_kish"],
            "diag_ess_chain": diag["ess_chain"], "diag_pareto_k": diag["pareto_k"],
            "diag_rhat": diag["rhat"], "diag_reliable": bool(diag["reliable"]),
            "diag_messages": list(diag["messages"])}


def warn_if_unreliable(diag: dict[str, Any], sampler: str, stacklevel: int = 3) -> None:
    """One :class:`PosteriorWarning` listing every reason, for an unreliable set of draws."""
    if diag["reliable"] or diag["kind"] == "optima":
        return
    warnings.warn(f"the posterior of {sampler} is unreliable: " + "; ".join(diag["messages"]),
                  PosteriorWarning, stacklevel=stacklevel)
