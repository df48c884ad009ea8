"""Analytic targets the conformance checks run samplers on.

:class:`CorrelatedGaussian` (3-D, in the unit cube, with a ``partition`` into
"observation" subsets that mimics a lattice's sub-lattices, and ``residuals``),
:class:`TwoModes` and :class:`MostlyMinusInf`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.partition import split_ids

__all__ = ["BoxGaussian", "CorrelatedGaussian", "MostlyMinusInf", "TwoModes", "box_gaussian"]


# --------------------------------------------------------------------------
# Analytic targets
# --------------------------------------------------------------------------
class CorrelatedGaussian(Target):
    """A correlated 3-D Gaussian posterior inside the unit cube, built like an MRF target.

    The log density is a sum over ``n_obs`` "observations" ``x_m`` (the analogue
    of lattice nodes): ``log p(θ) = Σ_m log N(x_m | θ, Σ_obs)``, so that, with a
    flat prior, the posterior is ``N(mean, Σ_obs / n_obs)`` exactly (the
    observations are centred so their mean is ``mean``). The density is
    truncated to the unit cube, more than 5 sd from any face, so ``mean`` and
    ``cov`` are the moments of the target to within 1e-6.

    ``partition(k, kind)`` splits the observations into ``k`` strided
    (``{n, n+k, ...}``) or contiguous blocks whose log densities sum exactly to
    the full one (each with ``cost`` = its share of the observations), and
    ``residuals(θ)`` returns the whitened errors ``r`` with
    ``log p(θ) = const - ½‖r‖²``.
    """

    param_names = ("x", "y", "z")
    bounds = np.array([[0.0, 1.0]] * 3)
    mean = np.array([0.45, 0.55, 0.5])
    sd = np.array([0.05, 0.04, 0.06])
    corr = np.array([[1.0, 0.6, -0.3], [0.6, 1.0, 0.2], [-0.3, 0.2, 1.0]])

    def __init__(self, n_obs: int = 60, *, _obs: np.ndarray | None = None, cost: float = 1.0):
        self.cov = self.corr * np.outer(self.sd, self.sd)
        self.n_total = int(n_obs)
        if _obs is None:
            if self.n_total < 4:
                raise ValueError(f"n_obs must be >= 4; got {n_obs}")
            cov_obs = self.cov * self.n_total
            z = np.random.default_rng(12345).multivariate_normal(np.zeros(3), cov_obs,
                                                                 self.n_total)
            _obs = self.mean + z - z.mean(axis=0)
        self.obs = np.asarray(_obs, dtype=np.float64)
        self.cost = float(cost)
        self._prec_obs = np.linalg.inv(self.cov * self.n_total)
        self._chol = np.linalg.cholesky(self._prec_obs)  # prec = L Lᵀ, r = Lᵀ(x - θ)
        self._log_norm = -0.5 * (3 * math.log(2 * math.pi)
                                 + np.linalg.slogdet(self.cov * self.n_total)[1])
        m = self.obs.mean(axis=0)
        dev = self.obs - m
        self._m, self._k = m, self.obs.shape[0]
        self._const = self._k * self._log_norm - 0.5 * np.einsum(
            "ij,jk,ik->", dev, self._prec_obs, dev)

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        # Σ_m (x_m-θ)ᵀP(x_m-θ) = k (θ-m̄)ᵀP(θ-m̄) + Σ_m (x_m-m̄)ᵀP(x_m-m̄)
        e = theta - self._m
        return self._const - 0.5 * self._k * np.einsum("ij,jk,ik->i", e, self._prec_obs, e)

    def residuals(self, theta: Any) -> np.ndarray:
        """Whitened errors (N, 3·n_obs): ``log_prob = const - ½ Σ r²`` inside the cube."""
        theta = as_theta_batch(theta, 3)
        diff = self.obs[None, :, :] - theta[:, None, :]  # (N, M, 3)
        return (diff @ self._chol).reshape(theta.shape[0], -1)

    def partition(self, k: int, kind: str = "strided") -> list[CorrelatedGaussian]:
        """``k`` sub-targets over disjoint observation subsets; their log_probs sum to ours."""
        idx = split_ids(np.arange(self._k), k, kind, what="n_obs")
        parts = []
        for ix in idx:
            sub = CorrelatedGaussian(self.n_total, _obs=self.obs[ix],
                                     cost=self.cost * len(ix) / self._k)
            parts.append(sub)
        return parts

    # -- as a likelihood with a simulator (for doubly-intractable samplers' checks) ----------
    #: Draws from the model are exact (:meth:`simulate`).
    exact_simulator = True

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``log f(x | θ) = -½ Σ_m (x_m - θ)ᵀ P (x_m - θ)`` (N,) for observations ``x`` (k, 3).

        ``log_prob(θ)`` equals ``unnormalised(θ)`` plus a constant inside the cube.
        """
        theta = as_theta_batch(theta, 3)
        obs = self.obs if x is None else np.asarray(x, dtype=np.float64).reshape(-1, 3)
        diff = obs[None, :, :] - theta[:, None, :]
        return -0.5 * np.einsum("nmi,ij,nmj->n", diff, self._prec_obs, diff)

    def simulate(self, theta: Any, n: int | None = None, *, seed: Any = None,
                 **_: Any) -> np.ndarray:
        """``n`` (default ``n_obs``) observations drawn from ``N(θ, Σ_obs)``: (n, 3)."""
        th = as_theta_batch(theta, 3)[0]
        k = self._k if n is None else int(n)
        z = np.random.default_rng(seed).standard_normal((k, 3))
        return th + z @ np.linalg.cholesky(self.cov * self.n_total).T

    def describe(self) -> dict:
        return {**super().describe(), "n_obs": int(self._k)}


