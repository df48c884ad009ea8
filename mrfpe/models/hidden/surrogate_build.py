"""Building a :class:`~mrfpe.models.hidden.surrogate.Surrogate`: the design's simulations.

:func:`build_surrogate` simulates the MRF (no data) at a design of values of its free
parameters over their bounds -- Swendsen-Wang where it applies, else Gibbs -- each point's
chain lengthened until it holds :data:`MIN_ESS` effective draws of the sufficient
statistics (at most 32 times its ``n_sweeps``: near a first-order transition the
autocorrelation time runs to hundreds of sweeps), and refines the design where the
interpolant misses a fresh simulation (in one dimension: every interval's midpoint,
split while it is off by more than the tolerance; in several: Sobol check points). Each
design point's simulations take a seed derived from ``seed`` and the point itself, so a
design simulated on a ``dask.distributed`` client (``client=``, one task per point, as
the study runner's cluster path) gives the same numbers as a local one; a client that
fails mid-run is an error and no surrogate.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import qmc

from mrfpe.models.design import Design
from mrfpe.models.hidden.surrogate import SURROGATE_TOL, Surrogate, is_log_linear
from mrfpe.models.mixing import statistics_tau
from mrfpe.models.simulate import simulate
from mrfpe.validation import check_positive_int, check_seed

__all__ = ["MIN_ESS", "PointMoments", "build_surrogate", "moments_at", "statistic_chain"]

#: Effective draws a design point's chain is lengthened to (its mean's noise: 0.05 sd).
MIN_ESS = 400.0
_NO_CHECKS = np.empty((0, 3))
#: Bytes of draws held at once per chunk of a statistics chain.
_CHUNK_BYTES = 2e7


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
    """τ of a design point's statistics (:func:`~mrfpe.models.mixing.statistics_tau`), at
    least one sweep."""
    return max(1.0, statistics_tau(s))


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


