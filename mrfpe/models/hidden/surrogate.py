"""A pre-computed surrogate of a log-linear MRF's likelihood, for hidden fields.

For a log-linear MRF ``p(x | θ) = exp(θ·S(x)) / Z(θ)`` the likelihood of the free
parameters ``θ_F`` depends on the labels only through ``S_F(x)`` (their columns of the
sufficient statistics), and the density of ``S_F`` at ``θ`` is proportional to it.
Moores, Drovandi, Mengersen & Robert (2015) pre-compute the mean ``μ(θ)`` and the
covariance ``Σ(θ)`` of ``S_F`` over a design of ``θ`` values -- once per lattice, since
they do not depend on the image -- and use ``N(μ(θ), Σ(θ))`` in place of the
simulations inside the sampler: the Gaussian synthetic likelihood (Wood 2010)

    ``log L(θ) ≈ log N(S_F(x); μ(θ), Σ(θ))``.

Its error in the posterior mean is of a smaller order than the posterior sd: expanding
both about the point where ``μ(θ̂) = S_F(x)``, the exact log-likelihood and the synthetic
one give the same first skew correction ``-κ₃ / (2 σ⁴)`` (the ``-log σ(θ)`` term of the
normal density carries it).

Interpolation between design points uses the score identity ``∂μ/∂θ = Σ(θ)`` of a
log-linear model, the known property Moores, Pettitt & Mengersen (2020) build their
integral curve on: in one dimension the mean is a cubic Hermite spline through ``μ(θ_k)``
with slopes ``Σ(θ_k)``, and ``Σ``'s Cholesky factor (log-diagonal) a PCHIP curve; in
several, thin-plate radial basis functions (``scipy.interpolate.RBFInterpolator``) of
both.

Validation (:func:`~mrfpe.models.hidden.surrogate_build.build_surrogate`, which simulates
the design). A mean off by ``δμ`` moves the synthetic posterior of ``θ`` by about ``Σ⁻¹
δμ``, i.e. ``z = sqrt(δμᵀ Σ⁻¹ δμ)`` posterior sds. In one dimension the mean is
simulated at the midpoint of every interval of the design and compared with the
interpolant; intervals with ``z > tol`` are split (the midpoint joins the design) until
none fails or ``max_design`` points are spent. In several dimensions ``n_validation``
Sobol points are checked. :meth:`Surrogate.error_within` is the largest ``z`` of the
checks in the posterior's range; the sampler flags its result when it exceeds the
tolerance :data:`SURROGATE_TOL` (an error far from the posterior does not move it).

A surrogate depends on the lattice, not on an image: :meth:`Surrogate.save` writes it
(``.npz``: the design's moments and what it was built for) and :meth:`Surrogate.load`
reads it back, for every later image of that shape; it also pickles (to a dask worker).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator, RBFInterpolator

from mrfpe.models.design import Design

__all__ = ["SURROGATE_TOL", "Surrogate", "check_surrogate", "is_log_linear"]

#: Largest mean error of the surrogate, in posterior sds of θ, a reliable result may have.
SURROGATE_TOL = 0.15


def is_log_linear(design: Design, d: int) -> bool:
    """Whether the design's feature map is the identity (``psi(θ) = θ``, ``d`` features)."""
    if design.n_features != d:
        return False
    probe = np.random.default_rng(0).standard_normal((3, d))
    return bool(np.array_equal(design.psi(probe), probe))


