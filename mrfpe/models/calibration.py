"""Calibrated pseudo-posteriors and Monte Carlo maximum likelihood, from a model's simulator.

``exp(PL(θ))`` is not the posterior of a model whose normaliser is intractable:
its mode is the maximum pseudolikelihood estimate (MPLE), not the MLE, and its
curvature is not the likelihood's. With a simulator both can be corrected:

* :func:`fisher_information` -- ``I(θ) = M Cov_y[∇_θ log f(y | θ)]`` from draws
  ``y ~ p(· | θ)`` (for a log-linear model the covariance of the sufficient
  statistics);
* :func:`mcmc_mle` -- Geyer & Thompson's (1992) Monte Carlo MLE: with draws at
  ``θ0``, ``ℓ(θ) - ℓ(θ0) ≈ log f(x|θ) - log f(x|θ0) - M log mean_k exp(log
  f(y_k|θ) - log f(y_k|θ0))``, maximised inside the region where the importance
  weights keep an effective sample size of at least a fifth of the draws, and
  iterated from the new point until it stops moving;
* :class:`AdjustedPL` -- the curvature- and mode-adjusted pseudolikelihood of
  Stoehr & Friel (2015) and Bouranis, Friel & Maire (2017):
  ``PL_adj(θ) = PL(θ_PL + W (θ - θ_ML))`` with ``W = M⁻¹N``, where ``-∇²
  log PL(θ_PL) = MᵀM`` and ``I(θ_ML) = NᵀN``, so that its mode is the MLE and its
  Hessian there is the Fisher information. With a flat prior it is a Gaussian-
  accurate approximation of the posterior, at the PL's cost per evaluation.
* :func:`parametric_bootstrap` -- the sampling distribution of the MPLE by
  simulating data at the MPLE and refitting (as R's ngspatial does).

Assumptions, and when it fails: the adjustment is exact for a Gaussian
posterior; it keeps the PL's *shape* beyond the curvature (skewness and tails
are the PL's); it needs interior modes (an MPLE on the box's face, e.g. for a
configuration of one state only, is refused) and a non-singular Fisher
information (refused, naming the statistic that does not vary); and the draws
must come from a chain that has mixed (their number, burn-in and thinning
follow the measured autocorrelation time, :mod:`mrfpe.models.mixing`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp

from mrfpe.models.mixing import autocorrelation_time
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.maximise import maximise

__all__ = ["AdjustedPL", "Draws", "fisher_information", "mcmc_mle", "parametric_bootstrap",
           "simulate_draws"]


@dataclass(frozen=True)
class Draws:
    """Draws ``y_k ~ p(· | θ)`` of one configuration each, with the chain's settings."""

    theta: np.ndarray
    y: np.ndarray  # (K, n_nodes)
    tau: float
    burn_in: int
    thin: int

    @property
    def n_sweeps(self) -> int:
        return int(self.burn_in + self.thin * (self.y.shape[0] - 1))


def simulate_draws(lik: Any, theta: Any, n_draws: int, *, seed: int) -> Draws:
    """``n_draws`` configurations at ``theta`` from one chain started at the data.

    Exact simulators give independent draws; otherwise the chain's autocorrelation
    time ``τ`` is measured first, then the chain runs ``max(10 τ, 10)`` sweeps of
    burn-in and keeps a draw every ``max(1, ⌈τ⌉)`` sweeps.
    """
    th = as_theta_batch(theta, lik.ndim)[0]
    rng = np.random.default_rng(seed)
    if getattr(lik, "exact_simulator", False):
        y = lik.simulate(th, n=n_draws, seed=int(rng.integers(2**63)))
        return Draws(th, np.asarray(y), 0.0, 0, 1)
    tau = autocorrelation_time(lik, th, seed=int(rng.integers(2**63)))
    if not math.isfinite(tau):
        raise ValueError(f"the model's simulator does not mix at theta {th.tolist()}: its "
                         f"autocorrelation time exceeds the pilot run (use a simulator that "
                         f"mixes, e.g. sampler='swendsen_wang' for Potts models)")
    burn, thin = max(10, math.ceil(10 * tau)), max(1, math.ceil(tau))
    y = lik.simulate(th, n=n_draws, seed=int(rng.integers(2**63)), init=lik.x[0],
                     n_sweeps=burn, thin=thin)
    return Draws(th, np.asarray(y), tau, burn, thin)