class TwoModes(Target):
    """Two Gaussian bumps in the unit square; the ``high`` mode's peak is ``e``× the other's.

    ``log p = logsumexp(-½‖θ-μ_high‖²/s², -1 - ½‖θ-μ_low‖²/s²)``, s = 0.06. The
    global maximum is at ``high`` (to within 1e-9: the low bump's tail there is
    ~e^-80). ``residuals(θ) = [sqrt(2(c - log p)), 0]`` with ``c = log p(high) + 1``.
    """

    param_names = ("u", "v")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    high = np.array([0.72, 0.3])
    low = np.array([0.28, 0.68])
    scale = 0.06

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        a = -0.5 * np.sum((theta - self.high) ** 2, axis=1) / self.scale**2
        b = -1.0 - 0.5 * np.sum((theta - self.low) ** 2, axis=1) / self.scale**2
        return np.logaddexp(a, b)

    @property
    def max_log_prob(self) -> float:
        return float(self.log_prob(self.high)[0])

    # -- as a likelihood: one observation ``high`` of ``y ~ w N(θ, s²) + (1-w) N(θ + δ, s²)``,
    # δ = high - low, w = 1/(1 + e^-1); Z(θ) = 1, so the posterior is this target exactly.
    exact_simulator = True

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``log f(x | θ)`` (N,) of observations ``x`` (k, 2) (default the one observation)."""
        theta = as_theta_batch(theta, 2)
        obs = self.high[None] if x is None else np.asarray(x, dtype=np.float64).reshape(-1, 2)
        d = self.high - self.low
        a = -0.5 * np.sum((obs[None] - theta[:, None]) ** 2, -1) / self.scale**2
        b = -1.0 - 0.5 * np.sum((obs[None] - theta[:, None] - d) ** 2, -1) / self.scale**2
        return np.logaddexp(a, b).sum(axis=1)

    def simulate(self, theta: Any, n: int | None = None, *, seed: Any = None,
                 **_: Any) -> np.ndarray:
        """``n`` (default 1) observations from the two-component location mixture."""
        th = as_theta_batch(theta, 2)[0]
        rng = np.random.default_rng(seed)
        k = 1 if n is None else int(n)
        shift = (rng.random(k) < 1.0 / (1.0 + np.e))[:, None] * (self.high - self.low)
        return th + shift + self.scale * rng.standard_normal((k, 2))

    def residuals(self, theta: Any) -> np.ndarray:
        theta = as_theta_batch(theta, 2)
        lp = self.log_prob(theta)
        r = np.sqrt(2.0 * (self.max_log_prob + 1.0 - lp))
        return np.stack([r, np.zeros_like(r)], axis=1)


class MostlyMinusInf(Target):
    """``-inf`` everywhere in the unit cube except a small box (0.3% of the volume).

    Inside the box ``[0.61, 0.76] × [0.2, 0.35] × [0.45, 0.6]`` the density is a
    gentle Gaussian bump; an evenly spaced grid of 1000 points hits it at most a
    few times and a random draw almost never.
    """

    param_names = ("a", "b", "c")
    bounds = np.array([[0.0, 1.0]] * 3)
    box = np.array([[0.61, 0.76], [0.2, 0.35], [0.45, 0.6]])

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        inside = np.all((theta >= self.box[:, 0]) & (theta <= self.box[:, 1]), axis=1)
        centre = self.box.mean(axis=1)
        out = np.full(theta.shape[0], -np.inf)
        out[inside] = -0.5 * np.sum((theta[inside] - centre) ** 2, axis=1) / 0.05**2
        return out

    # -- as a likelihood: one observation (the box's centre) of ``y ~ N(θ, 0.05² I)``, the
    # box being the prior's support; Z(θ) is constant, so the posterior is this target.
    exact_simulator = True

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``log f(x | θ)`` (N,) of observations ``x`` (k, 3) (default the box's centre)."""
        theta = as_theta_batch(theta, 3)
        obs = self.box.mean(axis=1)[None] if x is None else np.asarray(
            x, dtype=np.float64).reshape(-1, 3)
        return -0.5 * np.sum((obs[None] - theta[:, None]) ** 2, axis=(1, 2)) / 0.05**2

    def simulate(self, theta: Any, n: int | None = None, *, seed: Any = None,
                 **_: Any) -> np.ndarray:
        """``n`` (default 1) observations from ``N(θ, 0.05² I)``."""
        th = as_theta_batch(theta, 3)[0]
        k = 1 if n is None else int(n)
        return th + 0.05 * np.random.default_rng(seed).standard_normal((k, 3))

    def residuals(self, theta: Any) -> np.ndarray:
        theta = as_theta_batch(theta, 3)
        lp = self.log_prob(theta)
        r = np.sqrt(2.0 * (1.0 - lp))  # +inf outside the box, like the log density
        return np.stack([r, np.zeros_like(r), np.zeros_like(r)], axis=1)


