"""How the ``hidden`` sampler draws the MRF's parameters given the labels: one class per method.

Given every chain's labels ``x``, the MRF's free parameters ``θ`` are updated by a
random walk (:class:`~mrfpe.samplers.kit.AdaptiveRandomWalk`, flat prior on their
bounds) against

* ``"pl"`` -- Besag's pseudolikelihood ``PL(θ | x)``: cheap, a pseudo-posterior;
* ``"pl_adjusted"`` -- the calibrated pseudolikelihood ``PL(c + W (θ - θ*) | x)``
  (:class:`~mrfpe.models.calibration.AdjustedPL`: Stoehr & Friel 2015; Bouranis,
  Friel & Maire 2017), its map ``(c, W, θ*)`` built once, by simulation, at chain 0's
  labels halfway through burn-in (the raw PL before): the point estimate's labels are
  smoother than the posterior's and would overstate the coupling. The map is then held
  fixed while the labels move. That is an approximation the labels amplify: a coupling
  drawn too high smooths the next labels, whose PL then asks for a higher one, so the
  map's error at one labelling returns multiplied (measured on a 6 x 40 three-state
  field: 0.0-2.1 exact sd off, by the labelling the map was built at). The result says
  so: it is never marked reliable;
* ``"exchange"`` -- the exchange algorithm (Murray, Ghahramani & MacKay 2006) on
  ``p(x | θ)``: auxiliary labels ``w`` from the MRF's simulator at the proposal
  ``θ'``, ``aux_sweeps`` sweeps started from the chain's labels (Caimo & Friel 2011),
  accepted with ``f(x|θ') f(w|θ) / (f(x|θ) f(w|θ'))``, ``theta_steps`` times a sweep;
* ``"surrogate"`` -- the pre-computed Gaussian synthetic likelihood of the sufficient
  statistics (:mod:`mrfpe.models.hidden.surrogate`; Moores et al. 2015, 2020).

Every update offers ``prepare`` (once, before the sweep :meth:`ThetaUpdate.prepare_at`
says), ``step`` (one sweep of every chain, in place; returns the acceptance rate),
``reasons`` (what makes the draws no estimate of the posterior, at the end) and
``attrs`` (what the posterior records).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrfpe.models.design import ConditionalRows, Design
from mrfpe.models.estimators import ConditionalTarget, LikelihoodTarget
from mrfpe.models.hidden.surrogate import SURROGATE_TOL, Surrogate
from mrfpe.models.hidden.surrogate_build import build_surrogate
from mrfpe.models.hidden.target import HiddenTarget
from mrfpe.models.mixing import autocorrelation_time
from mrfpe.samplers.hidden_steps import walk_block
from mrfpe.samplers.kit import AdaptiveRandomWalk, metropolis_accept

__all__ = ["ThetaUpdate", "make_theta_update"]


def _mrf_target(target: HiddenTarget, cls: type, x: np.ndarray, *, free_only: bool = False,
                **kwargs: Any) -> Any:
    """The MRF's own target of the labelling ``x`` on the hidden target's compiled design:
    over every MRF parameter, or (``free_only``) over the free ones, the fixed ones held
    at their values inside the feature map."""
    design, n_mrf = target.design, target.n_mrf
    keep = np.arange(n_mrf)
    if free_only:
        keep = np.flatnonzero(target.free[:n_mrf])
        base = np.where(target.free[:n_mrf], 0.0, target.fixed_values[:n_mrf])

        def psi(theta: np.ndarray) -> np.ndarray:
            full = np.repeat(base[None], theta.shape[0], axis=0)
            full[:, keep] = theta
            return target.design.psi(full)

        design = Design(design.graph, design.q, design.node, design.pair, psi,
                        pair_per_edge=design.pair_per_edge)
    return cls(model=target.model.mrf, design=design, x=np.asarray(x, np.int64)[None],
               param_names=[target.all_names[i] for i in keep],
               bounds=target.all_bounds[keep], estimator=kwargs.pop("estimator"), **kwargs)


class ThetaUpdate:
    """``"pl"``: random-walk Metropolis on the labels' pseudolikelihood (a pseudo-posterior)."""

    method = "pl"

    def __init__(self, target: HiddenTarget) -> None:
        self.target = target
        self.idx = np.flatnonzero(target.free[: target.n_mrf])

    def prepare_at(self, burn_in: int) -> int:
        """The sweep before which :meth:`prepare` runs."""
        return 0

    def prepare(self, state: Any, seed: int) -> None:
        """Anything built once (here nothing)."""

    def after_burn_in(self, state: Any, seed: int) -> None:
        """A last adaptation at the end of burn-in (here nothing)."""

    def log_density(self, x: np.ndarray, rows: ConditionalRows | None = None) -> Any:
        """``mrf vectors (k, d_mrf) -> (k,)`` of one chain's labels ``x`` (their conditional
        rows ``rows``, if built: :meth:`LabelField.conditional_rows
        <mrfpe.models.hidden.field.LabelField.conditional_rows>`)."""
        rows = self.target.field.conditional_rows(x) if rows is None else rows
        return lambda mrf: self.target.log_pl_rows(rows, mrf)

    def step(self, state: Any, walk: AdaptiveRandomWalk | None, rng: np.random.Generator,
             theta_steps: int, rows: list[ConditionalRows] | None = None) -> float:
        """``theta_steps`` random-walk steps of every chain's free MRF parameters, in place
        (``rows``: each chain's conditional rows, if built); the acceptance rate."""
        if walk is None:
            return float("nan")
        n_mrf = self.target.n_mrf
        rows = [None] * state.labels.shape[0] if rows is None else rows
        densities = [self.log_density(x, r) for x, r in zip(state.labels, rows, strict=True)]

        def log_density(c: int, trial: np.ndarray) -> np.ndarray:
            return densities[c](trial[:, :n_mrf])

        return float(np.mean([walk_block(walk, self.idx, state.params, log_density, rng)
                              for _ in range(theta_steps)]))

    def reasons(self, theta: np.ndarray, seed: int) -> list[str]:
        return ["pseudo-posterior: the MRF's parameters are drawn from exp(PL) of the labels "
                "(method='pl'), not from the likelihood, so their spread is not the "
                "posterior's (the labels and the emission given them are exact)"]

    def attrs(self) -> dict:
        return {}


