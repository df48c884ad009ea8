"""Gaussian emission: ``y_i | x_i = a ~ N(mean_a, sd^2)`` (one sd, or one per state).

Priors (conditionally conjugate, as in Marin & Robert 2014, ch. 8, and the R package
bayesImageS): independently ``mean_a ~ N(m0, s0^2)`` and ``sd^2 ~ InvGamma(a0, b0)``
(each ``sd_a^2`` with ``shared_sd=False``), restricted to the support -- the bounds,
and ``mean_0 < mean_1 < ... < mean_{q-1}`` so that labels cannot switch. Defaults,
weakly informative and stated in every result: ``m0`` the mean and ``s0`` the range of
the observed ``y``; ``a0 = 1``, ``b0 = var(y) / 100``; supports ``m0 ± 10 s0`` for the
means and ``(1e-6 s0, 10 s0)`` for the sds. A parameter given ``bounds`` has the flat
prior on them instead (on the sd itself, not its square).

The update draws, given the labels, every free sd from its inverse-gamma full
conditional (``a0 + n/2``, ``b0 + SS/2``; flat: ``(n - 1)/2``, ``SS/2``) and then
every free mean in turn from its normal full conditional (precision
``1/s0^2 + n_a / sd_a^2``) truncated to its bounds and its neighbours in the ordering:
a Gibbs scan of the exact full conditionals (:mod:`~mrfpe.models.emissions.truncated`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit

from mrfpe.models.emissions.base import (
    BoundEmission,
    Emission,
    check_prior_pair,
    observed_values,
    ordered_prior_draw,
    resolve_bounds,
)
from mrfpe.models.emissions.truncated import (
    ordered_mode,
    truncated_inverse_gamma,
    truncated_normal,
)
from mrfpe.validation import check_bool

__all__ = ["Gaussian", "gaussian"]

_HALF_LOG_2PI = 0.5 * np.log(2 * np.pi)


class Gaussian(Emission):
    """``N(mean_a, sd^2)`` per state ``a`` (see the module docstring).

    Parameters
    ----------
    shared_sd : bool
        One ``sd`` for every state (default) or ``sd_0 .. sd_{q-1}``.
    mean_prior : tuple or None
        ``(m0, s0)``: the normal prior of every mean (default: mean and range of the observed data).
    sd_prior : tuple or None
        ``(a0, b0)``: the inverse-gamma prior (shape, scale) of every variance
        (default ``(1, var(y)/100)``).
    """

    name = "gaussian"
    ordered = True
    data_kind = "real"

    def __init__(self, shared_sd: bool = True, mean_prior: Any = None,
                 sd_prior: Any = None) -> None:
        self.shared_sd = check_bool("shared_sd", shared_sd)
        self.mean_prior = check_prior_pair("mean_prior", mean_prior, "(mean m0, sd s0)")
        self.sd_prior = check_prior_pair("sd_prior", sd_prior,
                                         "(shape a0, scale b0) of the inverse gamma")

    def param_names(self, q: int) -> tuple[str, ...]:
        sds = ("sd",) if self.shared_sd else tuple(f"sd_{a}" for a in range(q))
        return (*(f"mean_{a}" for a in range(q)), *sds)

    def bind(self, q: int, y: np.ndarray, observed: np.ndarray,
             covariates: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]],
             ) -> BoundGaussian:
        v = observed_values(y, observed)
        scale = float(np.ptp(v)) if v.size and np.ptp(v) > 0 else 1.0
        m0, s0 = self.mean_prior or (float(v.mean()) if v.size else 0.0, scale)
        a0, b0 = self.sd_prior or (1.0, max(float(v.var()) if v.size else 0.0, 1e-12 * scale ** 2)
                                   / 100.0)
        names = self.param_names(q)
        n_sd = len(names) - q
        default = np.array([(m0 - 10 * s0, m0 + 10 * s0)] * q
                           + [(1e-6 * scale, 10 * max(scale, s0))] * n_sd)
        domain = np.array([(-np.inf, np.inf)] * q + [(np.finfo(float).tiny, np.inf)] * n_sd)
        b, flat = resolve_bounds(names, default, bounds, domain)
        return BoundGaussian(self, q, y, observed, names, b, flat, (m0, s0, a0, b0))

    def simulate(self, x: np.ndarray, params: np.ndarray, rng: np.random.Generator,
                 covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        q = len(params) - (1 if self.shared_sd else len(params) // 2)
        mean, sd = _split(np.asarray(params, float)[None], q, self.shared_sd)
        x = np.asarray(x, dtype=np.int64)
        return mean[0, x] + sd[0, x] * rng.standard_normal(x.shape)

    def describe(self) -> dict:
        return {**super().describe(), "shared_sd": self.shared_sd,
                "mean_prior": self.mean_prior, "sd_prior": self.sd_prior}


def _split(p: np.ndarray, q: int, shared: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(means (N, q), sds (N, q))`` of parameter vectors ``p`` (N, d)."""
    sd = np.repeat(p[:, q:q + 1], q, axis=1) if shared else p[:, q:2 * q]
    return p[:, :q], sd


