"""Simulations from a model at one parameter vector, and what they estimate there.

:func:`simulate_draws` runs the model's simulator from the data (an exact
simulator, or a chain whose burn-in and thinning follow its measured
autocorrelation time); :func:`fisher_information` is ``M Cov[∇ log f(y | θ)]``
over the draws, the statistic :mod:`mrfpe.models.calibration` and
:mod:`mrfpe.models.bootstrap` build on; :func:`posterior_mean_shift` the third-order
difference between the likelihood posterior's mean and the MLE.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import logsumexp

from mrfpe.models.mixing import autocorrelation_time
from mrfpe.models.pl_spread import hessian
from mrfpe.targets.base import as_theta_batch

__all__ = ["Draws", "check_score_variance", "fisher_information", "posterior_mean_shift",
           "simulate_draws"]


@dataclass(frozen=True)
class Draws:
    """Draws ``y_k ~ p(· | θ)`` of one configuration each, with the chain's settings."""

    theta: np.ndarray
    y: np.ndarray  # (K, n_nodes)
    tau: float
    burn_in: int
    thin: int
    memo: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_sweeps(self) -> int:
        return int(self.burn_in + self.thin * (self.y.shape[0] - 1))


def simulate_draws(lik: Any, theta: Any, n_draws: int, *, seed: int,
                   pilot_sweeps: int = 2000) -> Draws:
    """``n_draws`` configurations at ``theta`` from one chain started at the data.

    Exact simulators give independent draws; otherwise the chain's autocorrelation
    time ``τ`` is measured first (a pilot chain of at least ``pilot_sweeps`` and 50 τ
    sweeps, :func:`~mrfpe.models.mixing.autocorrelation_time`), then the chain runs
    ``max(10 τ, 10)`` sweeps of burn-in and keeps a draw every ``max(1, ⌈τ⌉)`` sweeps.
    """
    th = as_theta_batch(theta, lik.ndim)[0]
    rng = np.random.default_rng(seed)
    if getattr(lik, "exact_simulator", False):
        y = lik.simulate(th, n=n_draws, seed=int(rng.integers(2**63)))
        return Draws(th, np.asarray(y), 0.0, 0, 1)
    tau = autocorrelation_time(lik, th, seed=int(rng.integers(2**63)), min_sweeps=pilot_sweeps)
    if not math.isfinite(tau):
        raise ValueError(f"the model's simulator does not mix at theta {th.tolist()}: its "
                         f"autocorrelation time exceeds the pilot run (use a simulator that "
                         f"mixes, e.g. sampler='swendsen_wang' for Potts models)")
    burn, thin = max(10, math.ceil(10 * tau)), max(1, math.ceil(tau))
    y = lik.simulate(th, n=n_draws, seed=int(rng.integers(2**63)), init=lik.x[0],
                     n_sweeps=burn, thin=thin)
    return Draws(th, np.asarray(y), tau, burn, thin)


def _log_f_of(lik: Any, draws: Draws) -> Any:
    """``theta (N, d) -> log f(y_k | θ_j)`` (N, K) for the draws (one configuration each),
    made once per draws.

    For a design model the draws' sufficient statistics are computed once, so each
    call is one matrix product; a target with a ``log_f_of_draws(y)`` method (e.g.
    the BRDF likelihood, which keeps each draw's geometry) supplies its own.
    """
    if "log_f" not in draws.memo:
        draws.memo["log_f"] = _make_log_f(lik, draws.y)
    return draws.memo["log_f"]


def _make_log_f(lik: Any, y: np.ndarray) -> Any:
    own = getattr(lik, "log_f_of_draws", None)
    if callable(own):
        return own(y)
    stats = getattr(lik, "sufficient_statistics", None)
    design = getattr(lik, "design", None)
    if callable(stats) and design is not None:
        S = stats(y).T
        return lambda theta: design.psi(theta) @ S
    return lambda theta: np.stack([lik.unnormalised(theta, yk[None]) for yk in y], axis=1)


