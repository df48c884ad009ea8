"""Sandwich (Godambe) standard errors and Wald intervals for a composite-likelihood estimate.

A composite likelihood ``CL(θ; x) = Π_k p(x_{A_k} | x_{B_k}; θ)`` -- Besag's
pseudolikelihood (``"pl"``), a coding likelihood (``"coding"``) or a block
pseudolikelihood (``"block"``) -- is maximised at ``θ̂``, an unbiased estimating
equation ``∇ log CL(θ̂; x) = 0``. Its sampling covariance is not the inverse curvature
``H⁻¹`` (what ``exp(CL)`` as a "posterior" reports) but the inverse Godambe information
(Godambe 1960; Lindsay 1988; Varin, Reid & Firth 2011, Statistica Sinica 21, 5-42, eq. 4)

    ``G(θ) = H(θ) J(θ)⁻¹ H(θ)``,   ``Var θ̂ ≈ G⁻¹ = H⁻¹ J H⁻¹``,

with the *sensitivity* ``H = -∇² log CL(θ̂; x)`` and the *variability* ``J = Var_θ[∇ log
CL(θ; X)]``. For a full likelihood ``J = H`` (the information identity) and ``G = H``; the
conditionals of a pseudolikelihood overlap, so their scores are correlated and ``J ≠ H``.

Estimating ``J``. A lattice is one observation: the score's variance cannot be taken
over replicates of the data. Two routes are usual: spatial block resampling of the
score's per-site contributions (a subsampling variance in the spirit of Heagerty &
Lele 1998), and simulation from the fitted model (Hughes, Haran & Caragea 2011, the
parametric route of R's ngspatial for the autologistic MPLE). This module simulates:
every declared model has a simulator, so ``J`` is estimated without tuning a block size
-- whose bias near a critical coupling, where correlations reach across the lattice, is
the block approach's weakness -- and without edge effects, and the Monte Carlo error
shrinks as ``1/√K`` with the number ``K`` of simulated fields. The price is that ``J`` is
the model's at ``θ̂``: a misspecified model's own variability is not captured (block
resampling would capture it). Draws come from :func:`~mrfpe.models.draws.simulate_draws`
(exact draws for the auto-normal model, a chain whose burn-in and thinning follow its
autocorrelation time otherwise), one field each, and ``J = M Cov_k[∇ log CL(θ̂; y_k)]``
for data of ``M`` independent fields.

``H`` is the observed curvature at the data by default (``curvature="observed"``), or its
expectation over the simulated fields (``"expected"``). The scores and Hessians are
central differences (:func:`~mrfpe.models.pl_spread.hessian`; the log CLs are smooth).
The Monte Carlo error of each standard error is a grouped jackknife over the draws.
For a coding likelihood, a true conditional likelihood, ``J`` equals the expected ``H``:
the result's ``expected_sensitivity`` gives that check.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import norm

from mrfpe.models.draws import _step, check_score_variance, simulate_draws
from mrfpe.models.pl_spread import hessian
from mrfpe.targets.base import as_theta_batch
from mrfpe.targets.maximise import grid_size, maximise
from mrfpe.validation import check_choice, check_positive_int, check_range, check_seed

__all__ = ["COMPOSITE_ESTIMATORS", "GodambeResult", "godambe"]

#: The estimators whose targets are composite likelihoods of conditionals.
COMPOSITE_ESTIMATORS = ("pl", "coding", "block")
#: Groups of the jackknife that estimates the standard errors' Monte Carlo error.
JACKKNIFE_GROUPS = 20


@dataclass(frozen=True)
class GodambeResult:
    """A composite-likelihood estimate with its sandwich and naive covariances.

    ``covariance`` is ``G⁻¹ = H⁻¹ J H⁻¹``; ``naive_covariance`` is ``H⁻¹`` (exp(CL)'s
    curvature). ``se_mc_error`` is the Monte Carlo standard error of ``se`` from the
    ``n_draws`` simulated fields; ``scores`` (n_draws, d) are the per-field scores at
    ``theta`` and ``expected_sensitivity`` the mean of ``-∇² log CL`` over the same
    fields (times ``n_observations``).
    """

    param_names: tuple[str, ...]
    theta: np.ndarray
    sensitivity: np.ndarray
    variability: np.ndarray
    covariance: np.ndarray
    naive_covariance: np.ndarray
    se_mc_error: np.ndarray
    expected_sensitivity: np.ndarray
    scores: np.ndarray = field(repr=False)
    level: float = 0.9
    estimator: str = "pl"
    curvature: str = "observed"
    n_observations: int = 1
    simulation: dict = field(default_factory=dict)

    @property
    def n_draws(self) -> int:
        return int(self.scores.shape[0])

    @property
    def godambe_information(self) -> np.ndarray:
        """``G = H J⁻¹ H``."""
        return self.sensitivity @ np.linalg.solve(self.variability, self.sensitivity)

    @property
    def se(self) -> np.ndarray:
        """Sandwich standard errors ``sqrt(diag(G⁻¹))``."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def naive_se(self) -> np.ndarray:
        """The curvature's standard errors ``sqrt(diag(H⁻¹))``."""
        return np.sqrt(np.diag(self.naive_covariance))

    def interval(self, level: float | None = None, *, naive: bool = False) -> np.ndarray:
        """Wald intervals ``θ̂ ± z_{(1+level)/2} se`` (d, 2), sandwich or ``naive``."""
        lev = self.level if level is None else check_range("level", level, 0.0, 1.0,
                                                           low_open=True, high_open=True)
        z = float(norm.ppf(0.5 + 0.5 * lev))
        se = self.naive_se if naive else self.se
        return np.stack([self.theta - z * se, self.theta + z * se], axis=1)

    def describe(self) -> dict:
        """A JSON-serialisable summary (lists and floats)."""
        ci, naive = self.interval(), self.interval(naive=True)
        return {"estimator": self.estimator, "param_names": list(self.param_names),
                "theta": self.theta.tolist(), "se": self.se.tolist(),
                "naive_se": self.naive_se.tolist(), "se_mc_error": self.se_mc_error.tolist(),
                "level": self.level, "interval": ci.tolist(), "naive_interval": naive.tolist(),
                "sensitivity": self.sensitivity.tolist(), "variability": self.variability.tolist(),
                "covariance": self.covariance.tolist(), "curvature": self.curvature,
                "n_draws": self.n_draws, "n_observations": self.n_observations,
                "simulation": dict(self.simulation)}

    def to_dict(self) -> dict:
        """Alias of :meth:`describe`."""
        return self.describe()

    def __repr__(self) -> str:
        ci = self.interval()
        pct = f"{100 * self.level:g}%"
        w = max(len(n) for n in self.param_names)
        lines = [f"GodambeResult({self.estimator!r}, {self.n_draws} simulated fields, "
                 f"curvature {self.curvature!r})",
                 f"  {'':<{w}}  {'estimate':>9}  {'se':>8}  {'± mc':>7}  {'naive se':>8}  "
                 f"{pct + ' interval':>22}"]
        for j, n in enumerate(self.param_names):
            lines.append(f"  {n:<{w}}  {self.theta[j]:>9.4g}  {self.se[j]:>8.4g}  "
                         f"{self.se_mc_error[j]:>7.2g}  {self.naive_se[j]:>8.4g}  "
                         f"[{ci[j, 0]:>9.4g}, {ci[j, 1]:>9.4g}]")
        return "\n".join(lines)