@njit(cache=True)
def _normal_log_density(yo, mean, sd, out) -> None:
    """``out[k, i, a] = log N(yo[i]; mean[k, a], sd[k, a]^2)``, in one pass."""
    N, q = mean.shape
    for k in range(N):
        r, c = 1.0 / sd[k], np.log(sd[k]) + _HALF_LOG_2PI
        for i in range(yo.size):
            for a in range(q):
                z = (yo[i] - mean[k, a]) * r[a]
                out[k, i, a] = -0.5 * z * z - c[a]


@njit(cache=True)
def _normal_log_density_at(yo, xo, mean, sd) -> np.ndarray:
    """``sum_i log N(yo[i]; mean[k, xo[i]], sd[k, xo[i]]^2)`` (N,), in one pass."""
    N = mean.shape[0]
    out = np.zeros(N)
    for k in range(N):
        r, c = 1.0 / sd[k], np.log(sd[k]) + _HALF_LOG_2PI
        for i in range(yo.size):
            a = np.uint32(xo[i])  # a state: no negative-index wraparound
            z = (yo[i] - mean[k, a]) * r[a]
            out[k] -= 0.5 * z * z + c[a]
    return out


class BoundGaussian(BoundEmission):
    """The Gaussian emission on one data set (see :class:`Gaussian`)."""

    conjugate = True

    def __init__(self, emission: Gaussian, q: int, y: np.ndarray, observed: np.ndarray,
                 names: tuple[str, ...], bounds: np.ndarray, flat: np.ndarray,
                 hyper: tuple[float, float, float, float]) -> None:
        super().__init__(emission, q, y, observed, names, bounds, flat)
        self.shared = emission.shared_sd
        self.m0, self.s0, self.a0, self.b0 = (float(h) for h in hyper)
        self._cache()

    def _cache(self) -> None:
        self.yo = observed_values(self.y, self.observed)

    def _log_lik_observed(self, params: np.ndarray) -> np.ndarray:
        mean, sd = _split(params, self.q, self.shared)
        out = np.empty((params.shape[0], self.yo.size, self.q))
        _normal_log_density(self.yo, mean, sd, out)
        return out

    def log_lik_at(self, params: Any, x: np.ndarray) -> np.ndarray:
        mean, sd = _split(self.as_params(params), self.q, self.shared)
        xo = np.asarray(x, dtype=np.int64)
        xo = xo if self.yo.size == xo.size else xo[self.observed]
        return _normal_log_density_at(self.yo, xo, mean, sd)

    def log_prior(self, params: Any) -> np.ndarray:
        p = self.as_params(params)
        q = self.q
        lp = np.zeros(p.shape[0])
        for k in range(self.d):
            if self.flat[k]:
                continue
            if k < q:
                lp -= 0.5 * ((p[:, k] - self.m0) / self.s0) ** 2
            else:  # inverse gamma on v = sd^2, written as a density of sd: |dv/dsd| = 2 sd
                v = p[:, k] ** 2
                lp += -(self.a0 + 1) * np.log(v) - self.b0 / v + np.log(2 * p[:, k])
        return np.where(self.in_support(p), lp, -np.inf)

    def _stats(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per state: observed count and sum of ``y``."""
        xo = np.asarray(x)[self.observed]
        return (np.bincount(xo, minlength=self.q).astype(float),
                np.bincount(xo, weights=self.yo, minlength=self.q))

    def update(self, params: np.ndarray, x: np.ndarray, rng: np.random.Generator,
               free: np.ndarray) -> np.ndarray:
        p = np.array(params, dtype=float)
        q = self.q
        xo = np.asarray(x)[self.observed]
        n, s = self._stats(x)
        u = rng.random(self.d)
        resid2 = (self.yo - p[xo]) ** 2
        if self.shared:
            groups = [(q, np.ones(q, bool))]
        else:
            groups = [(q + a, np.arange(q) == a) for a in range(q)]
        for k, states in groups:  # variances given the means
            if not free[k]:
                continue
            nk = float(n[states].sum())
            ss = float(resid2[states[xo]].sum())
            a, b = ((nk - 1) / 2, ss / 2) if self.flat[k] else (self.a0 + nk / 2,
                                                                 self.b0 + ss / 2)
            lo, hi = self.bounds[k] ** 2
            p[k] = np.sqrt(truncated_inverse_gamma(a, b, lo, hi, u[k]))
        _, sd = _split(p[None], q, self.shared)
        for k in range(q):  # means given the variances, each within its neighbours
            if not free[k]:
                continue
            prec0 = 0.0 if self.flat[k] else 1.0 / self.s0 ** 2
            prec = prec0 + n[k] / sd[0, k] ** 2
            centre = (prec0 * self.m0 + s[k] / sd[0, k] ** 2) / prec if prec > 0 else 0.0
            lo, hi = self._interval(p, k)
            p[k] = truncated_normal(centre, prec, lo, hi, u[k])
        return p

    def _interval(self, p: np.ndarray, k: int) -> tuple[float, float]:
        """Where mean ``k`` may go: its bounds, cut by its neighbours in the ordering."""
        lo, hi = self.bounds[k]
        if k > 0:
            lo = max(lo, p[k - 1])
        if k < self.q - 1:
            hi = min(hi, p[k + 1])
        return lo, hi

    def map_update(self, params: np.ndarray, resp: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Conditional modes given soft assignments ``resp`` (n, q): the means (ordered, by
        pool-adjacent-violators) at the current sds, then the sds at the new means."""
        p = np.array(params, dtype=float)
        q, r = self.q, np.asarray(resp, float)[self.observed]
        n, s = r.sum(axis=0), r.T @ self.yo
        _, sd = _split(p[None], q, self.shared)
        prec0 = np.where(self.flat[:q], 0.0, 1.0 / self.s0 ** 2)
        num, den = prec0 * self.m0 + s / sd[0] ** 2, prec0 + n / sd[0] ** 2
        mode = ordered_mode(num, den, p[:q])
        p[:q] = np.where(free[:q], np.clip(mode, self.bounds[:q, 0], self.bounds[:q, 1]), p[:q])
        ss = (r * (self.yo[:, None] - p[None, :q]) ** 2).sum(axis=0)
        for k in range(q, self.d):
            states = slice(None) if self.shared else slice(k - q, k - q + 1)
            nk, sk = float(n[states].sum()), float(ss[states].sum())
            # the mode in sd itself (the parameter the prior's density is over): flat,
            # SS / n; inverse gamma on sd^2, (SS + 2 b0) / (n + 2 a0 + 1)
            v = sk / max(nk, 1e-300) if self.flat[k] else (sk + 2 * self.b0) / (
                nk + 2 * self.a0 + 1)
            if free[k]:
                p[k] = float(np.clip(np.sqrt(v), *self.bounds[k]))
        return p

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """Means at the quantiles ``(a + 1/2)/q`` of the observed data, the sd(s) their
        spread over ``2q``; labels: the nearest mean."""
        q, v = self.q, self.yo
        mean = np.quantile(v, (np.arange(q) + 0.5) / q) if v.size else np.zeros(q)
        mean = strictly_increasing(mean, float(np.ptp(v)) if v.size else 1.0)
        sd = max(float(v.std()) / q if v.size else 1.0, 1e-3 * max(float(np.ptp(v)), 1e-12))
        p = np.concatenate([mean, np.full(self.d - q, sd)])
        p = np.clip(p, self.bounds[:, 0], self.bounds[:, 1])
        labels = np.argmin(np.abs(self.y[:, None] - mean[None]), axis=1)
        return p, labels.astype(np.int64)

    def prior_sample(self, rng: np.random.Generator) -> np.ndarray:
        def mean(k: int, u: float) -> float:
            prec = 0.0 if self.flat[k] else self.s0 ** -2
            return truncated_normal(self.m0, prec, *self.bounds[k], u)

        p = np.empty(self.d)
        p[: self.q] = ordered_prior_draw(mean, self, rng)
        for k in range(self.q, self.d):
            lo, hi = self.bounds[k]
            a, b = (-0.5, 0.0) if self.flat[k] else (self.a0, self.b0)
            p[k] = np.sqrt(truncated_inverse_gamma(a, b, lo ** 2, hi ** 2, rng.random()))
        return p

    def describe_prior(self) -> dict:
        out = {}
        for k, name in enumerate(self.names):
            lo, hi = self.bounds[k]
            if self.flat[k]:
                dist = f"flat on [{lo:.6g}, {hi:.6g}]"
            elif k < self.q:
                dist = f"N({self.m0:.6g}, {self.s0:.6g}^2) on [{lo:.6g}, {hi:.6g}]"
            else:
                dist = f"{name}^2 ~ InvGamma({self.a0:.6g}, {self.b0:.6g}), {name} in " \
                       f"[{lo:.6g}, {hi:.6g}]"
            out[name] = dist
        out["order"] = "mean_0 < mean_1 < ..."
        return out


def strictly_increasing(v: np.ndarray, scale: float) -> np.ndarray:
    """``v`` made strictly increasing by nudging ties apart by ``1e-6 scale``."""
    out = np.array(v, dtype=float)
    step = 1e-6 * (scale if scale > 0 else 1.0)
    for k in range(1, out.size):
        out[k] = max(out[k], out[k - 1] + step)
    return out


def gaussian(shared_sd: bool = True, mean_prior: Any = None, sd_prior: Any = None) -> Gaussian:
    """The Gaussian emission (see :class:`Gaussian`)."""
    return Gaussian(shared_sd=shared_sd, mean_prior=mean_prior, sd_prior=sd_prior)