def _scores(lik: Any, draws: Draws, h: np.ndarray) -> np.ndarray:
    """``∇_θ log f(y_k | θ)`` (K, d) at the draws' θ by central differences (exact for
    log-linear models)."""
    theta = draws.theta
    d = theta.size
    steps = np.concatenate([theta + np.diag(h), theta - np.diag(h)])
    lf = _log_f_of(lik, draws)(steps)  # (2d, K)
    return ((lf[:d] - lf[d:]) / (2 * h)[:, None]).T


def _step(target: Any, theta: np.ndarray | None = None) -> np.ndarray:
    """Finite-difference steps: 1e-4 of the parameter's scale, at most 1e-4 of its range.

    The scale is ``|θ|`` (at least 1 % of the range), so that a wide box (say a
    precision in ``(0, 10^4)``) does not step across the point's own magnitude.
    """
    b = np.asarray(target.bounds, dtype=np.float64)
    width = b[:, 1] - b[:, 0]
    if theta is None:
        return 1e-4 * width
    return 1e-4 * np.minimum(width, np.maximum(np.abs(theta), 1e-2 * width))


def fisher_information(lik: Any, draws: Draws) -> np.ndarray:
    """``I(θ) = M Cov_k[∇ log f(y_k | θ)]`` (d, d) at the draws' θ (M observations).

    Raises ValueError naming the parameter whose score does not vary (a singular
    information: every draw at this θ has the same statistic -- e.g. uniform lattices
    on the coupling's bound -- or the data cannot identify the parameter).
    """
    s = _scores(lik, draws, _step(lik, draws.theta))
    cov = np.atleast_2d(np.cov(s, rowvar=False))
    M = int(getattr(lik, "n_observations", 1))
    info = M * cov
    check_score_variance(info, list(lik.param_names),
                         f"the Fisher information at theta {draws.theta.tolist()}",
                         f"{draws.y.shape[0]} simulations")
    return info


def check_score_variance(matrix: np.ndarray, names: list[str], what: str, over: str) -> None:
    """ValueError unless a score's variance ``matrix`` is non-singular: naming the
    parameter whose score does not vary ``over`` the simulations, or the conditioning (the
    model is degenerate there, or the data cannot identify a combination of parameters)."""
    flat = np.flatnonzero(np.diag(matrix) <= 1e-12 * max(1.0, np.abs(matrix).max()))
    if flat.size:
        raise ValueError(f"{what} is singular: the score of {names[flat[0]]!r} does not vary "
                         f"over {over} (the model is degenerate there, or the data cannot "
                         f"identify the parameter)")
    w = np.linalg.eigvalsh(matrix)
    if w[0] <= 1e-10 * w[-1]:
        raise ValueError(f"{what} is singular (condition number "
                         f"{w[-1] / max(w[0], 1e-300):.3g}): some combination of {names} has a "
                         f"score that does not vary over {over}")


def log_likelihood_near(lik: Any, draws: Draws) -> Any:
    """``θ (N, d) -> ℓ(θ) - ℓ(θ0)`` (N,) by importance sampling from the draws at ``θ0``.

    Geyer & Thompson (1992): ``ℓ(θ) - ℓ(θ0) = log f(x | θ) - log f(x | θ0) - M log
    mean_k exp(log f(y_k | θ) - log f(y_k | θ0))``, a smooth function of ``θ`` for fixed
    draws whose derivatives at ``θ0`` are the draws' estimates of the likelihood's
    (those of ``log Z`` are the cumulants of ``log f(y | θ)``'s derivatives).
    """
    log_f = _log_f_of(lik, draws)
    lf0 = log_f(draws.theta[None])[0]
    lx0 = float(lik.log_prob(draws.theta[None])[0])
    M, K = int(getattr(lik, "n_observations", 1)), lf0.size

    def ell(theta: np.ndarray) -> np.ndarray:
        theta = as_theta_batch(theta, lik.ndim)
        lw = log_f(theta) - lf0
        return lik.log_prob(theta) - lx0 - M * (logsumexp(lw, axis=1) - math.log(K))
    return ell


