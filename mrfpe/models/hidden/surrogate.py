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

Validation. A mean off by ``δμ`` moves the synthetic posterior of ``θ`` by about
``Σ⁻¹ δμ``, i.e. ``z = sqrt(δμᵀ Σ⁻¹ δμ)`` posterior sds. In one dimension the mean is
simulated at the midpoint of every interval of the design and compared with the
interpolant; intervals with ``z > tol`` are split (the midpoint joins the design) until
none fails or ``max_design`` points are spent. In several dimensions ``n_validation``
Sobol points are checked. :meth:`Surrogate.error_within` is the largest ``z`` of the
checks in the posterior's range; the sampler flags its result when it exceeds the
tolerance :data:`SURROGATE_TOL` (an error far from the posterior does not move it).

Each design point's simulations (the MRF's simulator, Swendsen-Wang where it applies)
take a seed derived from ``seed`` and the point itself, so a design simulated on a
``dask.distributed`` client (``client=``) gives the same numbers as a local one.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator, RBFInterpolator
from scipy.stats import qmc

from mrfpe.models.design import Design
from mrfpe.models.simulate import simulate
from mrfpe.validation import check_positive_int, check_seed

__all__ = ["MIN_ESS", "SURROGATE_TOL", "PointMoments", "Surrogate", "build_surrogate",
           "check_surrogate", "is_log_linear", "statistic_chain"]

#: Largest mean error of the surrogate, in posterior sds of θ, a reliable result may have.
SURROGATE_TOL = 0.15
#: Effective draws a design point's chain is lengthened to (its mean's noise: 0.05 sd).
MIN_ESS = 400.0
_NO_CHECKS = np.empty((0, 3))
#: Bytes of draws held at once per chunk of a statistics chain.
_CHUNK_BYTES = 2e7


def is_log_linear(design: Design, d: int) -> bool:
    """Whether the design's feature map is the identity (``psi(θ) = θ``, ``d`` features)."""
    if design.n_features != d:
        return False
    probe = np.random.default_rng(0).standard_normal((3, d))
    return bool(np.array_equal(design.psi(probe), probe))


