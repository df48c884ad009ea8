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
* :class:`AdjustedPL` -- the calibrated pseudolikelihood ``PL_adj(θ) = PL(c + W (θ -
  θ*))``, at the PL's cost per evaluation. ``align="mode"`` is the curvature- and
  mode-adjustment of Stoehr & Friel (2015) and Bouranis, Friel & Maire (2017):
  ``c = θ_PL``, ``θ* = θ_ML``, ``W = M⁻¹N`` with ``-∇² log PL(θ_PL) = MᵀM`` and
  ``I(θ_ML) = NᵀN``, so that its mode is the MLE and its Hessian there the Fisher
  information. ``align="moments"`` (the default) maps the PL posterior's mean and
  covariance onto the likelihood posterior's third-order mean ``θ_ML + δ`` and
  ``I⁻¹`` instead, so that the PL's skew does not move the mean. Either condition
  fixes ``W`` up to a rotation: ``affine="cholesky"`` (the default) takes the
  published Cholesky factors, which depend on the parameters' order;
  ``affine="transport"`` the symmetric square root (the optimal-transport map between
  the two Gaussians, :mod:`mrfpe.models.affine_maps`), the map that moves points least.
* :func:`mrfpe.models.bootstrap.parametric_bootstrap` -- the sampling distribution
  of the MPLE by simulating data at the MPLE and refitting (as R's ngspatial does).

Assumptions, and when it fails: the adjustment is exact for a Gaussian
posterior; it keeps the PL's *shape* beyond the first two moments (skewness and
tails are the PL's, so near a critical coupling on a small lattice the spread of
a skewed exact posterior is underestimated); it needs interior modes (an MPLE on
the box's face, e.g. for a configuration of one state only, is refused) and a
non-singular Fisher information (refused, naming the statistic that does not
vary); and the draws must come from a chain that has mixed (their number, burn-in
and thinning follow the measured autocorrelation time, :mod:`mrfpe.models.mixing`).
The PL posterior's spread is taken from its moments, not from its curvature at the
MPLE, which a kinked log PL (a BRDF scene's absolute-difference data terms) makes far
too large (:mod:`mrfpe.models.pl_spread`). A second mode of exp(PL) is mapped along by
the one affine map, not calibrated; one that the moments' importance sampler (started
at the MPLE) never met does not even enter the moments, unless they are taken from a
global sample of exp(PL) (``pl_sample``, e.g. PMC annealed from the box).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from scipy.optimize import minimize
from scipy.special import logsumexp

from mrfpe.models.affine_maps import mode_map, moment_map, transport_map
from mrfpe.models.draws import (
    Draws,
    _log_f_of,
    _step,
    fisher_information,
    posterior_mean_shift,
    simulate_draws,
)
from mrfpe.models.pl_spread import (
    PLMoments,
    hessian,
    pl_moments,
    sample_moments,
    start_covariance,
)
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.maximise import grid_size, maximise

__all__ = ["AdjustedPL", "Draws", "fisher_information", "hessian", "mcmc_mle",
           "simulate_draws", "transport_map"]


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
             tol: float = 0.05, seed: int = 0, metric: np.ndarray | None = None,
             max_step: float = 1.0, pilot_sweeps: int = 2000) -> MLEResult:
    """Geyer-Thompson Monte Carlo MLE from ``theta0``, iterated (see the module docstring).

    Stops when a step moves less than ``tol`` asymptotic standard errors in every
    coordinate (``converged``) or after ``max_iter`` rounds of ``n_draws`` draws
    (each from a chain whose autocorrelation time a pilot of at least ``pilot_sweeps``
    sweeps measures, :func:`simulate_draws`).

    ``metric`` (d, d), positive definite -- for :class:`AdjustedPL` the PL's negative
    Hessian at the MPLE -- limits each round's move ``Δ`` to ``sqrt(Δᵀ metric Δ) <=
    max_step``. The importance weights' ESS alone does not: draws that stay in one
    phase of a model near its critical coupling reweight smoothly to parameters whose
    lattices live in the other phase, and the undamped iterate then jumps between
    phases onto the box's face (measured on 10 x 10 Ising data sets at coupling 0.44).
    """
    A = None if metric is None else np.asarray(metric, dtype=np.float64)
    rng = np.random.default_rng(seed)
    b = np.asarray(lik.bounds, dtype=np.float64)
    M = int(getattr(lik, "n_observations", 1))
    theta = as_theta_batch(theta0, lik.ndim)[0].copy()
    sims, converged, it = 0, False, 0
    while it < max_iter:
        it += 1
        draws = simulate_draws(lik, theta, n_draws, seed=int(rng.integers(2**63)),
                               pilot_sweeps=pilot_sweeps)
        sims += draws.n_sweeps
        info = fisher_information(lik, draws)
        log_f = _log_f_of(lik, draws)
        lf0 = log_f(theta[None])[0]
        lx0 = float(lik.log_prob(theta)[0])

        def neg(t: np.ndarray, lf0: np.ndarray = lf0, lx0: float = lx0,
                log_f: Any = log_f, t0: np.ndarray = theta) -> float:
            if A is not None and (t - t0) @ A @ (t - t0) > max_step ** 2:
                return 1e300  # outside this round's step limit
            lw = log_f(t[None])[0] - lf0
            ess = math.exp(2 * logsumexp(lw) - logsumexp(2 * lw))
            if ess < lw.size / 5:  # outside the trust region of these draws
                return 1e300
            return -(float(lik.log_prob(t)[0]) - lx0 - M * (logsumexp(lw) - math.log(lw.size)))

        new = np.clip(_argmin_whitened(neg, theta, info), b[:, 0], b[:, 1])
        se = np.sqrt(np.diag(np.linalg.inv(info)))
        moved = np.abs(new - theta) / se
        theta = new
        if np.all(moved < tol):
            converged = True
            break
    cov = np.linalg.inv(info)
    return MLEResult(theta, cov, it, sims, converged, draws)