class AdjustedPLUpdate(ThetaUpdate):
    """``"pl_adjusted"``: the calibrated pseudolikelihood, its map built halfway through burn-in."""

    method = "pl_adjusted"
    adjusted: Any = None

    def prepare_at(self, burn_in: int) -> int:
        return burn_in // 2  # labels of the posterior, not the point estimate's smoother ones

    def prepare(self, state: Any, seed: int) -> None:
        from mrfpe.models.calibration import AdjustedPL

        x0 = state.labels[0]
        pl = _mrf_target(self.target, ConditionalTarget, x0, free_only=True, estimator="pl",
                         rows=[self.target.design.conditional_rows(x0[None])],
                         nodes=np.arange(self.target.n_nodes))
        lik = _mrf_target(self.target, LikelihoodTarget, x0, free_only=True,
                          estimator="likelihood")
        # over the free parameters only: a map over all would move them through the fixed
        # ones' offsets from its centre (measured: 2.3 exact sd with the fields fixed at 0)
        self.adjusted = AdjustedPL(pl, lik, seed=seed)

    def log_density(self, x: np.ndarray, rows: ConditionalRows | None = None) -> Any:
        pl = super().log_density(x, rows)
        if self.adjusted is None:  # the first half of burn-in: the raw PL
            return pl
        b = self.target.all_bounds[: self.target.n_mrf]

        def density(mrf: np.ndarray) -> np.ndarray:
            mapped = mrf.copy()
            mapped[:, self.idx] = self.adjusted.to_pl(mrf[:, self.idx])
            out = pl(mapped)  # -inf where the map leaves the PL's box
            out[np.any((mrf < b[:, 0]) | (mrf > b[:, 1]), axis=1)] = -np.inf  # θ's flat prior
            return out

        return density

    def reasons(self, theta: np.ndarray, seed: int) -> list[str]:
        return ["approximate: the calibrated pseudolikelihood's map was built at one "
                "labelling (method='pl_adjusted') and the labels' feedback amplifies its "
                "error (up to 2 posterior sd measured); use method='exchange' or 'surrogate' "
                "for the posterior"]

    def attrs(self) -> dict:
        d = self.adjusted.describe()
        return {"pl_adjusted_theta_mode": np.asarray(d.get("theta_mode", []), float).tolist(),
                "pl_adjusted_at": "chain 0's labels halfway through burn-in"}