def _log_f_of(lik: Any, y: np.ndarray) -> Any:
    """``theta (N, d) -> log f(y_k | θ_j)`` (N, K) for draws ``y`` of one configuration each.

    For a design model the draws' sufficient statistics are computed once, so each
    call is one matrix product.
    """
    stats = getattr(lik, "sufficient_statistics", None)
    design = getattr(lik, "design", None)
    if callable(stats) and design is not None:
        S = stats(y).T
        return lambda theta: design.psi(theta) @ S
    return lambda theta: np.stack([lik.unnormalised(theta, yk[None]) for yk in y], axis=1)


def _log_f(lik: Any, theta: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``log f(y_k | θ_j)`` (N, K) for a batch of θ and draws of one configuration each."""
    return _log_f_of(lik, y)(theta)


def _scores(lik: Any, theta: np.ndarray, y: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``∇_θ log f(y_k | θ)`` (K, d) by central differences (exact for log-linear models)."""
    d = theta.size
    steps = np.concatenate([theta + np.diag(h), theta - np.diag(h)])
    lf = _log_f(lik, steps, y)  # (2d, K)
    return ((lf[:d] - lf[d:]) / (2 * h)[:, None]).T


def _step(lik: Any) -> np.ndarray:
    b = np.asarray(lik.bounds, dtype=np.float64)
    return 1e-4 * (b[:, 1] - b[:, 0])


def fisher_information(lik: Any, draws: Draws) -> np.ndarray:
    """``I(θ) = M Cov_k[∇ log f(y_k | θ)]`` (d, d) at the draws' θ (M observations).

    Raises ValueError naming the parameter whose score does not vary (a singular
    information: the data cannot identify it).
    """
    s = _scores(lik, draws.theta, draws.y, _step(lik))
    cov = np.atleast_2d(np.cov(s, rowvar=False))
    M = int(getattr(lik, "n_observations", 1))
    info = M * cov
    names = list(lik.param_names)
    flat = np.flatnonzero(np.diag(info) <= 1e-12 * max(1.0, np.abs(info).max()))
    if flat.size:
        raise ValueError(f"the Fisher information is singular at theta {draws.theta.tolist()}: "
                         f"the score of {names[flat[0]]!r} does not vary over "
                         f"{draws.y.shape[0]} simulations (the data cannot identify it)")
    w = np.linalg.eigvalsh(info)
    if w[0] <= 1e-10 * w[-1]:
        raise ValueError(f"the Fisher information is singular at theta {draws.theta.tolist()} "
                         f"(condition number {w[-1] / max(w[0], 1e-300):.3g}): some combination "
                         f"of {names} is not identified by the data")
    return info


@dataclass(frozen=True)
class MLEResult:
    """An MCMC-MLE: the estimate, its asymptotic covariance and what it cost."""

    theta: np.ndarray
    covariance: np.ndarray
    n_iterations: int
    n_simulations: int
    converged: bool
    draws: Draws

    @property
    def se(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def mcmc_mle(lik: Any, theta0: Any, *, n_draws: int = 1000, max_iter: int = 10,
             tol: float = 0.05, seed: int = 0) -> MLEResult:
    """Geyer-Thompson Monte Carlo MLE from ``theta0``, iterated (see the module docstring).

    Stops when a step moves less than ``tol`` asymptotic standard errors in every
    coordinate (``converged``) or after ``max_iter`` rounds of ``n_draws`` draws.
    """
    rng = np.random.default_rng(seed)
    b = np.asarray(lik.bounds, dtype=np.float64)
    M = int(getattr(lik, "n_observations", 1))
    theta = as_theta_batch(theta0, lik.ndim)[0].copy()
    sims, converged, it = 0, False, 0
    while it < max_iter:
        it += 1
        draws = simulate_draws(lik, theta, n_draws, seed=int(rng.integers(2**63)))
        sims += draws.n_sweeps
        info = fisher_information(lik, draws)
        log_f = _log_f_of(lik, draws.y)
        lf0 = log_f(theta[None])[0]
        lx0 = float(lik.log_prob(theta)[0])

        def neg(t: np.ndarray, lf0: np.ndarray = lf0, lx0: float = lx0,
                log_f: Any = log_f) -> float:
            lw = log_f(t[None])[0] - lf0
            ess = math.exp(2 * logsumexp(lw) - logsumexp(2 * lw))
            if ess < lw.size / 5:  # outside the trust region of these draws
                return 1e300
            return -(float(lik.log_prob(t)[0]) - lx0 - M * (logsumexp(lw) - math.log(lw.size)))

        res = minimize(neg, theta, method="Nelder-Mead",
                       options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 400 * lik.ndim})
        new = np.clip(res.x, b[:, 0], b[:, 1])
        se = np.sqrt(np.diag(np.linalg.inv(info)))
        moved = np.abs(new - theta) / se
        theta = new
        if np.all(moved < tol):
            converged = True
            break
    cov = np.linalg.inv(info)
    return MLEResult(theta, cov, it, sims, converged, draws)


def _hessian(f: Any, theta: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central-difference Hessian of a batched scalar function at ``theta``."""
    d = theta.size
    E = np.diag(h)
    pts = [theta]
    for i in range(d):
        for j in range(d):
            pts += [theta + E[i] + E[j], theta + E[i] - E[j], theta - E[i] + E[j],
                    theta - E[i] - E[j]]
    v = f(np.array(pts))
    H = np.empty((d, d))
    k = 1
    for i in range(d):
        for j in range(d):
            a, b_, c, e = v[k:k + 4]
            H[i, j] = (a - b_ - c + e) / (4 * h[i] * h[j])
            k += 4
    return 0.5 * (H + H.T)


class AdjustedPL(Target):
    """The mode- and curvature-adjusted pseudolikelihood (see the module docstring).

    Parameters
    ----------
    pl : a ``"pl"`` target of the model (its ``_log_prob`` is evaluated anywhere).
    lik : the model's ``"likelihood"`` target (simulator and unnormalised likelihood).
    mode : "mcmc_mle" | "mple"
        Where the adjusted target peaks: the Monte Carlo MLE (default) or the
        MPLE (curvature only; Stoehr & Friel's curvature adjustment). A single
        Fisher-scoring step from the MPLE is not offered: near the critical
        coupling it overshoots by many posterior sd (measured on an 8 x 8 Ising).
    n_draws : int
        Simulations per Fisher information / MCMC-MLE round.
    seed : int
        Every simulation flows from it.
    """

    data_kind = "configurations"

    def __init__(self, pl: Any, lik: Any, *, mode: str = "mcmc_mle", n_draws: int = 1000,
                 seed: int = 0) -> None:
        self.pl, self.lik = pl, lik
        self.param_names = tuple(pl.param_names)
        self.bounds = np.asarray(pl.bounds, dtype=np.float64)
        self.name = getattr(pl, "name", "pl").replace(":pl", "") + ":pl_adjusted"
        self.cost = float(getattr(pl, "cost", 1.0))
        if mode not in ("mcmc_mle", "mple"):
            raise ValueError(f"mode must be 'mcmc_mle' or 'mple'; got {mode!r}")
        self.mode = mode
        self.mle = None
        b = self.bounds
        # a grid of at most ~4096 points whatever the dimension, then the local polish
        theta_pl, _ = maximise(pl, grid=max(3, int(4096 ** (1 / b.shape[0]))), seed=seed)
        h = _step(pl)
        H = -_hessian(pl._log_prob, theta_pl, h)
        dist = np.minimum(theta_pl - b[:, 0], b[:, 1] - theta_pl)
        try:
            m_chol = np.linalg.cholesky(H).T  # H = MᵀM
            sd = np.sqrt(np.diag(np.linalg.inv(H)))
        except np.linalg.LinAlgError:
            m_chol, sd = None, np.full(b.shape[0], np.inf)
        edge = (dist < 1e-6 * (b[:, 1] - b[:, 0])) | (dist < sd)
        if edge.any():
            raise ValueError(f"the MPLE lies on (or within one PL sd of) the bounds' face for "
                             f"{[self.param_names[i] for i in np.flatnonzero(edge)]} "
                             f"(theta {theta_pl.round(4).tolist()}): the adjustment needs an "
                             f"interior mode (widen the bounds, or the data carry no "
                             f"information on these parameters)")
        if m_chol is None:
            raise ValueError(f"the PL's Hessian is not negative definite at the MPLE "
                             f"{theta_pl.round(4).tolist()}: no curvature to adjust")
        rng = np.random.default_rng(seed)
        if mode == "mcmc_mle":
            res = mcmc_mle(lik, theta_pl, n_draws=n_draws, seed=int(rng.integers(2**63)))
            theta_ml, info, sims = res.theta, np.linalg.inv(res.covariance), res.n_simulations
            self.mle = res
        else:
            draws = simulate_draws(lik, theta_pl, n_draws, seed=int(rng.integers(2**63)))
            info, sims = fisher_information(lik, draws), draws.n_sweeps
            theta_ml = theta_pl
        n_chol = np.linalg.cholesky(info).T  # I = NᵀN
        self.theta_pl, self.theta_ml = theta_pl, theta_ml
        self.W = np.linalg.solve(m_chol, n_chol)
        self.fisher_information, self.pl_hessian = info, H
        self.n_simulation_sweeps = int(sims)
        self._offset = float(pl._log_prob(theta_pl[None])[0])

    def to_pl(self, theta: Any) -> np.ndarray:
        """The PL's argument for adjusted parameters: ``θ_PL + W (θ - θ_ML)``."""
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        return self.theta_pl + (theta - self.theta_ml) @ self.W.T

    def _row_bytes(self) -> float:
        return self.pl._row_bytes()

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return self.pl._log_prob(self.to_pl(theta)) - self._offset

    def describe(self) -> dict:
        return {**self.pl.describe(), "name": self.name, "class": type(self).__name__,
                "estimator": "pl_adjusted", "mode": self.mode,
                "theta_mple": self.theta_pl.tolist(), "theta_mode": self.theta_ml.tolist(),
                "W": self.W.tolist(), "n_simulation_sweeps": self.n_simulation_sweeps}


def parametric_bootstrap(model: Any, data: Any, *, n_boot: int = 200, estimator: str = "pl",
                         seed: int = 0, **options: Any) -> Any:
    """Parametric-bootstrap distribution of the maximiser of ``estimator`` (default the MPLE).

    Fits the data, simulates ``n_boot`` data sets of the same size at the
    estimate with the model's simulator, refits each; returns a posterior-schema
    Dataset of ``kind="optima"`` (the refits; their quantiles are the bootstrap
    intervals) with the original estimate as ``map_theta``.
    """
    from mrfpe.posterior import build

    rng = np.random.default_rng(seed)
    target = model.target(estimator, data, **options)
    grid = max(3, int(4096 ** (1 / target.ndim)))
    theta_hat, value = maximise(target, grid=grid, seed=int(rng.integers(2**31)))
    lik = model.target("likelihood", data, **{k: v for k, v in options.items()
                                               if k in ("covariates", "bounds")})
    draws = simulate_draws(lik, theta_hat, n_boot * lik.n_observations,
                           seed=int(rng.integers(2**63)))
    from mrfpe.models.graph import LatticeSpec

    lattice = isinstance(getattr(model, "graph_spec", None), LatticeSpec)
    shape = tuple(np.shape(data)[-2:]) if lattice else (lik.x.shape[1],)
    fits, values = [], []
    for k in range(n_boot):
        yk = draws.y[k * lik.n_observations:(k + 1) * lik.n_observations]
        tk = model.target(estimator, yk.reshape(-1, *shape), **options)
        t, v = maximise(tk, grid=grid, seed=int(rng.integers(2**31)))
        fits.append(t)
        values.append(v)
    return build(np.array(fits), np.array(values), param_names=target.param_names,
                 map_theta=theta_hat[None], map_log_target=np.array([value]),
                 sampler="parametric_bootstrap", kind="optima", target=target,
                 config={"n_boot": n_boot, "estimator": estimator}, seed=seed,
                 extra_attrs={"simulation_sweeps": draws.n_sweeps, "tau": draws.tau})