def _argmin_whitened(f: Any, theta: np.ndarray, info: np.ndarray) -> np.ndarray:
    """Nelder-Mead from ``theta`` in coordinates ``z = Lᵀ (t - theta)`` with ``info = L Lᵀ``.

    One unit of ``z`` is one asymptotic standard error in every direction, so the
    simplex (started half a unit wide) is well conditioned however differently the
    parameters are scaled; it stops at a thousandth of a standard error.
    """
    d = theta.size
    L = np.linalg.cholesky(info)

    def to_theta(z: np.ndarray) -> np.ndarray:
        return theta + np.linalg.solve(L.T, z)

    simplex = np.vstack([np.zeros(d), 0.5 * np.eye(d)])
    res = minimize(lambda z: f(to_theta(z)), np.zeros(d), method="Nelder-Mead",
                   options={"xatol": 1e-3, "fatol": 1e-8, "maxiter": 400 * d,
                            "initial_simplex": simplex})
    return to_theta(res.x)


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
    align : "moments" | "mode"
        ``"mode"`` (Bouranis et al. 2017): the adjusted target's mode is the MLE and
        its Hessian there the Fisher information. ``"moments"`` (default): its mean
        is the likelihood's posterior mean to third order -- the MLE plus the skew
        term ``δ = ½ Σ ℓ₃ Σ`` (Tierney & Kadane 1986), ``ℓ₃`` the log-likelihood's third
        derivatives from the simulations (:func:`~mrfpe.models.draws.posterior_mean_shift`:
        their cumulants and the expected derivatives of ``log f``, not the score's third
        cumulant alone, which holds only for models log-linear in ``θ``) -- and its
        covariance the inverse Fisher information: the PL
        posterior's mean and covariance (adaptive importance sampling of exp(PL),
        thousands of cheap PL evaluations) are mapped onto them. Where the
        posterior is skewed (near a critical coupling) the mode alignment carries
        the PL's skew into the mean: on 10 x 10 Ising data sets at couplings 0.3 and
        0.44 its mean was 0.4-0.9 exact sd off, the moment alignment's 0.0-0.4.
    affine : "cholesky" | "transport"
        Which ``W`` meets the alignment's condition (it fixes ``W`` up to a rotation).
        ``"cholesky"`` (default): from Cholesky factors, as Bouranis et al. (2017).
        ``"transport"``: the symmetric one
        (:func:`~mrfpe.models.affine_maps.transport_map`), which does not depend on the
        parameters' order and distorts least. Where the two spreads differ in
        shape, the Cholesky map can stretch the PL's box into a thin slab across the
        target's box: on a 100 x 100 Phong scene the calibrated target's support was
        0.06 % of its box (PMC's 4000 start points found none), the transport map's
        21 %. Both give the same mean and covariance; the shape beyond them differs.
    n_draws : int
        Simulations per Fisher information / MCMC-MLE round.
    max_rounds : int
        Most MCMC-MLE rounds (:func:`mcmc_mle`'s ``max_iter``).
    pilot_sweeps : int
        Shortest pilot chain measuring the simulator's autocorrelation time
        (:func:`simulate_draws`); it is at least 50 τ long whatever this says.
    seed : int
        Every simulation flows from it.
    pl_sample : posterior Dataset, optional
        A sample of exp(PL) (a sampler's result on ``pl``, e.g. PMC's, which anneals
        from the whole box): exp(PL)'s mean and covariance are its weighted ones
        (:func:`mrfpe.models.pl_spread.sample_moments`, which refuses an unreliable
        sample or one of another PL) instead of the importance sampler's from the
        MPLE. Give it where exp(PL) may have mass far from its mode: the importance
        sampler does not meet a mode tens of its sds away, and the calibration then
        maps the near mode's moments only.

    Attributes
    ----------
    theta_pl, theta_ml : the MPLE and the adjusted target's centre (with
        ``align="moments"``: the Monte Carlo MLE plus the posterior mean's third-order
        shift, so not ``mle.theta``; ``describe()["theta_mode"]``).
    bounds : the PL's box narrowed to the bounding box of the parameters that the map
        ``to_pl`` sends into it (the density is -inf at the others).
    pl_covariance : exp(PL)'s covariance (:func:`mrfpe.models.pl_spread.pl_moments`); its
        sds are the PL posterior's spread in the face test and the Monte Carlo MLE's step
        limit. ``pl_hessian`` (the curvature at the MPLE) is only its importance sampler's
        start: a BRDF scene's log PL is kinked, and its curvature is not its spread.
    fisher_information, W, mle : the calibration.
    """

    calibrated = True

    data_kind = "configurations"

    def __init__(self, pl: Any, lik: Any, *, mode: str = "mcmc_mle", align: str = "moments",
                 affine: str = "cholesky", n_draws: int = 1000, max_rounds: int = 10,
                 pilot_sweeps: int = 2000, seed: int = 0,
                 pl_sample: xr.Dataset | None = None) -> None:
        self._set_pl(pl)
        self.lik = lik
        if mode not in ("mcmc_mle", "mple"):
            raise ValueError(f"mode must be 'mcmc_mle' or 'mple'; got {mode!r}")
        if align not in ("mode", "moments"):
            raise ValueError(f"align must be 'mode' or 'moments'; got {align!r}")
        if affine not in ("cholesky", "transport"):
            raise ValueError(f"affine must be 'cholesky' or 'transport'; got {affine!r}")
        self.mode, self.align, self.affine = mode, align, affine
        self.mle = None
        given = None if pl_sample is None else sample_moments(pl, pl_sample)  # before the work
        b = self.bounds
        # a grid of at most 4096 points whatever the dimension, then the local polish
        theta_pl, lp_pl = maximise(pl, grid=max(3, grid_size(4096, b.shape[0])), seed=seed)
        self._check_interior(theta_pl, np.zeros(b.shape[0]))
        H = self._curvature(theta_pl)
        rng = np.random.default_rng(seed)
        s_mle = int(rng.integers(2**63))
        mom = given if given is not None else _pl_moments(pl, theta_pl, H, b, rng, align)
        if mom is not None and mom.best_log_prob > lp_pl + 1e-3:  # the maximiser stopped short
            theta_pl, lp_pl = maximise(pl, grid=np.stack([theta_pl, mom.best_theta]), n_starts=2)
            H = self._curvature(theta_pl)
        if align == "mode" and _cholesky_or_none(H) is None:
            raise ValueError(f"the PL's Hessian is not negative definite at the MPLE "
                             f"{theta_pl.round(4).tolist()} (eigenvalues of its negative "
                             f"{np.linalg.eigvalsh(H).round(3).tolist()}), which align='mode' "
                             f"needs: a saddle where the maximiser stopped (a negative "
                             f"eigenvalue), a ridge of {list(self.param_names)} the data do "
                             f"not identify (a zero one), or a kinked PL (use align='moments')")
        # the PL posterior's spread: its moments where they could be estimated (a kinked
        # log PL's curvature is not its spread, mrfpe.models.pl_spread), else the curvature
        pl_cov = mom.covariance if mom is not None else np.linalg.inv(H)
        self._check_interior(theta_pl, np.sqrt(np.diag(pl_cov)))
        if mode == "mcmc_mle":
            res = mcmc_mle(lik, theta_pl, n_draws=n_draws, seed=s_mle,
                           metric=np.linalg.inv(pl_cov), max_iter=max_rounds,
                           pilot_sweeps=pilot_sweeps)
            theta_ml, info, sims = res.theta, np.linalg.inv(res.covariance), res.n_simulations
            self.mle = res
        else:
            draws = simulate_draws(lik, theta_pl, n_draws, seed=s_mle, pilot_sweeps=pilot_sweeps)
            info, sims = fisher_information(lik, draws), draws.n_sweeps
            theta_ml = theta_pl
        centre, W = ((theta_pl, mode_map(H, info, affine)) if align == "mode"
                     else (mom.mean, moment_map(pl_cov, info, affine)))
        if align == "moments" and self.mle is not None:
            # mean = MLE + the likelihood's skew (third-order Laplace expansion)
            theta_ml = theta_ml + posterior_mean_shift(lik, self.mle.draws, theta_ml, info)
        self._set_map(centre, W, theta_ml, theta_pl)
        self.fisher_information, self.pl_hessian, self.pl_covariance = info, H, pl_cov
        self.n_simulation_sweeps = int(sims)
        self.pl_moments_from = "sample" if pl_sample is not None else "importance"

    @classmethod
    def restore(cls, pl: Any, *, centre: Any, W: Any, theta_ml: Any,
                theta_pl: Any) -> AdjustedPL:
        """The target of an earlier calibration, from its map (``centre``, ``W``,
        ``theta_ml``, ``theta_pl``, as :meth:`describe` and saved results hold them):
        the same log-density without simulating again. The calibration's statistics
        (``fisher_information``, ``mle``, ``pl_covariance``, ...) are not restored."""
        self = cls.__new__(cls)
        self._set_pl(pl)
        self.lik = self.mode = self.align = self.affine = self.mle = None
        self.pl_moments_from = None
        self.fisher_information = self.pl_hessian = self.pl_covariance = None
        self.n_simulation_sweeps = 0
        self._set_map(*(np.array(v, dtype=np.float64) for v in (centre, W, theta_ml, theta_pl)))
        return self

    def _set_pl(self, pl: Any) -> None:
        self.pl = pl
        self.param_names = tuple(pl.param_names)
        self.bounds = np.asarray(pl.bounds, dtype=np.float64)
        self.name = getattr(pl, "name", "pl").replace(":pl", "") + ":pl_adjusted"
        self.cost = float(getattr(pl, "cost", 1.0))

    def _set_map(self, centre: np.ndarray, W: np.ndarray, theta_ml: np.ndarray,
                 theta_pl: np.ndarray) -> None:
        self.centre, self.W, self.theta_ml, self.theta_pl = centre, W, theta_ml, theta_pl
        self._offset = float(self.pl._log_prob(theta_pl[None])[0])
        # the density is -inf where the map leaves the PL's box: narrow the bounds to the
        # bounding box of the rest, so that a sampler's first draws can find the support
        A, b = np.linalg.inv(W), np.asarray(self.pl.bounds, dtype=np.float64)
        ends = A[:, :, None] * (b - centre[:, None])[None]  # (d, d, 2)
        box = np.stack([theta_ml + ends.min(axis=2).sum(axis=1),
                        theta_ml + ends.max(axis=2).sum(axis=1)], axis=1)
        box = np.stack([np.maximum(box[:, 0], b[:, 0]), np.minimum(box[:, 1], b[:, 1])], axis=1)
        self.bounds = box if np.all(box[:, 0] < box[:, 1]) else b

    def _check_interior(self, theta_pl: np.ndarray, sd: np.ndarray) -> None:
        """Refuse an MPLE on the box's face or within one PL sd of it."""
        b = self.bounds
        dist = np.minimum(theta_pl - b[:, 0], b[:, 1] - theta_pl)
        edge = (dist < 1e-6 * (b[:, 1] - b[:, 0])) | (dist < sd)
        if edge.any():
            raise ValueError(f"the MPLE lies on (or within one PL sd of) the bounds' face for "
                             f"{[self.param_names[i] for i in np.flatnonzero(edge)]} "
                             f"(theta {theta_pl.round(4).tolist()}"
                             + (f", PL sd {sd.round(4).tolist()}" if sd.any() else "")
                             + "): the adjustment needs an interior mode "
                             "(widen the bounds, or the data carry no information on these "
                             "parameters)")

    def _curvature(self, theta_pl: np.ndarray) -> np.ndarray:
        """The PL's negative Hessian at the MPLE (refused where it is not finite)."""
        H = -hessian(self.pl._log_prob, theta_pl, _step(self.pl, theta_pl))
        if not np.all(np.isfinite(H)):
            raise ValueError(f"the PL's Hessian at the MPLE {theta_pl.round(4).tolist()} is not "
                             f"finite: the MPLE is at the edge of the model's valid region")
        return H

    def to_pl(self, theta: Any) -> np.ndarray:
        """The PL's argument for adjusted parameters: ``c + W (θ - θ_ML)``.

        ``c`` is the MPLE (``align="mode"``) or the PL posterior's mean (``"moments"``).
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        return self.centre + (theta - self.theta_ml) @ self.W.T

    def _row_bytes(self) -> float:
        return self.pl._row_bytes()

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        # exp(PL) lives on its box (its moments were taken there): a parameter the map
        # sends outside it has no density, however the PL's formula extrapolates
        z = self.to_pl(theta)
        out = np.full(z.shape[0], -np.inf)
        inside = self.pl.in_bounds(z)
        if inside.any():
            out[inside] = self.pl._log_prob(z[inside]) - self._offset
        return out

    def describe(self) -> dict:
        return {**self.pl.describe(), "name": self.name, "class": type(self).__name__,
                "estimator": "pl_adjusted", "mode": self.mode, "align": self.align,
                "affine": self.affine,
                "theta_mple": self.theta_pl.tolist(), "theta_mode": self.theta_ml.tolist(),
                "centre": self.centre.tolist(), "W": self.W.tolist(),
                "n_simulation_sweeps": self.n_simulation_sweeps,
                "pl_moments_from": self.pl_moments_from}


def _pl_moments(pl: Any, theta_pl: np.ndarray, H: np.ndarray, bounds: np.ndarray,
                rng: np.random.Generator, align: str) -> PLMoments | None:
    """exp(PL)'s moments importance-sampled from the MPLE (None where that fails and
    ``align="mode"`` does not need them)."""
    try:
        return pl_moments(pl, theta_pl, start_covariance(H, bounds), rng)
    except ValueError as err:
        if align == "moments":
            raise ValueError(f"{err}: exp(PL) is far from one Gaussian (a curved ridge "
                             f"or several modes), which the moment alignment cannot map; "
                             f"align='mode' calibrates the curvature at the MPLE only, and "
                             f"PMC on exp(PL) shows its shape") from None
        return None


def _cholesky_or_none(H: np.ndarray) -> np.ndarray | None:
    """``M`` with ``H = MᵀM``, or None where ``H`` is not positive definite."""
    try:
        return np.linalg.cholesky(H).T
    except np.linalg.LinAlgError:
        return None