@dataclass
class Surrogate:
    """Mean and covariance of the free MRF parameters' sufficient statistics, over θ.

    Attributes
    ----------
    names : the free MRF parameters (the design's axes)
    fixed : every MRF parameter's value where fixed (NaN where free)
    low, high : (d,) the design's box
    points, means, covs, ess : the design: (K, d), (K, k), (K, k, k), (K,)
    checks : (m, 2 d + 1) each validation check's region (low corner, high corner: an
        interval of the design in one dimension, a point in several) and the interpolated
        mean's error there, in posterior sds (module docstring)
    node_shape, n_states, model : what the surrogate was built for
    """

    names: tuple[str, ...]
    fixed: np.ndarray
    low: np.ndarray
    high: np.ndarray
    points: np.ndarray
    means: np.ndarray
    covs: np.ndarray
    ess: np.ndarray
    checks: np.ndarray
    node_shape: tuple[int, ...]
    n_states: int
    model: str
    _fit: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        order = np.argsort(self.points[:, 0]) if self.points.shape[1] == 1 else slice(None)
        self.points, self.means, self.covs, self.ess = (self.points[order], self.means[order],
                                                        self.covs[order], self.ess[order])
        self._fit = _fit(self.points, self.means, self.covs)

    @property
    def n_design(self) -> int:
        return int(self.points.shape[0])

    @property
    def validation_error(self) -> float:
        """The largest mean error of every check, in posterior sds."""
        return float(self.checks[:, -1].max()) if self.checks.size else math.nan

    def error_within(self, low: Any, high: Any) -> float:
        """The largest error of the checks whose region meets the box ``[low, high]`` (the
        posterior's range: an error far from the posterior does not move it); every
        check's where none does."""
        d = len(self.names)
        lo, hi, z = self.checks[:, :d], self.checks[:, d:2 * d], self.checks[:, -1]
        near = np.all((hi >= np.asarray(low)) & (lo <= np.asarray(high)), axis=1)
        return float(z[near].max()) if near.any() else self.validation_error

    def moments(self, theta: Any) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated ``(μ (N, k), lower Cholesky factor of Σ (N, k, k))`` at θ (N, d)."""
        th = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        mean_fn, chol_fn = self._fit
        return mean_fn(th), chol_fn(th)

    def log_lik(self, s: np.ndarray, theta: Any) -> np.ndarray:
        """``log N(s; μ(θ), Σ(θ))`` (N,) of the statistics ``s`` (k,) at θ (N, d)."""
        mu, L = self.moments(theta)
        r = np.asarray(s, dtype=np.float64)[None, :] - mu
        z = np.linalg.solve(L, r[..., None])[..., 0]
        logdet = np.log(np.abs(np.diagonal(L, axis1=1, axis2=2))).sum(axis=1)
        return -0.5 * (z ** 2).sum(axis=1) - logdet - 0.5 * r.shape[1] * math.log(2 * math.pi)

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_fit"}  # rebuilt on load

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._fit = _fit(self.points, self.means, self.covs)

    def save(self, path: Any) -> None:
        """Write the surrogate to ``path`` (``.npz``; the interpolants are rebuilt on load)."""
        meta = {"names": list(self.names), "node_shape": list(self.node_shape),
                "n_states": self.n_states, "model": self.model, "format": 1}
        np.savez_compressed(path, fixed=self.fixed, low=self.low, high=self.high,
                            points=self.points, means=self.means, covs=self.covs,
                            ess=self.ess, checks=self.checks, meta=np.array(json.dumps(meta)))

    @classmethod
    def load(cls, path: Any) -> Surrogate:
        """A surrogate written by :meth:`save`; ValueError naming the file if it is none."""
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in ("fixed", "low", "high", "points", "means",
                                            "covs", "ess", "checks")}
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not a surrogate written by Surrogate.save "
                             f"({type(exc).__name__}: {exc})") from None
        return cls(tuple(meta["names"]), arrays["fixed"], arrays["low"], arrays["high"],
                   arrays["points"], arrays["means"], arrays["covs"], arrays["ess"],
                   arrays["checks"], tuple(meta["node_shape"]), int(meta["n_states"]),
                   str(meta["model"]))

    def describe(self) -> dict:
        return {"names": list(self.names), "low": self.low.tolist(), "high": self.high.tolist(),
                "n_design": self.n_design, "min_ess": float(self.ess.min()),
                "validation_error": self.validation_error, "node_shape": list(self.node_shape),
                "n_states": self.n_states, "model": self.model,
                "reference": "Moores, Drovandi, Mengersen & Robert (2015); Wood (2010)"}

    def __repr__(self) -> str:
        return f"Surrogate({json.dumps(self.describe())})"


def _chol_entries(covs: np.ndarray) -> np.ndarray:
    """(K, k(k+1)/2): Cholesky factors with log diagonals, flattened (smooth in θ)."""
    k = covs.shape[1]
    L = np.linalg.cholesky(covs + 1e-12 * np.eye(k) * np.trace(covs, axis1=1, axis2=2)
                           [:, None, None] / k)
    rows, cols = np.tril_indices(k)
    out = L[:, rows, cols].copy()
    diag = rows == cols
    out[:, diag] = np.log(out[:, diag])
    return out


def _chol_from(entries: np.ndarray, k: int) -> np.ndarray:
    rows, cols = np.tril_indices(k)
    diag = rows == cols
    e = entries.copy()
    e[:, diag] = np.exp(e[:, diag])
    L = np.zeros((e.shape[0], k, k))
    L[:, rows, cols] = e
    return L


def _fit(points: np.ndarray, means: np.ndarray, covs: np.ndarray) -> tuple[Any, Any]:
    """The interpolants ``θ -> μ`` and ``θ -> chol Σ`` (module docstring)."""
    k = means.shape[1]
    entries = _chol_entries(covs)
    if points.shape[1] == 1:
        t = points[:, 0]
        # ∂μ/∂θ = Σ: the Hermite slopes of a one-parameter log-linear model
        hermite = CubicHermiteSpline(t, means, covs[:, :, 0], axis=0, extrapolate=True)
        pchip = PchipInterpolator(t, entries, axis=0, extrapolate=True)
        return (lambda th: hermite(th[:, 0]),
                lambda th: _chol_from(pchip(th[:, 0]), k))
    rbf_mean = RBFInterpolator(points, means, kernel="thin_plate_spline")
    rbf_chol = RBFInterpolator(points, entries, kernel="thin_plate_spline")
    return rbf_mean, lambda th: _chol_from(rbf_chol(th), k)


def check_surrogate(surrogate: Any, target: Any) -> None:
    """ValueError unless ``surrogate`` was built for this target's lattice, states, free MRF
    parameters and fixed values, over a box that covers their bounds (their prior)."""
    if not isinstance(surrogate, Surrogate):
        raise ValueError(f"surrogate must be an mrfpe.models.hidden.Surrogate "
                         f"(build_surrogate(target, seed=...)); got {type(surrogate).__name__}")
    if target.method != "surrogate":
        raise ValueError(f"surrogate= is used by method='surrogate' only; got "
                         f"method={target.method!r}")
    free = np.flatnonzero(target.free[: target.n_mrf])
    names = tuple(target.all_names[i] for i in free)
    fixed = np.where(target.free[: target.n_mrf], np.nan, target.fixed_values[: target.n_mrf])
    built = (surrogate.model, tuple(surrogate.node_shape), surrogate.n_states, surrogate.names)
    wanted = (target.model.mrf.name, tuple(target.node_shape), target.q, names)
    if built != wanted or not np.array_equal(surrogate.fixed, fixed, equal_nan=True):
        raise ValueError(f"the surrogate was built for (model, node shape, states, free MRF "
                         f"parameters) = {built} with fixed values {surrogate.fixed.tolist()}; "
                         f"this target needs {wanted} with {fixed.tolist()}")
    box = target.all_bounds[: target.n_mrf][free]
    out = [f"{n} [{lo:g}, {hi:g}]" for n, (lo, hi), a, b in
           zip(names, box, surrogate.low, surrogate.high, strict=True) if lo < a or hi > b]
    if out:
        span = ", ".join(f"{a:g}..{b:g}" for a, b in zip(surrogate.low, surrogate.high,
                                                          strict=True))
        raise ValueError(f"the surrogate's design [{span}] does not cover the prior of "
                         f"{', '.join(out)}: narrow bounds= or "
                         f"build the surrogate on this target")