class ExchangeUpdate(ThetaUpdate):
    """``"exchange"``: the exchange algorithm with auxiliary labels from the MRF's simulator."""

    method = "exchange"

    def __init__(self, target: HiddenTarget, aux_sweeps: int | str = "auto",
                 max_aux_sweeps: int = 2000, mixing_factor: float = 5.0) -> None:
        super().__init__(target)
        self.aux_sweeps, self.max_aux_sweeps = aux_sweeps, max_aux_sweeps
        self.mixing_factor = mixing_factor
        self.tau_start = math.nan

    def prepare(self, state: Any, seed: int) -> None:
        self.lik = _mrf_target(self.target, LikelihoodTarget, state.labels[0],
                               estimator="likelihood")
        self.tau_start = autocorrelation_time(self.lik, state.params[0, : self.target.n_mrf],
                                              seed=seed)
        self.sweeps = self._sweeps(self.tau_start)

    def after_burn_in(self, state: Any, seed: int) -> None:
        """``aux_sweeps="auto"``: ``10 τ`` measured again, at the chains' mean after burn-in
        (near a first-order transition τ there ran to 5 x its value at the start point)."""
        if self.aux_sweeps == "auto":
            mean = state.params[:, : self.target.n_mrf].mean(axis=0)
            self.tau_burn_in = autocorrelation_time(self.lik, mean, seed=seed)
            self.sweeps = self._sweeps(self.tau_burn_in)

    def _sweeps(self, tau: float) -> int:
        if self.aux_sweeps != "auto":
            return int(self.aux_sweeps)
        if not math.isfinite(tau):
            return self.max_aux_sweeps
        return int(min(max(10, math.ceil(10 * tau)), self.max_aux_sweeps))

    def step(self, state: Any, walk: AdaptiveRandomWalk | None, rng: np.random.Generator,
             theta_steps: int, rows: list[ConditionalRows] | None = None) -> float:
        """``theta_steps`` exchange steps of every chain, a simulation each (as many steps
        as the other methods' random walks take: at one a sweep the chains of θ mixed too
        slowly for R̂ <= 1.01 in 7 of 12 runs on 6 x 40); the acceptance rate."""
        if walk is None:
            return float("nan")
        return float(np.mean([self._once(state, walk, rng) for _ in range(theta_steps)]))

    def _once(self, state: Any, walk: AdaptiveRandomWalk, rng: np.random.Generator) -> float:
        n_mrf = self.target.n_mrf
        prop, inside = walk.propose(state.params[:, self.idx], rng)
        log_u = np.log(rng.random(state.labels.shape[0]))
        accepted = np.zeros(state.labels.shape[0], dtype=bool)
        for c in np.flatnonzero(inside):
            pair = np.stack([state.params[c, :n_mrf]] * 2)
            pair[1, self.idx] = prop[c]
            x = state.labels[c]
            w = self.lik.simulate(pair[1], n=1, seed=int(rng.integers(2**63)), init=x,
                                  n_sweeps=self.sweeps)
            fx, fw = self.lik.unnormalised(pair, x[None]), self.lik.unnormalised(pair, w)
            log_ratio = (fx[1] - fx[0]) - (fw[1] - fw[0])
            accepted[c] = bool(metropolis_accept(log_u[c:c + 1], np.zeros(1),
                                                 np.array([log_ratio]))[0])
            if accepted[c]:
                state.params[c, self.idx] = prop[c]
        return float(accepted.mean())

    def reasons(self, theta: np.ndarray, seed: int) -> list[str]:
        full = self.target.full(theta.mean(axis=0))[0, : self.target.n_mrf]
        self.tau_end = autocorrelation_time(self.lik, full, seed=seed)
        if self.sweeps >= self.mixing_factor * self.tau_end:
            return []
        return [f"auxiliary chains of {self.sweeps} sweeps are shorter than "
                f"{self.mixing_factor:g} autocorrelation times ({self.tau_end:.1f} sweeps at the "
                f"posterior mean): raise aux_sweeps (or max_aux_sweeps)"]

    def attrs(self) -> dict:
        return {"aux_sweeps": float(self.sweeps), "aux_tau_start": float(self.tau_start),
                "aux_tau_burn_in": float(getattr(self, "tau_burn_in", math.nan)),
                "aux_tau_posterior_mean": float(getattr(self, "tau_end", math.nan))}


