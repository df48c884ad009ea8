"""The ``hidden`` sampler: the posterior of a hidden MRF's parameters and labels.

On a :class:`~mrfpe.models.hidden.target.HiddenTarget` (``hm.target("hidden", y, ...)``)
it runs ``n_chains`` chains that alternate the labels, the emission's parameters and
the MRF's parameters (:mod:`mrfpe.samplers.hidden_steps`), started from mean-field EM
(``init="em"``), ICM or the emission's classification of the data
(:mod:`mrfpe.models.hidden.point`). The posterior holds

* ``theta``: the kept draws of every free parameter (MRF and emission), in chains;
* ``label_probability`` (node dims × ``state``): the posterior marginals of the labels,
  Rao-Blackwellised, with ``label_probability_mcse`` (batch means,
  :mod:`mrfpe.samplers.hidden_labels`), ``label_mode`` (the marginal-posterior-mode
  labelling) and ``label_uncertainty``;
* ``param_rhat`` and ``param_ess`` (per parameter), ``state_occupancy`` and
  ``state_empty_fraction`` (per state), ``mrf_acceptance`` and ``emission_acceptance``
  (per step);
* the attributes ``label_mcse_max`` and ``priors`` (JSON: every prior, stated).

The target's ``method`` says how the MRF's parameters are drawn given the labels
(:mod:`mrfpe.samplers.hidden_theta`). With ``"pl"`` they are drawn from ``exp(PL)`` of the
labels, which makes the result a *pseudo-posterior*: its diagnostics say so (the
``bias`` attribute, which marks it unreliable as an estimate of the posterior).
``"exchange"`` is flagged when its auxiliary chains were shorter than ``mixing_factor``
autocorrelation times at the posterior mean, ``"surrogate"`` when the surrogate's
validated mean error exceeds its tolerance. States empty in most sweeps (the data
support fewer states) and label probabilities with a Monte Carlo error above
``LABEL_MCSE_MAX`` are flagged the same way, with the reason.

On any other target -- one with no hidden labels -- the parameters are the only block and
the sampler is random-walk Metropolis (as ``mh``, adapted during burn-in only).
"""

from __future__ import annotations

import json
from typing import Any, ClassVar

import numpy as np

from mrfpe.budget import check_memory
from mrfpe.models.hidden.labels import label_variables
from mrfpe.models.hidden.point import PointEstimate, em_estimate, icm_estimate, start_point
from mrfpe.models.hidden.target import HiddenTarget
from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int
from mrfpe.samplers.hidden_labels import LabelRecord, param_diagnostics
from mrfpe.samplers.hidden_steps import hidden_step, make_walks, start_state
from mrfpe.samplers.hidden_theta import ThetaUpdate, make_theta_update
from mrfpe.samplers.kit import (
    AdaptiveRandomWalk,
    KeptStates,
    Run,
    check_chain_length,
    check_seed,
)
from mrfpe.samplers.mh import run_random_walk

__all__ = ["LABEL_MCSE_MAX", "HiddenSampler"]

#: Largest Monte Carlo standard error of a label probability a reliable result may have.
LABEL_MCSE_MAX = 0.05
#: Share of the sweeps in which a state may be empty before the result says the data
#: support fewer states.
EMPTY_STATE_MAX = 0.5
LABEL_KERNELS = ("gibbs", "swendsen_wang")
INITS = ("em", "icm", "classify")


