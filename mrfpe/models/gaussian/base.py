"""The base of the auto-normal targets: theta's layout, the data's columns, the PD check.

Every target is batched over theta ``(N, d)``, ``theta = (mean, coupling |
coupling_<type>..., precision, <covariate coefficients>...)``, and its ``log_prob``
is ``-inf`` outside the positive-definite region (and outside the bounds), never
NaN. With ``u = x - mu = C a(theta)``, ``C = [x - x0, 1, Z - z0]``, the conditional
residual ``e = (I - sum_t beta_t W_t) u`` is linear in ``b(theta) = (a, -beta_1 a,
..., -beta_T a)``: ``e = G b`` with ``G = [C, W_1 C, ..., W_T C]`` (neighbour sums
per coupling type), which the pseudolikelihoods precompute once.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mrfpe.models.base import Model
from mrfpe.targets.base import Target

if TYPE_CHECKING:
    from mrfpe.models.gaussian.structure import CARStructure

__all__ = ["GaussianTarget"]

#: ``log(2 pi)``.
LOG_2PI = math.log(2.0 * math.pi)


class GaussianTarget(Target):
    """What every auto-normal target shares: parameters, data columns, PD check, description.

    ``u = x - mu = C a(theta)`` with ``C = [x - x0, 1, Z - z0]`` (centred, so that
    expanded quadratic forms lose little to cancellation) and ``a = (1, -(m - x0 +
    z0 . gamma), -gamma)``.
    """

    data_kind = "fields"

    def __init__(self, *, model: Model, structure: CARStructure, x: np.ndarray,
                 Z: np.ndarray, bounds: np.ndarray, estimator: str, cost: float = 1.0,
                 extra: dict | None = None) -> None:
        self.model = model
        self.structure = structure
        self.x = x
        self.Z = Z
        self.param_names = model.param_names()
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.estimator = estimator
        self.name = f"{model.name}:{estimator}"
        self.cost = float(cost)
        self._extra = dict(extra or {})
        self.T = structure.T
        self.K = Z.shape[1]
        self.P = 2 + self.K
        self._x0 = float(x.mean())
        self._z0 = Z.mean(axis=0) if self.K else np.zeros(0)
        self._C = self.columns(x)

    def columns(self, x: np.ndarray) -> np.ndarray:
        """``C = [x - x0, 1, Z - z0]`` (M, n, P) of fields ``x`` (M, n), centred as the data."""
        M, n = x.shape
        C = np.empty((M, n, self.P))
        C[:, :, 0] = x - self._x0
        C[:, :, 1] = 1.0
        if self.K:
            C[:, :, 2:] = (self.Z - self._z0)[None]
        return C

    @property
    def n_observations(self) -> int:
        return int(self.x.shape[0])

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(mean (N,), coupling (N, T), precision (N,), gamma (N, K))``."""
        T = self.T
        return theta[:, 0], theta[:, 1:1 + T], theta[:, 1 + T], theta[:, 2 + T:]

    def _a(self, theta: np.ndarray) -> np.ndarray:
        m, _, _, g = self.split(theta)
        a = np.empty((theta.shape[0], self.P))
        a[:, 0] = 1.0
        a[:, 1] = -(m - self._x0 + g @ self._z0)
        a[:, 2:] = -g
        return a

    def _b(self, theta: np.ndarray) -> np.ndarray:
        """``(a, -beta_1 a, ..., -beta_T a)`` (N, P (1 + T)): ``e = G b``."""
        a = self._a(theta)
        beta = self.split(theta)[1]
        return np.concatenate([a] + [-beta[:, t:t + 1] * a for t in range(self.T)], axis=1)

    def _G(self) -> np.ndarray:
        """``(M, n, P (1 + T))``: ``[C, W_1 C, ..., W_T C]`` per observation."""
        M, n, P = self._C.shape
        G = np.empty((M, n, P * (1 + self.T)))
        for m in range(M):
            G[m, :, :P] = self._C[m]
            for t, W in enumerate(self.structure.W):
                G[m, :, P * (1 + t):P * (2 + t)] = W @ self._C[m]
        return G

    def valid(self, theta: np.ndarray) -> np.ndarray:
        """``(N,)``: rows with ``precision > 0`` and ``Q`` positive definite."""
        tau = self.split(theta)[2]
        ok = tau > 0
        if ok.any():
            ok[ok] = self.structure.pd_mask(self.split(theta[ok])[1])
        return ok

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        out = np.full(theta.shape[0], -np.inf)
        ok = self.valid(theta)
        if ok.any():
            out[ok] = self._value(theta[ok])
        return out

    def _value(self, theta: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__, "model": self.model.name,
                "estimator": self.estimator, "param_names": list(self.param_names),
                "bounds": self.bounds.tolist(), "graph": self.structure.describe(),
                "n_observations": self.n_observations, "covariates": list(
                    self.model.covariate_names), "cost": self.cost, **self._extra}