def godambe(target: Any, theta_hat: Any = None, *, n_draws: int = 400, seed: int | None = 0,
            level: float = 0.9, curvature: str = "observed",
            simulator: Any = None) -> GodambeResult:
    """Sandwich covariance ``H⁻¹ J H⁻¹`` and Wald intervals of a composite-likelihood estimate.

    Parameters
    ----------
    target : a ``"pl"``, ``"coding"`` or ``"block"`` target of a declared model
        (``model.target(estimator, x)``: a discrete MRF's or the auto-normal model's).
    theta_hat : (d,) array, optional
        The maximum composite-likelihood estimate; by default it is found with
        :func:`mrfpe.targets.maximise` (a grid of at most 4096 points, then a local search).
        It must lie inside the box, off its faces.
    n_draws : int
        Fields simulated at ``theta_hat`` to estimate ``J`` (at least ``max(50, 10 d)``).
    seed : int or None
        Every random choice (the maximiser's, the simulator's) flows from it.
    level : float in (0, 1)
        Coverage of the Wald intervals ``θ̂ ± z_{(1+level)/2} sqrt(diag(G⁻¹))``.
    curvature : 'observed' | 'expected'
        ``H`` at the data, or its mean over the simulated fields.
    simulator : target, optional
        A ``"likelihood"`` target of the same model and data to draw from (e.g. with another
        sampler); by default one is built from the target's model.

    Returns
    -------
    GodambeResult

    Raises
    ------
    ValueError
        Naming the argument: a target that is no composite likelihood, a ``theta_hat``
        outside the box or on its face (no interior curvature there), too few draws, a
        curvature that is not negative definite, or a variability that is singular.

    Examples
    --------
    >>> from mrfpe import models
    >>> m = models.ising()
    >>> x = m.simulate([0.3, 0.0], shape=(12, 12), n_sweeps=200, seed=1)
    >>> res = godambe(m.target("pl", x), n_draws=100, seed=0)
    >>> res.interval().shape
    (2, 2)
    """
    est = _check_target(target)
    n_draws, seed, level, curvature = _check_arguments(target.ndim, n_draws, seed, level,
                                                       curvature)
    lik = _simulator(target) if simulator is None else _check_simulator(simulator, target)
    rng = np.random.default_rng(seed)
    if theta_hat is None:
        grid = max(3, grid_size(4096, target.ndim))
        theta_hat, _ = maximise(target, grid=grid, seed=int(rng.integers(2**31)))
    theta = _check_theta(target, theta_hat)
    h = _step(target, theta)
    H_obs = -hessian(target.log_prob, theta, h)
    draws = simulate_draws(lik, theta, n_draws, seed=int(rng.integers(2**63)))
    M = int(target.x.shape[0])
    scores, hess = _draw_derivatives(target, draws.y, theta, h)
    hess = M * hess  # per field, scaled to the data's M fields
    H_exp = hess.mean(axis=0)
    H = H_obs if curvature == "observed" else H_exp
    _check_curvature(target, theta, H, curvature)
    J = M * np.atleast_2d(np.cov(scores, rowvar=False))
    check_score_variance(J, list(target.param_names), "the variability J",
                         f"{n_draws} simulated fields")
    _check_score_mean(target, scores, theta)
    Hinv = np.linalg.inv(H)
    cov = Hinv @ J @ Hinv
    mc = _jackknife_se(scores, M, Hinv if curvature == "observed" else None,
                       None if curvature == "observed" else hess)
    return GodambeResult(param_names=tuple(target.param_names), theta=theta,
                         sensitivity=H, variability=J, covariance=0.5 * (cov + cov.T),
                         naive_covariance=Hinv, se_mc_error=mc, expected_sensitivity=H_exp,
                         scores=scores, level=level, estimator=est, curvature=curvature,
                         n_observations=M,
                         simulation={"tau": float(draws.tau), "burn_in": int(draws.burn_in),
                                     "thin": int(draws.thin), "n_sweeps": draws.n_sweeps,
                                     "seed": seed})