class HiddenSampler(Sampler):
    """Labels, emission and MRF parameters of a hidden MRF, in turn (module docstring).

    Parameters
    ----------
    n_steps, n_chains, burn_in, thin
        Steps (one sweep of every block) per chain, burn-in included; chains; leading
        steps discarded; keep every ``thin``-th draw of the parameters (the label
        probabilities use every post-burn-in sweep).
    theta_steps : int
        Random-walk Metropolis steps of each non-conjugate parameter block per sweep.
    proposal_sd, adapt, target_acceptance
        The random walks' (:class:`~mrfpe.samplers.kit.AdaptiveRandomWalk`).
    labels : ``"gibbs"`` | ``"swendsen_wang"``
        Chequerboard Gibbs sweeps with the data term, or a Swendsen-Wang sweep with the
        data as external field (Higdon 1998) before each (ferromagnetic Potts-form pair
        tables only; it helps at strong coupling).
    init : ``"em"`` | ``"icm"`` | ``"classify"``
        The point the chains start from: mean-field EM, ICM, or the emission's
        classification of the data with the MRF's parameters at 0.
    n_batches : int
        Batches per chain of the label probabilities' Monte Carlo error.
    aux_sweeps : "auto" | int
        ``method="exchange"``: sweeps of the auxiliary chain per proposal, started from
        the chain's labels; ``"auto"``: ``10 τ`` of the MRF's simulator at the start point,
        measured again at the chains' mean at the end of burn-in (at least 10, at most
        ``max_aux_sweeps``).
    max_aux_sweeps : int
        Cap of the automatic choice.
    """

    name = "hidden"
    conformance: ClassVar[dict] = {"quick_config": {"n_steps": 1000, "burn_in": 250}}

    def __init__(self, n_steps: int = 3000, n_chains: int = 4, burn_in: int = 1000,
                 thin: int = 1, theta_steps: int = 3, proposal_sd: float = 0.05,
                 adapt: bool = True, target_acceptance: float = 0.3, labels: str = "gibbs",
                 init: str = "em", n_batches: int = 20, aux_sweeps: int | str = "auto",
                 max_aux_sweeps: int = 2000):
        self.n_steps, self.burn_in, self.thin = check_chain_length(n_steps, burn_in, thin)
        self.n_chains = check_positive_int("n_chains", n_chains)
        self.theta_steps = check_positive_int("theta_steps", theta_steps)
        self.proposal_sd, self.adapt, self.target_acceptance = AdaptiveRandomWalk.check_options(
            proposal_sd, adapt, target_acceptance)
        self.labels = check_choice("labels", labels, LABEL_KERNELS)
        self.init = check_choice("init", init, INITS)
        self.n_batches = check_positive_int("n_batches", n_batches, minimum=2)
        if aux_sweeps != "auto":
            aux_sweeps = check_positive_int("aux_sweeps", aux_sweeps)
        self.aux_sweeps = aux_sweeps
        self.max_aux_sweeps = check_positive_int("max_aux_sweeps", max_aux_sweeps)

    def run(self, target: Any, *, seed: int | None = None, progress: bool = False,
            callback: Callback | None = None):
        """Sample the posterior of ``target``; return the posterior Dataset."""
        if not isinstance(target, HiddenTarget):
            return self._run_plain(target, seed, progress, callback)
        check_seed(seed)
        n, C = self.n_steps, self.n_chains
        check_memory(8.0 * (C + 3) * target.n_nodes * target.q + 8.0 * C * target.n_nodes,
                     f"sampler hidden holding the label probabilities of {C} chains of "
                     f"{target.n_nodes} nodes and {target.q} states", "use fewer chains")
        rng = np.random.default_rng(seed)
        run = Run(target, n, progress=progress, callback=callback, desc=self.name,
                  rows=n + C * (n // self.thin + 4))
        point = self._start(target)
        self._check_kernel(target, point)
        state = start_state(target, point, C, rng)
        update = make_theta_update(target, aux_sweeps=self.aux_sweeps,
                                   max_aux_sweeps=self.max_aux_sweeps)
        mrf_free = bool(target.free[: target.n_mrf].any())
        prepare_at, prepare_seed = update.prepare_at(self.burn_in), int(rng.integers(2**63))
        walks = make_walks(target, C, self.proposal_sd, self.burn_in, self.adapt,
                           self.target_acceptance)
        kept = KeptStates(n, self.burn_in, self.thin, C, len(target.param_names))
        record = LabelRecord(C, target.n_nodes, target.q, n, self.burn_in, self.n_batches)
        acceptance = np.full((2, n), np.nan)
        for t in range(n):
            if t == prepare_at and mrf_free:
                update.prepare(state, prepare_seed)
            if t == self.burn_in and mrf_free:
                update.after_burn_in(state, prepare_seed + 1)
            state, info = hidden_step(target, state, walks, rng, theta_update=update,
                                      theta_steps=self.theta_steps,
                                      swendsen_wang=self.labels == "swendsen_wang",
                                      acc=record.buffer(t))
            record.close(t, state.labels)
            self._adapt(target, walks, t, state.params, info)
            acceptance[:, t] = info["mrf_acceptance"], info["emission_acceptance"]
            theta = state.params[:, target.free]
            run.n_evals += C
            run.offer(theta, state.log_target)
            kept.record(t, theta, state.log_target)
            run.step(t, kept.trace_ess(t), **info)
        return self._finish(target, run, kept, record, acceptance, seed, update,
                            int(rng.integers(2**63)))

    def _start(self, target: HiddenTarget) -> PointEstimate:
        if self.init == "em":
            return em_estimate(target, max_iterations=100, tol=1e-5)
        if self.init == "icm":
            return icm_estimate(target)
        params, labels = start_point(target)
        return PointEstimate(params, labels, target.emission.one_hot(labels), float("nan"),
                             0, False)

    def _check_kernel(self, target: HiddenTarget, point: PointEstimate) -> None:
        if self.labels != "swendsen_wang":
            return
        psi = target.design.psi(point.params[None, : target.n_mrf])[0]
        tables = target.field.tables(psi, swendsen_wang=True)
        if tables.sw_field is None:
            raise ValueError(f"labels='swendsen_wang' needs ferromagnetic Potts pair tables "
                             f"(J [a == b] + per-state terms, J >= 0): {tables.sw_reason}")

    @staticmethod
    def _adapt(target: HiddenTarget, walks: Any, t: int, params: np.ndarray,
               info: dict) -> None:
        is_mrf = np.arange(len(target.all_names)) < target.n_mrf
        for walk, block, key in ((walks.mrf, is_mrf, "mrf_acceptance"),
                                 (walks.emission, ~is_mrf, "emission_acceptance")):
            if walk is not None:
                walk.update(t, params[:, block & target.free], info[key])

    def _finish(self, target: HiddenTarget, run: Run, kept: KeptStates, record: LabelRecord,
                acceptance: np.ndarray, seed: int | None, update: ThetaUpdate, seed2: int):
        theta, log_target, _ = kept.flat()
        prob, mcse, occupancy, empty = record.result()
        rhat, ess = param_diagnostics(kept.theta)
        extra = {**label_variables(target, prob, mcse),
                 "param_rhat": (("param",), rhat), "param_ess": (("param",), ess),
                 "state_occupancy": (("state",), occupancy),
                 "state_empty_fraction": (("state",), empty),
                 "mrf_acceptance": (("step",), acceptance[0]),
                 "emission_acceptance": (("step",), acceptance[1])}
        mcse_max = float(np.nanmax(mcse)) if np.isfinite(mcse).any() else float("nan")
        reasons = (update.reasons(theta, seed2) if target.free[: target.n_mrf].any() else [])
        attrs = {**(update.attrs() if target.free[: target.n_mrf].any() else {}),
                 "method": target.method, "labels_kernel": self.labels,
                 "label_mcse_max": mcse_max, "priors": json.dumps(
                     {**target.emission.describe_prior(),
                      "mrf": "flat on the bounds of every free MRF parameter"}),
                 "map_theta_is": "the draw of highest log PL(x | MRF parameters) + sum_i log "
                                 "p(y_i | x_i) + log prior of the emission (over labels too)"}
        return run.finish(theta, log_target, None, sampler=self.name, config=self.get_config(),
                          seed=seed, chain=kept.chain(), bias=self._reasons(
                              target, mcse_max, empty, reasons), extra_vars=extra,
                          extra_attrs=attrs)

    @staticmethod
    def _reasons(target: HiddenTarget, mcse_max: float, empty: np.ndarray,
                 method_reasons: list[str]) -> str | None:
        """What makes the result no estimate of the posterior, in words (or None)."""
        out = list(method_reasons)
        full = np.flatnonzero(empty > EMPTY_STATE_MAX)
        if full.size:
            out.append(f"state(s) {', '.join(map(str, full))} held no node in "
                       f"{100 * empty[full].max():.0f} % of the sweeps: the data support "
                       f"fewer than n_states={target.q} states")
        if mcse_max > LABEL_MCSE_MAX:
            out.append(f"label probabilities have Monte Carlo standard errors up to "
                       f"{mcse_max:.3f} > {LABEL_MCSE_MAX}: run longer (n_steps)")
        return "; ".join(out) or None

    def _run_plain(self, target: Any, seed: int | None, progress: bool,
                   callback: Callback | None):
        """Random-walk Metropolis on a target without hidden labels (the parameters alone)."""
        return run_random_walk(self, target, seed, progress, callback)
