"""The exchange algorithm: the posterior of a likelihood with an intractable normaliser.

For ``p(x | θ) = f(x | θ) / Z(θ)`` with ``Z`` intractable (every MRF on a
lattice), the posterior ``p(θ | x) ∝ f(x | θ) p(θ) / Z(θ)`` is *doubly
intractable*: a Metropolis ratio would need ``Z(θ') / Z(θ)``. The exchange
algorithm (Murray, Ghahramani & MacKay 2006) draws auxiliary data
``y ~ p(· | θ')`` at the proposed ``θ'`` and accepts with

    ``α = min(1, f(x | θ') f(y | θ) p(θ') / (f(x | θ) f(y | θ') p(θ)))``,

in which the normalisers cancel; the chain's stationary distribution is the
exact posterior when ``y`` is an exact draw. The prior is flat on the
target's box, as for every sampler here (a posterior ∝ exp(log_prob) there).

Auxiliary draws. A target with ``exact_simulator = True`` (the Gaussian MRF,
the checks' Gaussian) gives exact draws. A discrete MRF's draws come from
``aux_sweeps`` Swendsen-Wang or Gibbs sweeps started from the observed data
(the approximate exchange algorithm of Caimo & Friel 2011; Everitt 2012
bounds its error by the auxiliary chain's distance from stationarity). After
burn-in the sampler measures the integrated autocorrelation time ``τ`` of the
sufficient statistics of the auxiliary chain at the burn-in mean (``emcee``'s
estimator on a pilot run of ``max(2000, 50 τ)`` sweeps); ``aux_sweeps="auto"``
then takes ``10 τ`` sweeps (at least 10, at most ``max_aux_sweeps``): started
at the data, a draw after ``10 τ`` sweeps keeps a correlation of about
``e^-10`` with its start. At the end ``τ`` is measured again at the posterior
mean; a run whose auxiliary chains were shorter than ``5 τ`` there (e.g. Gibbs
near the critical coupling, where ``τ`` grows like ``L^2``) is marked
unreliable, with the reason, in the posterior's diagnostics.

Every step draws all chains' auxiliary data in one compiled call
(``target.simulate_aux``: one chain per proposal and observed configuration, each started
at the data) and prices them in one batched product (:func:`auxiliary_log_ratio`): at a
64 x 64 Ising lattice about 85 % of a step is spent in the compiled sweeps. The auxiliary
chain's sampler is the target's (``sampler="auto"``: Swendsen-Wang where the pair tables
are ferromagnetic Potts, else Gibbs). Priced per unit of mixing (``τ`` times a sweep's
time, 4 chains, Ising 64², ``python -m benchmarks.bench_exchange``) single-site Gibbs and
Swendsen-Wang cost about the same at the coupling 0.3, and Gibbs 11-17 times more at 0.42,
near the critical coupling, where its ``τ`` grows like ``L^2``: so "auto" keeps
Swendsen-Wang. With 16 chains or more, Gibbs chains of a binary lattice model run on the
multi-spin kernel (Jacobs & Rebbi 1981; :mod:`mrfpe.models.simulate_batch`), 12-20 times
cheaper per chain-sweep at 64 chains: ``sampler="gibbs"`` is then the cheaper choice away
from the critical coupling (with 4 chains a word is mostly empty and it does not pay).

Start and first proposal. In a wide box a uniform start can sit thousands of
posterior sds from the posterior (a 16 x 16 auto-normal field in a precision box of
``(0, 1e4 / var)``: chains 10^3-10^4 times too precise, R̂ 3.8 after 8000 steps), and
a first proposal of 5 % of each range keeps the chains there. With ``start="pl"``
(the default) the chains start near the maximum of the model's pseudolikelihood
(:func:`pl_start`; cheap, no simulation), drawn from ``N(θ_PL, s² Σ_PL)`` with
``Σ_PL`` the inverse of the PL's curvature there
(:func:`mrfpe.models.pl_spread.start_covariance`) and ``s =`` :data:`START_SPREAD`,
wider than the posterior so that R̂ still compares chains that started apart; the
first proposal is ``2.38 / √d`` times ``Σ_PL``'s Cholesky factor (Roberts, Gelman &
Gilks 1997), adapted during burn-in as before. A target without a pseudolikelihood
(``pseudolikelihood()`` or a discrete model's design) starts uniformly, as
``start="uniform"`` does.

MAP. A likelihood target's ``log_prob`` omits ``-log Z(θ)`` (it says so with
``normalised = False``), so its best-so-far is no MAP: the posterior then reports
as ``map_theta`` the draw of highest kernel density (:func:`kde_mode`), and says
which in its ``map_theta_is`` attribute.

The target must offer the likelihood interface of
:class:`mrfpe.models.estimators.LikelihoodTarget` (``model.target("likelihood",
x)``): ``log_prob(θ)`` = ``log f(x | θ)`` + const, ``unnormalised(θ, y)`` and
``simulate(θ, n, seed=..., init=..., n_sweeps=...)``. A target that also offers
``simulate_aux(θ_rows, seed=..., n_sweeps=...)`` and ``unnormalised_rows`` (a declared
discrete model's) gets every chain's auxiliary draw of a step from one compiled call
(:func:`auxiliary_log_ratio`): the draws have the distribution of the per-chain calls,
from other random numbers.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from mrfpe.models.mixing import autocorrelation_time
from mrfpe.models.pl_spread import hessian, start_covariance
from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import (
    AdaptiveRandomWalk,
    check_chain_length,
    check_target,
    evaluate_inside,
    metropolis_accept,
    start_chains,
)
from mrfpe.targets.maximise import grid_size, maximise

__all__ = ["START_SPREAD", "Exchange", "auxiliary_log_ratio", "check_likelihood_target",
           "kde_mode", "pl_start", "pseudolikelihood_of"]

#: The chains' starts spread this many times the PL's curvature-based sd (``start="pl"``).
START_SPREAD = 3.0


def kde_mode(theta: np.ndarray, rng: np.random.Generator, n_eval: int = 2000,
             n_fit: int = 4000) -> np.ndarray:
    """The draw of highest kernel density (scipy's Gaussian KDE, Scott's bandwidth).

    Fitted on at most ``n_fit`` draws and evaluated at ``n_eval`` of them, both
    drawn without replacement: the posterior mode estimated from the draws, for
    targets whose ``log_prob`` is not the posterior (a likelihood without its
    normaliser).
    """
    from scipy.stats import gaussian_kde

    fit = theta[rng.choice(theta.shape[0], min(n_fit, theta.shape[0]), replace=False)]
    cand = theta[rng.choice(theta.shape[0], min(n_eval, theta.shape[0]), replace=False)]
    try:
        dens = gaussian_kde(fit.T)(cand.T)
    except np.linalg.LinAlgError:  # draws on a lower-dimensional set: fall back to the mean
        return theta.mean(axis=0)
    return cand[int(np.argmax(dens))]


def check_likelihood_target(target: Any) -> None:
    """ValueError unless ``target`` offers ``unnormalised`` and ``simulate`` (one line)."""
    missing = [m for m in ("unnormalised", "simulate") if not callable(getattr(target, m, None))]
    if missing:
        name = getattr(target, "name", "") or type(target).__name__
        raise ValueError(f"target must be a likelihood target with a simulator (e.g. "
                         f"model.target('likelihood', x)); {name} has no "
                         f"{' or '.join(missing)}")


def pseudolikelihood_of(target: Any) -> Any | None:
    """The pseudolikelihood target on a likelihood target's data, or None.

    ``target.pseudolikelihood()`` where the target offers it (the auto-normal model's),
    Besag's PL over the design of a declared discrete model's ``"likelihood"`` target
    (the same rows ``model.target("pl", x)`` sums), else None.
    """
    own = getattr(target, "pseudolikelihood", None)
    if callable(own):
        return own()
    design = getattr(target, "design", None)
    if design is None or not callable(getattr(design, "conditional_rows", None)) or \
            getattr(target, "model", None) is None:
        return None
    from mrfpe.models.estimators import ConditionalTarget

    return ConditionalTarget(rows=[design.conditional_rows(target.x)],
                             nodes=np.arange(design.graph.n_nodes), model=target.model,
                             design=design, x=target.x, param_names=target.param_names,
                             bounds=target.bounds, estimator="pl")


def pl_start(pl: Any, bounds: np.ndarray, seed: int | None = 0,
             ) -> tuple[np.ndarray, np.ndarray] | None:
    """``(θ_PL, Σ_PL)``: the PL's maximum in ``bounds`` and the inverse of its curvature
    there (:func:`~mrfpe.models.pl_spread.start_covariance`: every eigenvalue by
    magnitude, no sd above a quarter of the range), or None where the PL is ``-inf``
    everywhere tried.

    The maximum is :func:`~mrfpe.targets.maximise`'s on a grid of at most 4096 points;
    the curvature is a central difference at ``1e-4`` of each coordinate's magnitude (at
    least ``1e-2`` of its range); entries that leave the PL's support count as flat.
    """
    d = bounds.shape[0]
    theta, lp = maximise(pl, grid=max(3, grid_size(4096, d)), seed=seed)
    if not np.isfinite(lp):
        return None
    width = bounds[:, 1] - bounds[:, 0]
    h = 1e-4 * np.minimum(width, np.maximum(np.abs(theta), 1e-2 * width))
    with np.errstate(invalid="ignore"):  # -inf - -inf where the stencil leaves the support
        H = -hessian(pl.log_prob, theta, h)
    return theta, start_covariance(np.where(np.isfinite(H), H, 0.0), bounds)


def auxiliary_log_ratio(target: Any, x: np.ndarray, y: np.ndarray, rng: np.random.Generator,
                        sweeps: int | None) -> np.ndarray:
    """``log f(w_i | x_i) - log f(w_i | y_i)`` (k,) with ``w_i ~ p(· | y_i)`` the auxiliary
    draw of chain ``i`` (Murray, Ghahramani & MacKay 2006) at its proposal ``y_i``.

    ``sweeps`` None: the target's exact simulator, one call per chain. Else ``sweeps``
    sweeps from the data (Caimo & Friel 2011): where the target offers ``simulate_aux``
    all chains' draws come from one compiled call and their log densities from one
    batched product (statistics once per draw), else one call per chain.
    """
    if sweeps is not None and callable(getattr(target, "simulate_aux", None)):
        w = target.simulate_aux(y, seed=int(rng.integers(2**63)), n_sweeps=sweeps)
        u = target.unnormalised_rows(np.stack([x, y]), w)
        return u[0] - u[1]
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        w = target.simulate(y[i], seed=int(rng.integers(2**63)), **(
            {} if sweeps is None else {"n_sweeps": sweeps, "init": "data"}))
        u = target.unnormalised(np.stack([x[i], y[i]]), w)
        out[i] = u[0] - u[1]
    return out


def _draw_near(run: Any, target: Any, rng: np.random.Generator, x: np.ndarray, lp: np.ndarray,
               bounds: np.ndarray, centre: np.ndarray, cov: np.ndarray,
               max_rounds: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """The chains' starts drawn from ``N(centre, cov)`` in the support (counted by ``run``);
    a chain that finds none in ``max_rounds`` rounds keeps its uniform start ``x``."""
    L = np.linalg.cholesky(cov)
    lo, hi = bounds[:, 0], bounds[:, 1]
    new, lpn = x.copy(), np.full(x.shape[0], -np.inf)
    for _ in range(max_rounds):
        bad = np.flatnonzero(~np.isfinite(lpn))
        if bad.size == 0:
            break
        cand = centre + rng.standard_normal((bad.size, centre.size)) @ L.T
        inside = np.all((cand >= lo) & (cand <= hi), axis=1)
        lpc = np.full(bad.size, -np.inf)
        if inside.any():
            lpc[inside] = run.evaluate(target, cand[inside])
        new[bad], lpn[bad] = cand, lpc
    bad = ~np.isfinite(lpn)
    new[bad], lpn[bad] = x[bad], lp[bad]
    return new, lpn


class Exchange(Sampler):
    """Exchange algorithm for doubly-intractable posteriors (Murray et al. 2006).

    Parameters
    ----------
    n_steps, n_chains, burn_in, thin, proposal_sd, adapt, target_acceptance
        As :class:`mrfpe.samplers.mh.MetropolisHastings` (a random walk adapted
        during burn-in only). The default length, 4 chains x 8000 steps, is what
        keeps R̂ <= 1.01 on 10 x 10 Ising posteriors: at 4000 steps 13 of 80 accurate
        runs missed it (R̂ 1.010-1.017), at 8000 R̂ was about 1.002.
    aux_sweeps : "auto" or int
        Sweeps of the auxiliary chain per draw (ignored for exact simulators);
        "auto": ``10 τ`` measured after burn-in (see the module docstring).
    max_aux_sweeps : int
        Cap of the automatic choice.
    mixing_factor : float
        The run is flagged unreliable when ``aux_sweeps < mixing_factor * τ`` at
        the posterior mean (5).
    start : "pl" or "uniform"
        ``"pl"`` (default): the chains start near the pseudolikelihood's maximum,
        spread :data:`START_SPREAD` times its curvature's sd, and the first proposal
        follows that curvature (see the module docstring; ``proposal_sd`` is then
        unused); ``"uniform"``, or a target without a pseudolikelihood: uniform starts
        in the box and a first proposal of ``proposal_sd`` of each range.
    """

    name = "exchange"
    conformance: ClassVar[dict] = {
        "quick_config": {"n_steps": 1200, "burn_in": 300},
    }

    def __init__(self, n_steps: int = 8000, n_chains: int = 4, burn_in: int = 1500,
                 thin: int = 1, proposal_sd: float = 0.05, adapt: bool = True,
                 target_acceptance: float = 0.3, aux_sweeps: int | str = "auto",
                 max_aux_sweeps: int = 2000, mixing_factor: float = 5.0, start: str = "pl"):
        self.n_steps, self.burn_in, self.thin = check_chain_length(n_steps, burn_in, thin)
        self.n_chains = check_positive_int("n_chains", n_chains)
        self.proposal_sd, self.adapt, self.target_acceptance = AdaptiveRandomWalk.check_options(
            proposal_sd, adapt, target_acceptance)
        if aux_sweeps != "auto":
            aux_sweeps = check_positive_int("aux_sweeps", aux_sweeps)
        self.aux_sweeps = aux_sweeps
        self.max_aux_sweeps = check_positive_int("max_aux_sweeps", max_aux_sweeps)
        self.mixing_factor = check_range("mixing_factor", mixing_factor, 0.0, np.inf,
                                         low_open=True, high_open=True)
        self.start = check_choice("start", start, ("pl", "uniform"))

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Run the chains on a likelihood ``target``; return the posterior Dataset."""
        check_target(target)
        check_likelihood_target(target)
        n, c = self.n_steps, self.n_chains
        exact = bool(getattr(target, "exact_simulator", False))
        sweeps = self._initial_sweeps(target)
        bounds, rng, run, x, lp, kept = start_chains(
            target, seed, n_steps=n, n_chains=c, burn_in=self.burn_in, thin=self.thin,
            desc=self.name, progress=progress, callback=callback)
        x, lp, walk, started = self._start(target, seed, bounds, rng, run, x, lp)
        acceptance = np.zeros(n)
        tau_burn = math.nan
        for t in range(n):
            y, inside = walk.propose(x, rng)
            lpy = evaluate_inside(run, target, y, inside)  # -inf outside, not evaluated
            log_ratio = np.full(c, -np.inf)
            ok = np.flatnonzero(inside & np.isfinite(lpy))
            if ok.size:
                log_ratio[ok] = (lpy[ok] - lp[ok]) + auxiliary_log_ratio(
                    target, x[ok], y[ok], rng, None if exact else sweeps)
            accept = inside & metropolis_accept(np.log(rng.random(c)),
                                                np.where(np.isfinite(lp), 0.0, lp), log_ratio)
            x[accept], lp[accept] = y[accept], lpy[accept]
            acceptance[t] = accept.mean()
            run.offer(x, lp)
            walk.update(t, x, acceptance[t])
            if t == self.burn_in - 1 and not exact:
                tau_burn = autocorrelation_time(target, x.mean(axis=0),
                                                    seed=int(rng.integers(2**63)))
                if self.aux_sweeps == "auto":
                    sweeps = self._auto_sweeps(tau_burn)
            kept.record(t, x, lp)
            run.step(t, kept.trace_ess(t), acceptance=float(acceptance[t]),
                     aux_sweeps=float(sweeps))
        theta, log_target, _ = kept.flat()
        bias, tau_end = None, math.nan
        if not exact:
            tau_end = autocorrelation_time(target, theta.mean(axis=0),
                                               seed=int(rng.integers(2**63)))
            if not sweeps >= self.mixing_factor * tau_end:
                bias = (f"auxiliary chains of {sweeps} sweeps are shorter than "
                        f"{self.mixing_factor:g} autocorrelation times ({tau_end:.1f} sweeps "
                        f"at the posterior mean): the auxiliary draws are not from p(y | θ) "
                        f"and the posterior is too wide; raise aux_sweeps (or max_aux_sweeps), "
                        f"or use a simulator that mixes (sampler='swendsen_wang' for Potts)")
        map_note = "the best-so-far of the target's log_prob"
        if not getattr(target, "normalised", True):
            # log_prob omits -log Z(θ): its best-so-far is no MAP. Report the draws' mode.
            mode = kde_mode(theta, np.random.default_rng(int(rng.integers(2**63))))
            best = float(target.log_prob(mode)[0])
            run.map_theta = [mode] * len(run.map_theta)
            run.map_log_target = [best] * len(run.map_log_target)
            map_note = "the mode of a kernel density estimate of the draws"
        return run.finish(theta, log_target, None, sampler=self.name, config=self.get_config(),
                          seed=seed, chain=kept.chain(), bias=bias,
                          extra_vars={"acceptance": (("step",), acceptance)},
                          extra_attrs={"aux_sweeps": float(sweeps) if not exact else 0.0,
                                       "aux_tau_burn_in": float(tau_burn),
                                       "aux_tau_posterior_mean": float(tau_end),
                                       "exact_simulator": int(exact),
                                       "map_theta_is": map_note, "start": started})

    def _start(self, target: Any, seed: int | None, bounds: np.ndarray,
               rng: np.random.Generator, run: Any, x: np.ndarray, lp: np.ndarray,
               ) -> tuple[np.ndarray, np.ndarray, AdaptiveRandomWalk, str]:
        """The chains' starts and the random walk: near the PL's maximum where there is
        one (``start="pl"``), else the uniform starts ``x`` (module docstring)."""
        pl = pseudolikelihood_of(target) if self.start == "pl" else None
        found = None if pl is None else pl_start(pl, bounds, seed)
        if found is None:
            return x, lp, AdaptiveRandomWalk(bounds, self.n_chains, self.proposal_sd,
                                             self.burn_in, self.adapt,
                                             self.target_acceptance), "uniform"
        centre, cov = found
        x, lp = _draw_near(run, target, rng, x, lp, bounds, centre, START_SPREAD ** 2 * cov)
        walk = AdaptiveRandomWalk(bounds, self.n_chains, self.proposal_sd, self.burn_in,
                                  self.adapt, self.target_acceptance,
                                  spread=np.linalg.cholesky(cov))
        return x, lp, walk, "pl"

    def _initial_sweeps(self, target: Any) -> int:
        if self.aux_sweeps != "auto":
            return int(self.aux_sweeps)
        return int(min(getattr(target, "n_sweeps", 200), self.max_aux_sweeps))

    def _auto_sweeps(self, tau: float) -> int:
        if not math.isfinite(tau):
            return self.max_aux_sweeps
        return int(min(max(10, math.ceil(10 * tau)), self.max_aux_sweeps))