def _check_arguments(d: int, n_draws: Any, seed: Any, level: Any,
                     curvature: Any) -> tuple[int, int | None, float, str]:
    n_draws = check_positive_int("n_draws", n_draws)
    if n_draws < max(50, 10 * d):
        raise ValueError(f"n_draws must be at least {max(50, 10 * d)} (max(50, 10 per "
                         f"parameter)) to estimate the {d} x {d} variability J; got {n_draws}")
    return (n_draws, check_seed(seed),
            check_range("level", level, 0.0, 1.0, low_open=True, high_open=True),
            check_choice("curvature", curvature, ("observed", "expected")))


def _check_target(target: Any) -> str:
    """The target's estimator, or ValueError naming ``target``."""
    from mrfpe.models.estimators import ConditionalTarget
    from mrfpe.models.gaussian.pseudolikelihood import GaussianBlockTarget, GaussianPLTarget

    est = getattr(target, "estimator", None)
    ok = isinstance(target, ConditionalTarget | GaussianPLTarget | GaussianBlockTarget)
    if not ok or est not in COMPOSITE_ESTIMATORS:
        what = getattr(target, "name", type(target).__name__)
        raise ValueError(f"target must be a composite likelihood of a declared model (its "
                         f"'pl', 'coding' or 'block' target); got {what!r} ({type(target).__name__}"
                         f"): a full likelihood's covariance is its inverse curvature")
    return str(est)