def statistic_chain(design: Design, psi: np.ndarray, columns: np.ndarray, n_sweeps: int, *,
                    seed: int, init: Any = "random", burn_in: int = 0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``S(x)[columns]`` after each of ``n_sweeps`` sweeps of the MRF's simulator at ``psi``
    (Swendsen-Wang where it applies, else Gibbs), after ``burn_in`` sweeps: ``(n_sweeps,
    k)``, and the chain's last state (to continue it). The draws are held a chunk at a
    time, never all at once."""
    rng = np.random.default_rng(seed)
    chunk = int(max(1, min(250, _CHUNK_BYTES // (8 * design.graph.n_nodes))))
    rows, done, sweeps = [], 0, burn_in + 1
    while done < n_sweeps:
        m = min(chunk, n_sweeps - done)
        y = simulate(design, psi, m, seed=int(rng.integers(2**63)), method="auto",
                     n_sweeps=sweeps, thin=1, init=init)
        rows.append(design.statistics(y)[:, columns])
        init, done, sweeps = y[-1], done + m, 1
    return np.concatenate(rows), np.asarray(init)


def _tau(s: np.ndarray) -> float:
    """The largest integrated autocorrelation time of the columns of ``s`` (emcee's)."""
    import logging

    from emcee.autocorr import integrated_time

    logging.getLogger("emcee.autocorr").setLevel(logging.ERROR)  # short chains are judged here
    sd = s.std(axis=0)
    moving = sd > 0
    if not moving.any():
        return 1.0
    z = (s[:, moving] - s[:, moving].mean(axis=0)) / sd[moving]
    return max(1.0, float(np.max(integrated_time(z[:, None, :], quiet=True))))


@dataclass(frozen=True)
class PointMoments:
    """The simulated moments of ``S_F`` at one design point."""

    theta: np.ndarray  # (d,)
    mean: np.ndarray  # (k,)
    cov: np.ndarray  # (k, k)
    ess: float  # effective draws: n_sweeps / the largest integrated autocorrelation time
    n_sweeps: int  # the chain's length (after burn-in)


def moments_at(design: Design, full: np.ndarray, free: np.ndarray, n_sweeps: int,
               burn_in: int, seed: int, min_ess: float = MIN_ESS,
               max_sweeps: int | None = None) -> PointMoments:
    """Mean, covariance and effective sample size of ``S_F`` at the full MRF vector
    ``full``: a chain of ``n_sweeps`` sweeps after ``burn_in``, doubled until it holds
    ``min_ess`` effective draws or ``max_sweeps`` (default ``32 n_sweeps``) sweeps -- near a
    first-order transition Swendsen-Wang's autocorrelation time runs to hundreds of sweeps.
    A pure function of its arguments: what a dask worker runs."""
    cap = 32 * n_sweeps if max_sweeps is None else max_sweeps
    rng = np.random.default_rng(seed)
    psi = design.psi(full[None])[0]
    s, last = statistic_chain(design, psi, free, n_sweeps, seed=int(rng.integers(2**63)),
                              burn_in=burn_in)
    tau = _tau(s)
    while len(s) / tau < min_ess and len(s) < cap:
        more, last = statistic_chain(design, psi, free, min(len(s), cap - len(s)),
                                     seed=int(rng.integers(2**63)), init=last)
        s = np.concatenate([s, more])
        tau = _tau(s)
    cov = np.atleast_2d(np.cov(s, rowvar=False))
    return PointMoments(full[free].copy(), s.mean(axis=0), cov, len(s) / tau, len(s))


def _point_seed(seed: int, theta: np.ndarray) -> int:
    """A seed of its own for each design point: the same wherever the point is simulated."""
    words = np.frombuffer(np.ascontiguousarray(theta, np.float64).tobytes(), np.uint32)
    return int(np.random.SeedSequence([seed, *words.tolist()]).generate_state(2, np.uint64)[0]
               >> np.uint64(1))


def _simulate_points(design: Design, fixed_full: np.ndarray, free: np.ndarray,
                     points: np.ndarray, n_sweeps: int, burn_in: int, seed: int,
                     client: Any) -> list[PointMoments]:
    """The moments at every point, locally or as one task per point on ``client``."""
    fulls = []
    for p in points:
        f = fixed_full.copy()
        f[free] = p
        fulls.append(f)
    seeds = [_point_seed(seed, p) for p in points]
    if client is None:
        return [moments_at(design, f, free, n_sweeps, burn_in, s) for f, s in zip(fulls, seeds,
                                                                                 strict=True)]
    try:
        futures = client.map(moments_at, [design] * len(fulls), fulls, [free] * len(fulls),
                             [n_sweeps] * len(fulls), [burn_in] * len(fulls), seeds, pure=False)
        return list(client.gather(futures))
    except Exception as exc:  # a client that is gone, a worker that died: nothing is kept
        raise RuntimeError(f"the surrogate's design simulations failed on the dask client "
                           f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                           f"; no surrogate was built") from exc


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


def _errors(surrogate: Surrogate, checks: list[PointMoments]) -> np.ndarray:
    """Each check point's mean error in posterior sds (Mahalanobis in its simulated Σ)."""
    out = np.empty(len(checks))
    for i, c in enumerate(checks):
        mu, _ = surrogate.moments(c.theta[None])
        r = mu[0] - c.mean
        out[i] = math.sqrt(max(0.0, float(r @ np.linalg.pinv(c.cov) @ r)))
    return out


def build_surrogate(target: Any, *, seed: int, client: Any = None, n_design: int = 17,
                    max_design: int = 65, n_sweeps: int = 1000, burn_in: int = 200,
                    n_validation: int = 16, tol: float = SURROGATE_TOL) -> Surrogate:
    """The surrogate of a hidden target's MRF over its free MRF parameters' bounds.

    Parameters
    ----------
    target : HiddenTarget
        Its MRF must be log-linear in the free parameters (every built-in Potts, Ising
        and autologistic model is); its data are not used.
    seed : every simulation derives from it (and from each design point's value).
    client : a ``dask.distributed.Client``, optional: one task per design point.
    n_design, max_design : points of the first design, and the most after refinement.
    n_sweeps, burn_in : sweeps of the simulator per design point, after ``burn_in``,
        lengthened up to 32-fold until the point holds :data:`MIN_ESS` effective draws.
    n_validation : check points in several dimensions (one dimension: every midpoint).
    tol : the mean error, in posterior sds, above which an interval is split.
    """
    check_seed(seed)
    for name, v in (("n_design", n_design), ("max_design", max_design), ("n_sweeps", n_sweeps),
                    ("n_validation", n_validation)):
        check_positive_int(name, v, minimum=2)
    check_positive_int("burn_in", burn_in, 0)
    design = target.design
    free = np.flatnonzero(target.free[: target.n_mrf])
    if not free.size:
        raise ValueError("method='surrogate' needs a free MRF parameter; every one is fixed")
    if not is_log_linear(design, target.n_mrf):
        raise ValueError(f"method='surrogate' needs an MRF log-linear in its parameters (the "
                         f"sufficient statistics' moments are its map); {target.model.mrf.name!r}"
                         f" has a feature map: use method='exchange'")
    box = target.all_bounds[: target.n_mrf][free]
    fixed_full = np.where(target.free[: target.n_mrf], 0.0, target.fixed_values[: target.n_mrf])
    sim = (design, fixed_full, free)
    if free.size == 1:
        points = np.linspace(box[0, 0], box[0, 1], n_design)[:, None]
    else:
        points = qmc.scale(qmc.Sobol(free.size, seed=seed).random(n_design * free.size),
                           box[:, 0], box[:, 1])
    done = _simulate_points(*sim, points, n_sweeps, burn_in, seed, client)

    def make(pm: list[PointMoments], checks: np.ndarray) -> Surrogate:
        return Surrogate(tuple(target.all_names[i] for i in free),
                         np.where(target.free[: target.n_mrf], np.nan, fixed_full),
                         box[:, 0].copy(), box[:, 1].copy(), np.array([p.theta for p in pm]),
                         np.array([p.mean for p in pm]), np.array([p.cov for p in pm]),
                         np.array([p.ess for p in pm]), checks, target.node_shape, target.q,
                         target.model.mrf.name)

    if free.size > 1:
        checks_at = qmc.scale(qmc.Sobol(free.size, seed=seed + 1).random(n_validation),
                              box[:, 0], box[:, 1])
        checks = _simulate_points(*sim, checks_at, n_sweeps, burn_in, seed, client)
        errors = _errors(make(done, _NO_CHECKS), checks)
        return make(done, np.column_stack([checks_at, checks_at, errors]))
    return _refine_1d(make, sim, done, n_sweeps, burn_in, seed, client, max_design, tol)


def _refine_1d(make: Any, sim: tuple, done: list[PointMoments], n_sweeps: int, burn_in: int,
               seed: int, client: Any, max_design: int, tol: float) -> Surrogate:
    """Split every interval whose midpoint the interpolant misses by more than ``tol``."""
    t = np.sort([p.theta[0] for p in done])
    todo = list(itertools.pairwise(t))
    worst: dict[tuple[float, float], float] = {}
    while todo:
        mids = np.array([[(a + b) / 2] for a, b in todo])
        checks = _simulate_points(*sim, mids, n_sweeps, burn_in, seed, client)
        errors = _errors(make(done, _NO_CHECKS), checks)
        split = []
        for (a, b), c, e in zip(todo, checks, errors, strict=True):
            worst[(a, b)] = e
            if e > tol and len(done) < max_design:
                done.append(c)
                split += [(a, c.theta[0]), (c.theta[0], b)]
                worst.pop((a, b))
        todo = split
    return make(done, np.array([[a, b, e] for (a, b), e in sorted(worst.items())]))


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
