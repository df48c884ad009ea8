"""Is a posterior's sample set good enough to trust? :func:`diagnose` and :class:`PosteriorWarning`.

Three published diagnostics, each computed by a well-known library (ensembles: below):

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
    Unreliable when ``rhat > RHAT_MAX`` (1.01) or not finite; ensembles are judged by τ.

*Ensembles* (``attrs["chain_type"] == "ensemble"``: walkers that move using each other,
as emcee's; a sampler opts in with ``KeptStates(..., ensemble=True)`` of
:mod:`mrfpe.samplers.kit`) are judged as Goodman & Weare (2010) and emcee's
documentation (Foreman-Mackey et al. 2013) judge them: by ``tau``, the ensemble's
integrated autocorrelation time in kept steps, the largest over the parameters
(:func:`ensemble_autocorr_time`). Short chains underestimate τ and emcee trusts it from
a chain of about 50 τ on: an ensemble is unreliable when its kept steps per walker are
fewer than :data:`ENSEMBLE_TAU_MULTIPLE` × τ, or τ cannot be estimated. Its ``ess`` is
``n_walkers × n_kept / max(τ, 1)`` (:func:`ensemble_ess`); ``ess_chain`` (ArviZ's, over
the walkers) and ``rhat`` (the split nested R̂ of Margossian et al. 2024,
:func:`nested_rhat`) are for comparison only: R̂ across the walkers of one ensemble is
inflated by about ``τ / (2n)`` (``n`` draws per walker) even when it is stationary.

A posterior of ``kind="optima"`` (the optima of a multi-start optimiser) is not a
posterior sample at all: :func:`diagnose` says so and marks it unreliable, and
:func:`mrfpe.posterior.build` does not warn about it (the kind is declared).
A posterior whose sampler declares a **known bias** (the attribute ``bias``, set by
``build(bias=...)``: e.g. SIR's ``weights="thesis"``, exact to the thesis but not
an importance sampler of the target) is unreliable whatever its ESS, and says why.

:func:`mrfpe.posterior.build` stores the result as the attributes
``diag_ess``, ``diag_ess_kish``, ``diag_ess_chain``, ``diag_pareto_k``, ``diag_rhat``
(floats, NaN where not applicable), ``diag_reliable`` (the integer 1 or 0: netCDF
has no boolean attribute, and the posterior should write with plain
``Dataset.to_netcdf``) and ``diag_messages`` (the reasons, one per line; empty
when reliable), see :data:`ATTRS` (an ensemble's τ is in :func:`diagnose`'s result
and in the reasons, not an attribute), and warns once with :class:`PosteriorWarning`
when a posterior of kind ``"draws"`` is unreliable.
"""

from __future__ import annotations

import json
import math
import warnings
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from mrfpe._arviz import arviz
from mrfpe._caller import stacklevel_outside_mrfpe
from mrfpe.resampling import check_log_weights, ess, normalise_log_weights

__all__ = [
    "ATTRS", "CHAIN_TYPES", "ENSEMBLE_SUPERCHAINS", "ENSEMBLE_TAU_MULTIPLE", "ESS_MIN", "KINDS",
    "PARETO_K_MAX", "RHAT_MAX", "PosteriorWarning", "chain_ess", "chain_layout", "diagnose",
    "diagnostics_attrs", "ensemble_autocorr_time", "ensemble_ess", "nested_rhat",
    "pareto_k_threshold", "stored_messages",
]