def _check_theta(target: Any, theta_hat: Any) -> np.ndarray:
    """``theta_hat`` as (d,), inside the box and off its faces by the stencil's reach."""
    th = as_theta_batch(theta_hat, target.ndim, "theta_hat")
    if th.shape[0] != 1 or not np.all(np.isfinite(th)):
        raise ValueError(f"theta_hat must be one finite parameter vector of length "
                         f"{target.ndim}; got {np.asarray(theta_hat).tolist()}")
    th = th[0]
    b = np.asarray(target.bounds, dtype=np.float64)
    reach = 2.0 * _step(target, th)  # the Hessian's stencil reaches θ ± 2h
    for j, name in enumerate(target.param_names):
        if not b[j, 0] + reach[j] < th[j] < b[j, 1] - reach[j]:
            raise ValueError(f"theta_hat[{name!r}] = {th[j]:.6g} lies on (or outside) the "
                             f"box's face [{b[j, 0]:.6g}, {b[j, 1]:.6g}]: a maximum there has "
                             f"no interior curvature, so it has no sandwich variance (widen "
                             f"the bounds, or the data carry no information on {name!r})")
    return th


def _simulator(target: Any) -> Any:
    """The ``"likelihood"`` target of the same model, data and box (its simulator)."""
    from mrfpe.models.estimators import ConditionalTarget, LikelihoodTarget
    from mrfpe.models.gaussian.likelihood import GaussianLikelihoodTarget

    if isinstance(target, ConditionalTarget):
        return LikelihoodTarget(model=target.model, design=target.design, x=target.x,
                                param_names=target.param_names, bounds=target.bounds,
                                estimator="likelihood")
    return GaussianLikelihoodTarget(model=target.model, structure=target.structure, x=target.x,
                                    Z=target.Z, bounds=target.bounds, estimator="likelihood")


def _check_simulator(simulator: Any, target: Any) -> Any:
    if not callable(getattr(simulator, "simulate", None)) or tuple(
            getattr(simulator, "param_names", ())) != tuple(target.param_names):
        raise ValueError(f"simulator must be a 'likelihood' target of the same model (with "
                         f"simulate() and parameters {list(target.param_names)}); got "
                         f"{type(simulator).__name__}")
    return simulator


def _field_target(target: Any, y: np.ndarray) -> Any:
    """The same composite likelihood on one simulated field ``y`` (1, n)."""
    from mrfpe.models.estimators import ConditionalTarget

    if isinstance(target, ConditionalTarget):
        common = {"model": target.model, "design": target.design, "x": y,
                  "param_names": target.param_names, "bounds": target.bounds,
                  "estimator": target.estimator}
        if target.blocks is not None:
            return ConditionalTarget(rows=target.design.block_rows(y, target.blocks),
                                     blocks=target.blocks, **common)
        return ConditionalTarget(rows=[target.design.conditional_rows(y, target.nodes)],
                                 nodes=target.nodes, **common)
    return _gaussian_field_target(target, y)


def _gaussian_field_target(target: Any, y: np.ndarray) -> Any:
    from mrfpe.models.gaussian.options import make_blocks
    from mrfpe.models.gaussian.pseudolikelihood import GaussianBlockTarget, GaussianPLTarget
    from mrfpe.models.options import coding_nodes

    common = {"model": target.model, "structure": target.structure, "x": y, "Z": target.Z,
              "bounds": target.bounds, "estimator": target.estimator}
    if target.estimator == "block":
        blocks = getattr(target, "blocks", None)
        if blocks is None:
            blocks = make_blocks(target.structure.graph, target._extra["block"])
        return GaussianBlockTarget(blocks=blocks, **common)
    nodes = None
    if target.estimator == "coding":
        nodes = coding_nodes(target.structure.graph, target._extra["coding"])[0]
    return GaussianPLTarget(nodes=nodes, **common)


