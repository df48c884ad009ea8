"""Poisson emission: counts ``y_i | x_i = a ~ Poisson(E_i rate_a)``, with an optional exposure.

``E_i`` is a node covariate named by ``exposure`` (passed as ``covariates={name: E}``
to the hidden model's ``target`` and ``simulate``), 1 without one -- the disease-mapping
form of a hidden Potts model (Green & Richardson 2002). Prior: independently
``rate_a ~ Gamma(a0, b0)`` (shape, rate), restricted to the support and to
``rate_0 < rate_1 < ...``; default ``a0 = 1`` and ``b0 = sum E / sum y`` (an exponential
prior whose mean is the overall rate), support ``(0, 10 (max y/E + 1))``. A rate given
``bounds`` has the flat prior on them (``a0 = 1, b0 = 0``).

Update: every free rate in turn from its gamma full conditional ``Gamma(a0 + sum y,
b0 + sum E)`` over the nodes in its state (the gamma-Poisson conjugate pair), truncated
to its bounds and its neighbours in the ordering.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.special import gammaln

from mrfpe.models.emissions.base import (
    BoundEmission,
    Emission,
    check_prior_pair,
    observed_values,
    ordered_prior_draw,
    resolve_bounds,
)
from mrfpe.models.emissions.gaussian import strictly_increasing
from mrfpe.models.emissions.truncated import ordered_mode, truncated_gamma

__all__ = ["Poisson", "poisson"]


class Poisson(Emission):
    """``Poisson(E_i rate_a)`` per state ``a`` (see the module docstring).

    Parameters
    ----------
    exposure : str or None
        Name of the node covariate holding ``E_i > 0`` (default: no exposure, ``E = 1``).
    rate_prior : tuple or None
        ``(a0, b0)``: the gamma prior (shape, rate) of every rate.
    """

    name = "poisson"
    ordered = True
    data_kind = "count"

    def __init__(self, exposure: str | None = None, rate_prior: Any = None) -> None:
        if exposure is not None and (not isinstance(exposure, str) or not exposure):
            raise ValueError(f"exposure must be None or a covariate name; got {exposure!r}")
        self.exposure = exposure
        self.covariate_names = () if exposure is None else (exposure,)
        self.rate_prior = check_prior_pair("rate_prior", rate_prior,
                                           "(shape a0, rate b0) of the gamma")

    def param_names(self, q: int) -> tuple[str, ...]:
        return tuple(f"rate_{a}" for a in range(q))

    def exposure_of(self, covariates: Mapping[str, np.ndarray] | None, n: int) -> np.ndarray:
        """``E`` (n,) from ``covariates`` (ones without an exposure), checked ``> 0``."""
        if self.exposure is None:
            return np.ones(n)
        if not covariates or self.exposure not in covariates:
            raise ValueError(f"covariates must include the exposure {self.exposure!r} of the "
                             f"poisson emission")
        e = np.asarray(covariates[self.exposure], dtype=np.float64).reshape(-1)
        if e.shape != (n,) or not np.all(np.isfinite(e)) or np.any(e <= 0):
            raise ValueError(f"covariate {self.exposure!r} (the exposure) must hold one finite "
                             f"value > 0 per node ({n}); got shape "
                             f"{np.shape(covariates[self.exposure])}")
        return e

    def bind(self, q: int, y: np.ndarray, observed: np.ndarray,
             covariates: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]],
             ) -> BoundPoisson:
        e = self.exposure_of(covariates, np.asarray(y).size)
        v, eo = observed_values(y, observed), e[observed]
        total = float(v.sum())
        a0, b0 = self.rate_prior or (1.0, float(eo.sum()) / total if total > 0 else 1.0)
        top = 10.0 * (float((v / eo).max()) + 1.0) if v.size else 10.0
        names = self.param_names(q)
        b, flat = resolve_bounds(names, np.array([(0.0, top)] * q), bounds,
                                 np.array([(0.0, np.inf)] * q))
        return BoundPoisson(self, q, y, observed, names, b, flat, e, (a0, b0))

    def simulate(self, x: np.ndarray, params: np.ndarray, rng: np.random.Generator,
                 covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=np.int64)
        e = self.exposure_of(covariates, x.size).reshape(x.shape)
        return rng.poisson(e * np.asarray(params, float)[x]).astype(np.float64)

    def describe(self) -> dict:
        return {**super().describe(), "exposure": self.exposure, "rate_prior": self.rate_prior}


class BoundPoisson(BoundEmission):
    """The Poisson emission on one data set (see :class:`Poisson`)."""

    conjugate = True

    def __init__(self, emission: Poisson, q: int, y: np.ndarray, observed: np.ndarray,
                 names: tuple[str, ...], bounds: np.ndarray, flat: np.ndarray,
                 exposure: np.ndarray, hyper: tuple[float, float]) -> None:
        super().__init__(emission, q, y, observed, names, bounds, flat)
        self.a0, self.b0 = (float(h) for h in hyper)
        self.eo = np.asarray(exposure, dtype=np.float64)[self.observed]
        self._cache()

    def _cache(self) -> None:
        self.yo = observed_values(self.y, self.observed)
        self._const = self.yo * np.log(self.eo) - gammaln(self.yo + 1.0)

    def _log_lik_observed(self, params: np.ndarray) -> np.ndarray:
        r = params[:, None, :]
        with np.errstate(divide="ignore"):  # a rate of 0: -inf where y > 0
            lr = np.log(r)
        term = np.where(self.yo[None, :, None] > 0, self.yo[None, :, None] * lr, 0.0)
        return term - self.eo[None, :, None] * r + self._const[None, :, None]

    def log_prior(self, params: Any) -> np.ndarray:
        p = self.as_params(params)
        with np.errstate(divide="ignore"):
            dens = (self.a0 - 1) * np.log(p) - self.b0 * p
        lp = np.where(self.flat[None], 0.0, dens).sum(axis=1)
        return np.where(self.in_support(p), lp, -np.inf)

    def _prior_ab(self, k: int) -> tuple[float, float]:
        return (1.0, 0.0) if self.flat[k] else (self.a0, self.b0)

    def update(self, params: np.ndarray, x: np.ndarray, rng: np.random.Generator,
               free: np.ndarray) -> np.ndarray:
        p = np.array(params, dtype=float)
        xo = np.asarray(x)[self.observed]
        sy = np.bincount(xo, weights=self.yo, minlength=self.q)
        se = np.bincount(xo, weights=self.eo, minlength=self.q)
        u = rng.random(self.q)
        for k in range(self.q):
            if free[k]:
                a, b = self._prior_ab(k)
                lo, hi = self.bounds[k]
                lo = max(lo, p[k - 1]) if k > 0 else lo
                hi = min(hi, p[k + 1]) if k < self.q - 1 else hi
                p[k] = truncated_gamma(a + sy[k], b + se[k], lo, hi, u[k])
        return p

    def map_update(self, params: np.ndarray, resp: np.ndarray, free: np.ndarray) -> np.ndarray:
        p = np.array(params, dtype=float)
        r = np.asarray(resp, float)[self.observed]
        a = np.array([self._prior_ab(k)[0] for k in range(self.q)])
        b = np.array([self._prior_ab(k)[1] for k in range(self.q)])
        num, den = a - 1 + r.T @ self.yo, b + r.T @ self.eo
        mode = ordered_mode(np.maximum(num, 0.0), den, p)
        lo = np.maximum(self.bounds[:, 0], 1e-9 * self.bounds[:, 1])
        mode = strictly_increasing(np.clip(mode, lo, self.bounds[:, 1]), float(self.bounds[0, 1]))
        return np.where(free, np.clip(mode, lo, self.bounds[:, 1]), p)

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """Rates at the quantiles ``(a + 1/2)/q`` of the observed ``y/E`` (plus 1/2, so
        none is 0); labels: the nearest rate."""
        ratio = self.yo / self.eo
        rate = np.quantile(ratio, (np.arange(self.q) + 0.5) / self.q) + 0.5 if ratio.size \
            else np.arange(1.0, self.q + 1)
        rate = strictly_increasing(rate, float(np.ptp(ratio)) + 1.0 if ratio.size else 1.0)
        rate = np.clip(rate, np.maximum(self.bounds[:, 0], 1e-9), self.bounds[:, 1])
        e = np.ones(self.y.size)
        e[self.observed] = self.eo
        labels = np.argmin(np.abs(self.y[:, None] / e[:, None] - rate[None]), axis=1)
        return rate, labels.astype(np.int64)

    def prior_sample(self, rng: np.random.Generator) -> np.ndarray:
        return ordered_prior_draw(
            lambda k, u: truncated_gamma(*self._prior_ab(k), *self.bounds[k], u), self, rng)

    def describe_prior(self) -> dict:
        out = {}
        for k, name in enumerate(self.names):
            lo, hi = self.bounds[k]
            out[name] = (f"flat on [{lo:.6g}, {hi:.6g}]" if self.flat[k] else
                         f"Gamma(shape {self.a0:.6g}, rate {self.b0:.6g}) on [{lo:.6g}, {hi:.6g}]")
        out["order"] = "rate_0 < rate_1 < ..."
        return out


def poisson(exposure: str | None = None, rate_prior: Any = None) -> Poisson:
    """The Poisson emission (see :class:`Poisson`)."""
    return Poisson(exposure=exposure, rate_prior=rate_prior)