#: Smallest effective sample size a posterior's estimates are trusted at.
ESS_MIN = 100.0
#: Largest Pareto k̂ of the importance weights (Vehtari et al. 2024), for large S.
PARETO_K_MAX = 0.7
#: Largest rank-normalised split R̂ (Vehtari et al. 2021).
RHAT_MAX = 1.01
#: Superchains the walkers of an ensemble are grouped into for :func:`nested_rhat`.
ENSEMBLE_SUPERCHAINS = 4
#: How many τ an ensemble's kept chain must span: emcee's ``integrated_time(tol=50)``.
ENSEMBLE_TAU_MULTIPLE = 50.0
#: The values of the ``chain_type`` attribute (absent: independent chains).
CHAIN_TYPES = ("independent", "ensemble")
#: The values of the ``kind`` attribute.
KINDS = ("draws", "optima")
#: The attributes :func:`diagnostics_attrs` returns, and their types.
ATTRS: dict[str, type] = {
    "diag_ess": float, "diag_ess_kish": float, "diag_ess_chain": float,
    "diag_pareto_k": float, "diag_rhat": float, "diag_reliable": bool, "diag_messages": str,
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
    az = arviz()

    ess_min = math.inf
    with warnings.catch_warnings():  # ArviZ warns on short or constant chains; we report
        warnings.simplefilter("ignore")
        for j in range(x.shape[2]):
            xj = x[:, :, j]
            e = min(float(az.ess(xj, method="bulk")), float(az.ess(xj, method="tail")))
            ess_min = min(ess_min, e if np.isfinite(e) else 0.0)
    return ess_min


def nested_rhat(x: np.ndarray, n_superchains: int = ENSEMBLE_SUPERCHAINS) -> float:
    """Split nested R̂ (Margossian et al. 2024) of chains ``x`` (chain, draw, param),
    the largest over the parameters.

    Chain ``c`` goes to superchain ``c mod n_superchains``; every chain is split into
    halves, the first halves and the second halves forming separate superchains
    (2·``n_superchains`` in all), so that drift along the run counts as disagreement.
    ``R̂_ν = √(1 + B_ν / W_ν)``: ``B_ν`` the variance of the superchain means,
    ``W_ν`` the mean over superchains of the variance between their chains' means
    plus their chains' mean within-chain variance. NaN with fewer than
    2·``n_superchains`` chains or 4 draws per chain.
    """
    c, n = x.shape[:2]
    k = n_superchains
    if c < 2 * k or n < 4:
        return math.nan
    h = n // 2
    halves = np.concatenate([x[:, :h], x[:, n - h:]], axis=0)  # (2c, h, d)
    group = np.concatenate([np.arange(c) % k, k + np.arange(c) % k])
    mean_c = halves.mean(axis=1)                       # (2c, d)
    var_c = halves.var(axis=1, ddof=1)                 # (2c, d)
    sup = np.stack([mean_c[group == g].mean(axis=0) for g in range(2 * k)])
    between_in = np.stack([mean_c[group == g].var(axis=0, ddof=1) for g in range(2 * k)])
    within_in = np.stack([var_c[group == g].mean(axis=0) for g in range(2 * k)])
    b = sup.var(axis=0, ddof=1)
    w = (between_in + within_in).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(1.0 + b / w)
    r = np.where(np.isfinite(r), r, math.inf)
    return float(np.max(r))


def ensemble_autocorr_time(x: np.ndarray,
                           tol: float = ENSEMBLE_TAU_MULTIPLE) -> tuple[np.ndarray, bool]:
    """An ensemble's integrated autocorrelation time per parameter, and whether its chain
    is long enough to trust it.

    ``emcee.autocorr.integrated_time`` (Foreman-Mackey et al. 2013) on the draws as
    ``(draw, walker, param)``: each walker's normalised autocorrelation function,
    averaged over the walkers and summed up to Sokal's automatic window (``c = 5``) —
    as emcee's "Autocorrelation analysis" tutorial recommends, for the τ by which
    Goodman & Weare (2010) measure an ensemble. The verdict is emcee's: with ``tol`` and
    ``quiet=False`` it raises ``AutocorrError`` (carrying its estimate) when the chain is
    shorter than ``tol × τ``. A τ not positive and finite fails too: τ is NaN for a
    parameter in which a walker never moved (its autocorrelation is undefined).

    Parameters
    ----------
    x : (C, K, d) array — ``C`` walkers of ``K`` draws each, in draw order.
    tol : float — how many autocorrelation times the chain must be long (emcee's 50).

    Returns
    -------
    (tau, long_enough) : τ per parameter in draws (NaN where not estimable), and whether
        ``K >= tol × τ`` for every parameter, each τ positive and finite.
    """
    import emcee

    with np.errstate(divide="ignore", invalid="ignore"):  # a constant walker: 0/0
        try:
            tau = emcee.autocorr.integrated_time(np.swapaxes(x, 0, 1), tol=tol, quiet=False)
            short = False
        except emcee.autocorr.AutocorrError as exc:
            tau, short = exc.tau, True
    tau = np.asarray(tau, dtype=np.float64)
    tau[np.any(np.ptp(x, axis=1) == 0, axis=0)] = np.nan  # a walker that never moved
    return tau, not short and bool(np.all(np.isfinite(tau) & (tau > 0)))


def ensemble_ess(x: np.ndarray, tau: np.ndarray | None = None) -> float:
    """An ensemble's ESS ``n_walkers × n_draws / max(τ, 1)`` (``x`` (walker, draw, param);
    τ the largest :func:`ensemble_autocorr_time`, or of ``tau``, in kept draws; never more
    than the draws), NaN unless τ is positive and finite. Short chains underestimate τ,
    overstating the ESS: trust it from a chain of :data:`ENSEMBLE_TAU_MULTIPLE` τ on."""
    t = float(np.max(ensemble_autocorr_time(x)[0] if tau is None else tau))
    return x.shape[0] * x.shape[1] / max(t, 1.0) if math.isfinite(t) and t > 0 else math.nan


def _rhat(x: np.ndarray, ensemble: bool) -> float:
    """The worst R̂ of chains ``x`` (chain, draw, param): ArviZ's, NaN for one chain; for
    an ensemble of at least 2·:data:`ENSEMBLE_SUPERCHAINS` walkers :func:`nested_rhat`."""
    if ensemble and x.shape[0] >= 2 * ENSEMBLE_SUPERCHAINS:
        return nested_rhat(x)
    if x.shape[0] < 2:
        return math.nan
    az, rhat_max = arviz(), -math.inf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for j in range(x.shape[2]):
            r = float(az.rhat(x[:, :, j]))
            rhat_max = max(rhat_max, r if np.isfinite(r) else math.inf)
    return rhat_max


def _pareto_k(log_w: np.ndarray, reff: float) -> float:
    """PSIS k̂ (ArviZ) of the positive weights; NaN when they are all equal."""
    pos = log_w[np.isfinite(log_w)]
    if pos.size == 0 or np.ptp(pos) <= 1e-12 * max(1.0, float(np.max(np.abs(pos)))):
        return math.nan
    az = arviz()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, k = az.psislw(pos - np.max(pos), reff=min(max(reff, 1e-3), 1.0))
    return float(k)


class _Chains(NamedTuple):  # what the chains say (:func:`_chains`)
    n_chains: int = 0
    n_draws: int = 0  # per chain
    ess: float = math.nan  # the ESS of the draws, before Kish's efficiency
    ess_chain: float = math.nan  # ArviZ's, pooled over the chains
    rhat: float = math.nan
    tau: float = math.nan  # ensembles: the largest τ, in draws
    long_enough: bool = True  # ensembles: the chain is ENSEMBLE_TAU_MULTIPLE τ long


def _chains(post: xr.Dataset, theta: np.ndarray, ensemble: bool) -> _Chains:
    """ArviZ's ESS and R̂ of ``post``'s chains; an ensemble's τ and ESS C·K/τ too."""
    if "chain" not in post:
        return _Chains()
    layout, chains = chain_layout(post)
    x = theta[layout]  # (chain, draw, param)
    ess_chain, rhat = chain_ess(x), _rhat(x, ensemble)
    if not ensemble:
        return _Chains(int(chains.size), x.shape[1], ess_chain, ess_chain, rhat)
    taus, long_enough = ensemble_autocorr_time(x)
    e = ensemble_ess(x, taus)
    return _Chains(int(chains.size), x.shape[1], e if math.isfinite(e) else ess_chain,
                   ess_chain, rhat, float(np.max(taus)), long_enough)


class _Remedy:
    """What to change, named by the sampler's own options (from ``attrs["config"]``)
    where it has them, per family: weighted sets (more samples, a softer power, more
    iterations), chains (a longer chain, a longer burn-in, more chains or walkers)."""

    def __init__(self, post: xr.Dataset, n_chains: int, chain_type: str, ess_used: float):
        try:
            cfg = json.loads(post.attrs.get("config", "{}"))
        except (TypeError, ValueError):
            cfg = {}
        self.cfg = cfg if isinstance(cfg, dict) else {}
        self.chains, self.ensemble = n_chains > 0, chain_type == "ensemble"
        # ESS grows about linearly with the budget: the factor that reaches ESS_MIN, ≥ 2
        self.factor = int(min(max(2, math.ceil(1.2 * ESS_MIN / max(ess_used, 1.0))), 10))

    def _opt(self, name: str, factor: float | None = None) -> str | None:
        v = self.cfg.get(name)
        if isinstance(v, bool) or not isinstance(v, int | float):
            return None
        new = v * (self.factor if factor is None else factor)
        return f"{name}={v:g} → {new:g}" if isinstance(v, float) else f"{name}={v} → {int(new)}"

    def _first(self, *names: str, factor: float | None = None) -> str | None:
        return next((o for n in names if (o := self._opt(n, factor)) is not None), None)

    def _join(self, options: list[str | None], generic: str) -> str:
        named = [o for o in options if o]
        return " or ".join(named) if named else generic

    def ess(self) -> str:
        if self.chains:
            more = ("more walkers" if self.ensemble else "more chains")
            opts = [self._first("n_steps", "n_iterations"),
                    self._first("n_walkers" if self.ensemble else "n_chains", factor=2)]
            return ("a longer chain (" + self._join(opts[:1], "more steps") + ") or "
                    f"{more} (" + self._join(opts[1:], more) + ")")
        return self._more() + self._soften() + " or a proposal closer to the target"

    def tail(self) -> str:
        if self.chains:  # weighted chains (dynamic weighting): excursions dominate
            return ("the chains' weights are dominated by a few excursions: a longer chain ("
                    + self._join([self._first("n_steps")], "more steps")
                    + "), or an unweighted sampler (mh, emcee)")
        return self._more() + self._soften() + " or a wider proposal"

    def tau(self, c: _Chains) -> str:
        """Why an ensemble is too short for its τ; the chain that reaches 50 τ (estimated)."""
        m, n, tau = ENSEMBLE_TAU_MULTIPLE, c.n_draws, c.tau
        ok = math.isfinite(tau) and tau > 0
        o = self._first("n_steps", "n_iterations",
                        factor=max(2, math.ceil(m * tau / max(n, 1))) if ok else 2)
        fix = f"a longer chain ({o} at least)" if o else "run a longer chain"
        if not ok:
            return (f"the ensemble's integrated autocorrelation time cannot be estimated "
                    f"from its chain of {n} steps (a walker that never moved?); {fix}")
        return (f"chain of {n} steps is shorter than {m:g} × τ = {m * tau:.0f} (τ = "
                f"{tau:.1f} steps, the integrated autocorrelation time of the "
                f"{c.n_chains}-walker ensemble; steps kept after burn-in): too short to "
                f"trust τ or the ESS; {fix}")

    def rhat(self) -> str:
        opts = [self._first("n_steps", factor=4), self._first("burn_in", factor=4)]
        return "a longer chain with a longer burn-in (" + ", ".join(
            o for o in opts if o) + ")" if any(opts) else "run longer chains with a longer burn_in"

    def _more(self) -> str:
        o = self._first("n_samples", "n_particles")
        return "draw more samples" + (f" ({o})" if o else "")

    def _soften(self) -> str:
        p = self.cfg.get("power")
        if isinstance(p, int | float) and not isinstance(p, bool):
            return f", a softer power (power={p:g} → {p / 2:g})"
        if p == "auto":
            it = self._first("n_iterations", factor=2)
            return f", a slower annealing ({it})" if it else ", a slower annealing"
        return ", soften the target (a power < 1)" if not self.cfg else ""


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
        (NaN for fewer than two chains; an ensemble's nested R̂, reported only),
        ``tau`` (an ensemble's integrated autocorrelation time in kept steps, the
        largest over the parameters; NaN for other posteriors), ``reliable`` (bool)
        and ``messages`` (list of str: why not, and what to change).

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
    chain_type = post.attrs.get("chain_type", "independent")
    if chain_type not in CHAIN_TYPES:
        raise ValueError(f"post.attrs['chain_type'] must be one of {CHAIN_TYPES}; got "
                         f"{chain_type!r}")
    label = f"the posterior of {post.attrs.get('sampler', '?')!s}"
    lw = normalise_log_weights(check_log_weights(post["log_weight"].values,
                                                 f"{label}: log_weight"))
    theta = np.asarray(post["theta"].values, dtype=np.float64)
    S = theta.shape[0]
    ess_kish = ess(lw)
    ensemble = chain_type == "ensemble"
    c = _chains(post, theta, ensemble)
    ess_used = max(c.ess * ess_kish / S, 1.0) if c.n_chains else ess_kish
    reff = c.ess_chain / S if c.n_chains else 1.0
    k = _pareto_k(lw, reff)
    k_max = pareto_k_threshold(S)
    messages: list[str] = []
    if kind == "optima":
        messages.append("kind='optima': the sample set is the optima of a multi-start "
                        "optimiser, not draws from the posterior, so its weighted moments and "
                        "spread are not posterior estimates (use a sampler for those)")
    fix = _Remedy(post, c.n_chains, chain_type, ess_used)
    if post.attrs.get("bias"):  # the estimator itself is off, whatever the ESS says
        messages.append(f"known bias: {post.attrs['bias']}")
    if not ess_used >= ESS_MIN:
        messages.append(f"ESS {ess_used:.1f} < {ESS_MIN:g}: {fix.ess()}")
    if not (math.isnan(k) or k <= k_max):
        messages.append(f"Pareto k̂ {k:.2f} > {k_max:.2f} (S = {S}): a few weights dominate; "
                        f"{fix.tail()}")
    if ensemble and c.n_chains and not c.long_enough:  # judged by τ, not by R̂
        messages.append(fix.tau(c))
    elif not ensemble and c.n_chains >= 2 and not c.rhat <= RHAT_MAX:
        messages.append(f"R̂ {c.rhat:.3f} > {RHAT_MAX}: the chains disagree; {fix.rhat()}")
    return {"kind": kind, "n_samples": int(S), "n_chains": c.n_chains, "ess": float(ess_used),
            "ess_kish": float(ess_kish), "ess_chain": float(c.ess_chain), "pareto_k": float(k),
            "pareto_k_threshold": float(k_max), "rhat": float(c.rhat), "tau": float(c.tau),
            "reliable": not messages, "messages": messages}


def diagnostics_attrs(diag: dict[str, Any]) -> dict[str, Any]:
    """The ``diag_*`` attributes (:data:`ATTRS`) of a :func:`diagnose` result, in types
    netCDF stores: ``diag_reliable`` as 1 or 0, ``diag_messages`` one reason per line."""
    return {"diag_ess": diag["ess"], "diag_ess_kish": diag["ess_kish"],
            "diag_ess_chain": diag["ess_chain"], "diag_pareto_k": diag["pareto_k"],
            "diag_rhat": diag["rhat"], "diag_reliable": int(bool(diag["reliable"])),
            "diag_messages": "\n".join(diag["messages"])}


def stored_messages(post: xr.Dataset) -> list[str]:
    """The reasons a posterior was found unreliable, from its ``diag_messages`` attribute
    (one per line; a list in files written before the attribute became a string)."""
    m = post.attrs.get("diag_messages", "")
    return [str(x) for x in m] if isinstance(m, list | tuple) else str(m).splitlines()


def warn_if_unreliable(diag: dict[str, Any], sampler: str, stacklevel: int | None = None) -> None:
    """One :class:`PosteriorWarning` listing every reason, for an unreliable set of draws
    (pointing at the first caller outside mrfpe unless ``stacklevel`` is given)."""
    if diag["reliable"] or diag["kind"] == "optima":
        return
    warnings.warn(f"the posterior of {sampler} is unreliable: " + "; ".join(diag["messages"]),
                  PosteriorWarning,
                  stacklevel=stacklevel if stacklevel is not None else stacklevel_outside_mrfpe())