def _draw_derivatives(target: Any, y: np.ndarray, theta: np.ndarray,
                      h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-field scores (K, d) and negative Hessians (K, d, d) of the CL at ``theta``.

    One batched evaluation per field: ``2 d`` points for the central-difference score,
    ``1 + 4 d²`` for :func:`~mrfpe.models.pl_spread.hessian`.
    """
    d = theta.size
    steps = np.concatenate([theta + np.diag(h), theta - np.diag(h)])
    scores, hess = np.empty((y.shape[0], d)), np.empty((y.shape[0], d, d))
    for k, yk in enumerate(y):
        tk = _field_target(target, np.asarray(yk)[None])
        lf = tk.log_prob(steps)
        scores[k] = (lf[:d] - lf[d:]) / (2.0 * h)
        hess[k] = -hessian(tk.log_prob, theta, h)
    if not (np.all(np.isfinite(scores)) and np.all(np.isfinite(hess))):
        bad = int(np.flatnonzero(~np.isfinite(scores).all(axis=1) | ~np.isfinite(hess).all(
            axis=(1, 2)))[0])
        raise ValueError(f"the composite likelihood of simulated field {bad} is not finite "
                         f"near theta_hat {theta.round(6).tolist()}: theta_hat is at the edge "
                         f"of the model's valid region")
    return scores, hess


def _check_curvature(target: Any, theta: np.ndarray, H: np.ndarray, curvature: str) -> None:
    if not np.all(np.isfinite(H)):
        raise ValueError(f"theta_hat {theta.round(6).tolist()} is at the edge of the model's "
                         f"valid region: the composite likelihood's Hessian is not finite there")
    w = np.linalg.eigvalsh(H)
    if w[0] <= 1e-10 * max(abs(w[-1]), 1e-300):
        names = list(target.param_names)
        raise ValueError(f"theta_hat {theta.round(6).tolist()} is no maximum of the composite "
                         f"likelihood: its {curvature} curvature -Hessian over {names} is not "
                         f"positive definite (eigenvalues {np.round(w, 6).tolist()})")


def _check_score_mean(target: Any, scores: np.ndarray, theta: np.ndarray) -> None:
    """Warn if the scores' mean is far from zero, as it is in expectation at the draws' θ.

    Each conditional's score has mean zero under the model, so a mean many Monte Carlo
    errors away says that the chain did not reach ``p(· | θ̂)``.
    """
    K = scores.shape[0]
    sd = scores.std(axis=0, ddof=1)
    z = np.abs(scores.mean(axis=0)) / np.maximum(sd / math.sqrt(K), 1e-300)
    if z.max() > 5.0:
        j = int(np.argmax(z))
        warnings.warn(f"the simulated fields' mean score of {target.param_names[j]!r} is "
                      f"{z[j]:.1f} Monte Carlo errors from zero at theta_hat "
                      f"{theta.round(4).tolist()}: the simulator may not have mixed, so J is "
                      f"unreliable", RuntimeWarning, stacklevel=3)


def _jackknife_se(scores: np.ndarray, M: int, Hinv: np.ndarray | None,
                  hess: np.ndarray | None) -> np.ndarray:
    """Grouped-jackknife Monte Carlo error (d,) of ``sqrt(diag(H⁻¹ J H⁻¹))``.

    ``Hinv`` is fixed (observed curvature), or ``hess`` (K, d, d) is the per-field negative
    Hessians (times ``M``) whose mean is ``H`` and which are left out with their scores.
    """
    K = scores.shape[0]
    g = min(JACKKNIFE_GROUPS, K)
    groups = np.array_split(np.arange(K), g)
    out = []
    for idx in groups:
        keep = np.setdiff1d(np.arange(K), idx)
        J = M * np.atleast_2d(np.cov(scores[keep], rowvar=False))
        Hi = Hinv if hess is None else np.linalg.inv(hess[keep].mean(axis=0))
        out.append(np.sqrt(np.abs(np.diag(Hi @ J @ Hi))))
    out = np.array(out)
    return np.sqrt((g - 1) / g * ((out - out.mean(axis=0)) ** 2).sum(axis=0))