# --------------------------------------------------------------------------
# Plumbing


class BoxGaussian(Target):
    """N(mean, cov) in the unit cube, far from every face (the accuracy suite's targets).

    The normaliser is 1 to within the mass beyond 5 sd, so ``log_evidence`` should be 0;
    :func:`box_gaussian` builds the 3-D correlated and the 10-D AR(1) instances.
    """

    bounds: np.ndarray

    def __init__(self, mean: np.ndarray, cov: np.ndarray):
        self.mean, self.cov = np.asarray(mean, float), np.asarray(cov, float)
        self.sd = np.sqrt(np.diag(self.cov))
        self.param_names = tuple(f"p{i}" for i in range(self.mean.size))
        self.bounds = np.array([[0.0, 1.0]] * self.mean.size)
        self._mvn = stats.multivariate_normal(self.mean, self.cov)

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return np.atleast_1d(self._mvn.logpdf(theta))


def box_gaussian(dim: int) -> BoxGaussian:
    """The 3-D correlated Gaussian (sd 0.05–0.08) or, for any other ``dim``, the AR(1)
    Gaussian (ρ = 0.7, sd 0.04) centred in the unit cube."""
    if dim == 3:
        sd = np.array([0.05, 0.065, 0.08])
        corr = np.array([[1.0, -0.5, 0.3], [-0.5, 1.0, 0.4], [0.3, 0.4, 1.0]])
        return BoxGaussian([0.42, 0.57, 0.5], corr * np.outer(sd, sd))
    i = np.arange(dim)
    corr = 0.7 ** np.abs(i[:, None] - i[None, :])
    return BoxGaussian(np.full(dim, 0.5), corr * 0.04**2)