def posterior_mean_shift(lik: Any, draws: Draws, theta_ml: Any, info: np.ndarray,
                         step: float = 0.1) -> np.ndarray:
    """The likelihood posterior's mean minus the MLE under a flat prior, to third order.

    ``δ = ½ Σ ∇ tr(Σ ∇²ℓ)`` at the MLE, i.e. ``δ_i = ½ Σ_ij ℓ_jkl Σ_kl`` with ``Σ =
    (-∇²ℓ)⁻¹`` the inverse observed information (Tierney & Kadane 1986; Tierney, Kass &
    Kadane 1989). With ``ℓ = Σ_m log f(x_m | θ) - M log Z(θ)`` the third derivatives of
    ``log Z`` are, with ``g = log f(y | θ)``, ``y ~ p(· | θ)`` (McCullagh 1987, ch. 7),

        ``∂_jkl log Z = E[g_jkl] + Cov(g_jk, g_l) + Cov(g_jl, g_k) + Cov(g_kl, g_j)
        + κ(g_j, g_k, g_l)``;

    only for a model log-linear in ``θ`` (``g_jk`` constant) does this reduce to the
    score's third cumulant, ``ℓ_jkl = -M κ_jkl``. Here every term comes at once from
    finite differences of the Geyer-Thompson log-likelihood (:func:`log_likelihood_near`),
    whose derivatives are exactly the draws' estimates of them, in coordinates whitened
    by ``info`` (one unit = one asymptotic sd) with steps of ``step`` units: local
    derivatives, as the expansion needs (0.5 sd averaged the third derivative over the
    stencil and moved the shift by up to 1.4 sd near the Ising model's critical coupling,
    where 0.1 reproduces the score-cumulant shortcut that is exact for that model).

    ``theta_ml`` is the MLE, ``draws`` are at a point near it. Returns zeros where the
    stencil leaves the likelihood's support even at an eighth of ``step``.
    """
    ell = log_likelihood_near(lik, draws)
    th = as_theta_batch(theta_ml, lik.ndim)[0]
    d = th.size
    L0 = np.linalg.cholesky(np.linalg.inv(info))
    s = float(step)
    for _ in range(3):  # a smaller stencil where the MLE is near the support's edge
        shift = _shift_whitened(lambda z: ell(th + z @ L0.T), d, s)
        if shift is not None:
            return L0 @ shift
        s /= 2.0
    return np.zeros(d)


def _shift_whitened(phi: Any, d: int, s: float) -> np.ndarray | None:
    """``½ Σz ∇ tr(Σz ∇²φ)`` at ``z = 0``, ``Σz = (-∇²φ(0))⁻¹``, by central differences of
    step ``s``; None where a stencil point is ``-inf`` or ``Σz`` is not positive definite."""
    with np.errstate(invalid="ignore"):
        Hz = hessian(phi, np.zeros(d), np.full(d, s))
    if not np.all(np.isfinite(Hz)):
        return None
    mu, U = np.linalg.eigh(-Hz)
    if mu[0] <= 0:
        return None
    Sz = (U / mu) @ U.T
    lam, V = np.linalg.eigh(Sz)  # tr(Sz ∇²φ) = Σ_e λ_e ∂²φ along v_e
    pts = []
    for j in range(d):
        for sign in (1.0, -1.0):
            c = sign * s * np.eye(d)[j]
            pts += [c] + [c + s * V[:, e] for e in range(d)] + [c - s * V[:, e] for e in range(d)]
    v = np.asarray(phi(np.array(pts)), dtype=np.float64).reshape(d, 2, 1 + 2 * d)
    if not np.all(np.isfinite(v)):
        return None
    second = (v[:, :, 1:1 + d] + v[:, :, 1 + d:] - 2.0 * v[:, :, :1]) / s**2  # (d, 2, e)
    trace = second @ lam  # (d, 2): tr at +s e_j and -s e_j
    grad = (trace[:, 0] - trace[:, 1]) / (2.0 * s)
    return 0.5 * Sz @ grad