class SurrogateUpdate(ThetaUpdate):
    """``"surrogate"``: random-walk Metropolis on the Gaussian synthetic likelihood."""

    method = "surrogate"

    def __init__(self, target: HiddenTarget) -> None:
        super().__init__(target)
        self.surrogate: Surrogate | None = target.surrogate

    def prepare(self, state: Any, seed: int) -> None:
        if self.surrogate is None:  # built here, locally, from the run's seed
            self.surrogate = build_surrogate(self.target, seed=seed)

    def log_density(self, x: np.ndarray, rows: ConditionalRows | None = None) -> Any:
        s = self.target.design.statistics(x[None])[0, self.idx]
        b = self.target.all_bounds[: self.target.n_mrf]

        def density(mrf: np.ndarray) -> np.ndarray:
            inside = np.all((mrf >= b[:, 0]) & (mrf <= b[:, 1]), axis=1)
            out = np.full(mrf.shape[0], -np.inf)
            if inside.any():
                out[inside] = self.surrogate.log_lik(s, mrf[inside][:, self.idx])
            return out

        return density

    def reasons(self, theta: np.ndarray, seed: int) -> list[str]:
        mrf = self.target.full(theta)[:, self.idx]
        self.error = self.surrogate.error_within(mrf.min(axis=0), mrf.max(axis=0))
        if self.error <= SURROGATE_TOL:
            return []
        return [f"the surrogate's mean misses the simulated one by up to {self.error:.2f} "
                f"posterior sds in the posterior's range (tolerance {SURROGATE_TOL}) after "
                f"{self.surrogate.n_design} design points: build it with a larger max_design "
                f"or n_sweeps (mrfpe.models.hidden.build_surrogate)"]

    def attrs(self) -> dict:
        d = self.surrogate.describe()
        return {"surrogate_n_design": d["n_design"],
                "surrogate_validation_error": d["validation_error"],
                "surrogate_error_in_range": float(getattr(self, "error", math.nan)),
                "surrogate_min_ess": d["min_ess"]}


def make_theta_update(target: HiddenTarget, *, aux_sweeps: int | str = "auto",
                      max_aux_sweeps: int = 2000) -> ThetaUpdate:
    """The update of the target's ``method``."""
    if target.method == "exchange":
        return ExchangeUpdate(target, aux_sweeps, max_aux_sweeps)
    if target.method == "surrogate":
        return SurrogateUpdate(target)
    if target.method == "pl_adjusted":
        return AdjustedPLUpdate(target)
    return ThetaUpdate(target)
