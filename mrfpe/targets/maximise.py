"""Global maximiser of a target: a grid (or a Halton set) over the box, then bounded local
refinement.

A pseudolikelihood's maximum need not sit on the true parameters, so studies
report a sampler's distance to the target's own maximiser separately from its
distance to the truth; this module finds that maximiser.

1. Evaluate the target on an evenly spaced grid over its bounds (``grid``
   points per dimension, as the thesis's evenly spaced initial samples, 6.6.1),
   in batches through the target's vectorised ``log_prob``. The search's cost is
   bounded: where ``grid ** d`` exceeds ``max_points`` (20 per axis beyond three
   parameters), a scrambled Halton set of ``max_points`` points from ``seed``
   (Owen 2017) covers the box instead.
2. Refine the ``n_starts`` best points (plus ``n_random`` uniform random
   starts drawn from ``seed``) with a bounded local optimiser, in coordinates
   scaled to the unit cube (each parameter's range is one unit, so a precision
   in ``(0, 10^4)`` and a coupling in ``(-0.25, 0.25)`` are searched alike):

   * ``"pattern"`` (default): pattern search -- every iteration evaluates all
     starts' ``3^d - 1`` neighbours on the step's grid (``2 d`` axis neighbours
     for ``d > 4``) in *one* batched call, moves each start to its best
     neighbour and doubles its step (up to the first) if that improves, and
     otherwise halves it, until the step is below ``pattern_xtol``; then a bounded
     Nelder-Mead polish of the best point to ``xtol``. Needs no gradient, so it copes with
     the kinks of the absolute-value data energy (4.12): with noise-free data
     the maximum of a pseudolikelihood sits at such a kink.
   * ``"nelder-mead"`` / ``"l-bfgs-b"``: :func:`scipy.optimize.minimize` with the
     bounds. L-BFGS-B gets central-difference gradients from one batched call, and a
     trial point where the target is ``-inf`` (outside a model's valid region) is
     answered with a value above the current iterate's by twice the decrease the
     gradient predicted, so that the line search backtracks instead of stopping (a
     huge stand-in value made it interpolate a step of nearly zero and report
     convergence at its start).

Each result is checked: if the target rises within a small step of the point
returned (:func:`ascent_from`), the point is no local maximum and ``maximise`` says
so (a logged warning and ``info["message"]``).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from mrfpe.budget import check_memory
from mrfpe.validation import check_seed

__all__ = ["DEFAULT_MAX_POINTS", "METHODS", "ascent_from", "grid_points", "grid_size",
           "maximise"]

METHODS = ("pattern", "nelder-mead", "l-bfgs-b")
#: Most points of the default search (20^3: the thesis's grid for three parameters).
DEFAULT_MAX_POINTS = 8000

log = logging.getLogger(__name__)


def grid_size(n_points: int, d: int) -> int:
    """The largest ``k`` with ``k ** d <= n_points`` (exact integer root; at least 1).

    ``int(4096 ** (1 / 3))`` is 15, not 16, because ``4096 ** (1/3)`` rounds to
    15.999999999999998; this corrects the floating-point guess in integers.
    """
    if d < 1 or n_points < 1:
        raise ValueError(f"grid_size needs n_points >= 1 and d >= 1; got {n_points}, {d}")
    k = max(1, round(n_points ** (1.0 / d)))
    while k > 1 and k ** d > n_points:
        k -= 1
    while (k + 1) ** d <= n_points:
        k += 1
    return k


def grid_points(bounds: Any, n: int) -> np.ndarray:
    """Evenly spaced grid (n^d, d) over closed ``bounds`` (d, 2), bounds included."""
    b = np.asarray(bounds, dtype=np.float64)
    axes = [np.linspace(lo, hi, n) for lo, hi in b]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.reshape(-1) for m in mesh], axis=1)


def _eval(target: Any, pts: np.ndarray, batch: int) -> np.ndarray:
    out = np.empty(pts.shape[0])
    for a in range(0, pts.shape[0], batch):
        v = np.asarray(target.log_prob(pts[a:a + batch]), dtype=np.float64)
        out[a:a + batch] = np.where(np.isnan(v), -np.inf, v)
    return out


def _directions(d: int) -> np.ndarray:
    """All ``3^d - 1`` neighbours' directions for ``d <= 4``, the ``2 d`` axis ones beyond."""
    if d <= 4:  # follows ridges (kinks) that are not axis-aligned
        dirs = grid_points([[-1.0, 1.0]] * d, 3)
        return dirs[np.any(dirs != 0, axis=1)]
    return np.concatenate([np.eye(d), -np.eye(d)])


def _pattern(target, starts, f0, lo, hi, step0, xtol, max_iter, batch):
    x = starts.copy()
    f = f0.copy()
    d = x.shape[1]
    step = np.full(x.shape[0], float(step0))
    dirs = _directions(d)
    nd = dirs.shape[0]
    for _ in range(max_iter):
        active = np.flatnonzero(step >= xtol)
        if active.size == 0:
            break
        cand = x[active, None, :] + step[active, None, None] * (hi - lo) * dirs[None]
        cand = np.clip(cand, lo, hi).reshape(-1, d)
        fc = _eval(target, cand, batch).reshape(active.size, nd)
        best = np.argmax(fc, axis=1)
        fbest = fc[np.arange(active.size), best]
        better = fbest > f[active]
        idx = active[better]
        x[idx] = cand.reshape(active.size, nd, d)[better, best[better]]
        f[idx] = fbest[better]
        # expand on success (up to the first step), contract on failure (as in GPS/MADS):
        # a start crawling along a ridge regains its stride instead of running out of
        # iterations (measured: 501 -> 234 batched calls on one 100x100 Ward scene)
        step[idx] = np.minimum(2.0 * step[idx], step0)
        step[active[~better]] *= 0.5
    return x, f


def _value_and_gradient(target: Any, x: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                        ) -> tuple[float, np.ndarray]:
    """``log_prob`` at ``x`` and its gradient by central differences (one batched call).

    Steps of ``6e-6`` of the coordinate's magnitude (at least ``1e-3`` of its range):
    about the cube root of the float64 epsilon, where a central difference's truncation
    and rounding errors balance. One-sided where a neighbour leaves the box or is
    ``-inf``; zero where both are.
    """
    d = x.size
    h = 6e-6 * np.maximum(np.abs(x), 1e-3 * (hi - lo))
    xp, xm = np.minimum(x + h, hi), np.maximum(x - h, lo)
    pts = np.vstack([x[None], x + np.diag(xp - x), x + np.diag(xm - x)])
    v = np.asarray(target.log_prob(pts), dtype=np.float64)
    v = np.where(np.isnan(v), -np.inf, v)
    f0, fp, fm = v[0], v[1:d + 1], v[d + 1:]
    if not np.isfinite(f0):
        return float(f0), np.zeros(d)
    okp, okm = np.isfinite(fp) & (xp > x), np.isfinite(fm) & (xm < x)
    g = np.zeros(d)
    both = okp & okm
    g[both] = (fp[both] - fm[both]) / (xp[both] - xm[both])
    only_p, only_m = okp & ~okm, okm & ~okp
    g[only_p] = (fp[only_p] - f0) / (xp[only_p] - x[only_p])
    g[only_m] = (f0 - fm[only_m]) / (x[only_m] - xm[only_m])
    return float(f0), g


def _lbfgsb(target: Any, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            max_iter: int) -> np.ndarray:
    """L-BFGS-B from ``x0`` in unit-cube coordinates (see the module docstring)."""
    from scipy.optimize import minimize

    w = hi - lo
    seen: dict[bytes, tuple[float, np.ndarray]] = {}
    cur: dict[str, Any] = {}  # the line search's base: the current iterate

    def fg(z: np.ndarray) -> tuple[float, np.ndarray]:
        v, g = _value_and_gradient(target, lo + w * np.clip(z, 0.0, 1.0), lo, hi)
        if np.isfinite(v):
            seen[z.tobytes()] = (-v, -g * w)
            if not cur:
                cur.update(z=z.copy(), F=-v, G=-g * w)
            return -v, -g * w
        # -inf: a value above the iterate's by twice the predicted decrease, and a slope
        # pointing back, so the line search's interpolation backtracks by a fixed factor
        slope = abs(float(cur["G"] @ (z - cur["z"])))
        return cur["F"] + 2.0 * slope + 1e-10 * (1.0 + abs(cur["F"])), -cur["G"]

    def callback(intermediate_result: Any) -> None:
        z = np.asarray(intermediate_result.x, dtype=np.float64)
        if z.tobytes() in seen:
            F, G = seen[z.tobytes()]
            cur.update(z=z.copy(), F=F, G=G)

    res = minimize(fg, (x0 - lo) / w, jac=True, method="L-BFGS-B", bounds=[(0.0, 1.0)] * w.size,
                   callback=callback, options={"maxiter": max_iter})
    return lo + w * np.clip(res.x, 0.0, 1.0)


def _nelder_mead(target: Any, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, xtol: float,
                 max_iter: int) -> np.ndarray:
    """Bounded Nelder-Mead from ``x0`` in unit-cube coordinates: ``xtol`` is a fraction of
    each parameter's range, as documented."""
    from scipy.optimize import minimize

    w = hi - lo

    def neg(z: np.ndarray) -> float:
        v = float(target.log_prob((lo + w * np.clip(z, 0.0, 1.0))[None])[0])
        return 1e300 if not np.isfinite(v) else -v

    res = minimize(neg, (x0 - lo) / w, method="Nelder-Mead", bounds=[(0.0, 1.0)] * w.size,
                   options={"xatol": xtol, "fatol": 1e-10, "maxiter": max_iter})
    return lo + w * np.clip(res.x, 0.0, 1.0)


def _scipy(target, starts, f0, lo, hi, method, xtol, max_iter):
    xs, fs = [], []
    for x0, fx0 in zip(starts, f0, strict=True):
        x = (_nelder_mead(target, x0, lo, hi, xtol, max_iter) if method == "nelder-mead"
             else _lbfgsb(target, x0, lo, hi, max_iter))
        fx = float(target.log_prob(x[None])[0])
        if not fx > fx0:
            x, fx = x0, fx0
        xs.append(x)
        fs.append(fx)
    return np.array(xs), np.array(fs)


def ascent_from(target: Any, theta: Any, step: float = 1e-4) -> tuple[float, np.ndarray]:
    """How far ``log_prob`` rises within ``step`` (a fraction of each range) of ``theta``.

    Evaluates the pattern search's neighbours (:func:`_directions`) at that step, inside
    the box, in one call; returns ``(rise, best neighbour)``. A rise above zero means
    ``theta`` is no local maximum at that resolution.
    """
    b = np.asarray(target.bounds, dtype=np.float64)
    lo, hi = b[:, 0], b[:, 1]
    x = np.asarray(theta, dtype=np.float64).reshape(-1)
    cand = np.clip(x + step * (hi - lo) * _directions(x.size), lo, hi)
    v = _eval(target, np.vstack([x[None], cand]), len(cand) + 1)
    j = int(np.argmax(v[1:]))
    if v[1 + j] == -np.inf:
        return -np.inf, cand[j]
    return (np.inf if v[0] == -np.inf else float(v[1 + j] - v[0])), cand[j]


def maximise(target: Any, grid: int | Any = 20, *, seed: int | None = 0, n_starts: int = 4,
             n_random: int = 0, method: str = "pattern", xtol: float = 1e-6,
             pattern_xtol: float = 1e-4, max_iter: int = 500, batch: int = 8192,
             max_points: int = DEFAULT_MAX_POINTS, return_info: bool = False,
             ) -> tuple[np.ndarray, float] | tuple[np.ndarray, float, dict]:
    """Global maximiser of ``target.log_prob`` over ``target.bounds``.

    Parameters
    ----------
    target : Target
    grid : int or (M, d) array
        Points per dimension of the evenly spaced grid (bounds included), or the
        points themselves. An integer grid of more than ``max_points`` points is
        replaced by a scrambled Halton set of ``max_points`` points (from ``seed``),
        and the log (logger ``mrfpe.targets.maximise``, level INFO) and ``info`` say so.
    seed : int or None
        Seeds the Halton set and the ``n_random`` extra random starts.
    n_starts : int
        Best grid points refined locally.
    n_random : int
        Extra starts drawn uniformly in the bounds.
    method : "pattern" | "nelder-mead" | "l-bfgs-b"
    xtol : float
        Final step, as a fraction of each parameter's range (every local optimiser
        works in coordinates scaled to the unit cube).
    pattern_xtol : float
        Where the pattern search hands over to the Nelder-Mead polish (``method =
        "pattern"``; never below ``xtol``). Stopping compass steps at 1e-4 instead of
        1e-6, measured on 100×100 scenes with 20 labels (6 Ward, 4 Phong, float32): 47-123
        instead of 74-222 batched calls for Ward, 25-114 instead of 229-501 for Phong,
        1.2-4.9× less time; log_prob at the result within 3e-6 nats, the point within
        1e-4. At 1e-3 the polish, started 4e-3 from a kink, stopped 0.03 nats short on a
        24×24 scene (``tests/targets/test_maximise.py``).
    max_iter : int
        Iterations of the local optimiser.
    batch : int
        Rows per ``log_prob`` call on the grid.
    max_points : int
        Most points of an integer grid (:data:`DEFAULT_MAX_POINTS`, 20^3), whatever the
        dimension (20^5 points had not been searched after two minutes).
    return_info : bool
        Also return ``info``: ``grid`` ("product", "halton" or "given"), ``grid_points``,
        ``per_axis``, ``starts``, ``method``, ``rise`` (:func:`ascent_from` at the result)
        and ``message``, empty unless the result is no local maximum (also logged).

    Returns
    -------
    theta : (d,) ndarray
        The maximiser in the target's sampling space.
    log_prob : float
        ``target.log_prob(theta)``; ``-inf`` if the target is ``-inf`` everywhere tried.
    info : dict
        Only with ``return_info``.
    """
    b = np.asarray(target.bounds, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] < 1 or not np.all(np.isfinite(b)):
        raise ValueError(f"target.bounds must be a finite (d, 2) array; got {b.tolist()}")
    lo, hi = b[:, 0], b[:, 1]
    seed = _check_arguments(method, seed, n_starts, n_random, max_iter, batch, xtol,
                            pattern_xtol, max_points)
    pts, spacing, info = _grid(b, grid, max_points, seed)
    f = _eval(target, pts, batch)
    order = np.argsort(-f, kind="stable")
    starts, f0 = pts[order[:n_starts]], f[order[:n_starts]]
    if n_random:
        extra = lo + np.random.default_rng(seed).random((n_random, b.shape[0])) * (hi - lo)
        starts = np.vstack([starts, extra])
        f0 = np.concatenate([f0, _eval(target, extra, batch)])
    keep = np.isfinite(f0)
    info.update(starts=int(keep.sum()), method=method, rise=math.nan, message="")
    if not keep.any():
        info["message"] = "the target is -inf at every point tried"
        return _out(pts[order[0]].copy(), float(f[order[0]]), info, return_info)
    xs, fs = _refine(target, starts[keep], f0[keep], lo, hi, method, spacing, xtol,
                     pattern_xtol, max_iter, batch)
    j = int(np.argmax(fs))
    theta, value = ((xs[j].copy(), float(fs[j])) if fs[j] >= f[order[0]]
                    else (pts[order[0]].copy(), float(f[order[0]])))
    _judge(target, theta, value, max(xtol, 1e-4), info)
    return _out(theta, value, info, return_info)


def _judge(target: Any, theta: np.ndarray, value: float, step: float, info: dict) -> None:
    """Put :func:`ascent_from` at the result in ``info``, and say (``info["message"]``, a
    logged warning) where ``log_prob`` rises within ``step``: no local maximum."""
    rise, _ = ascent_from(target, theta, step)
    info["rise"] = rise
    if rise > 1e-9 * (1.0 + abs(value)):
        info["message"] = (f"{info['method']} stopped at {np.round(theta, 6).tolist()}, which "
                           f"is no local maximum: log_prob rises by {rise:.3g} within {step:g} "
                           f"of each range; more n_starts, a finer grid or another method "
                           f"may reach it")
        log.warning("maximise(%s): %s", getattr(target, "name", type(target).__name__),
                    info["message"])


def _out(theta: np.ndarray, value: float, info: dict, return_info: bool) -> Any:
    return (theta, value, info) if return_info else (theta, value)


def _check_arguments(method: str, seed: Any, n_starts: Any, n_random: Any, max_iter: Any,
                     batch: Any, xtol: Any, pattern_xtol: Any, max_points: Any) -> int | None:
    """Check :func:`maximise`'s arguments by name; return the checked seed."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    seed = check_seed(seed)
    for name, val, low in (("n_starts", n_starts, 1), ("n_random", n_random, 0),
                           ("max_iter", max_iter, 1), ("batch", batch, 1),
                           ("max_points", max_points, 2)):
        if isinstance(val, bool) or not isinstance(val, int | np.integer) or val < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {val!r}")
    for name, val in (("xtol", xtol), ("pattern_xtol", pattern_xtol)):
        if isinstance(val, bool) or not (isinstance(val, int | float) and np.isfinite(val)
                                         and val > 0):
            raise ValueError(f"{name} must be a positive number; got {val!r}")
    return seed


def _grid(b: np.ndarray, grid: Any, max_points: int, seed: int | None,
          ) -> tuple[np.ndarray, float, dict]:
    """The search's points in the bounds ``b`` (d, 2), their spacing (unit-cube fraction)
    and what they are (``info``)."""
    d = b.shape[0]
    if isinstance(grid, int | np.integer) and not isinstance(grid, bool):
        if grid < 2:
            raise ValueError(f"grid must be >= 2 points per dimension; got {grid}")
        n = int(grid)
        if float(n) ** d <= max_points:
            check_memory(8.0 * (d + 2) * float(n) ** d, f"a grid of {n}^{d} points",
                         "use a coarser grid")
            return grid_points(b, n), 1.0 / (n - 1), {"grid": "product", "grid_points": n ** d,
                                                      "per_axis": n}
        from scipy.stats import qmc

        check_memory(8.0 * (d + 2) * max_points, f"{max_points} Halton points",
                     "lower max_points")
        rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        u = qmc.Halton(d, scramble=True, seed=rng).random(max_points)
        log.info("maximise: %d^%d = %.3g grid points exceed max_points = %d; searching %d "
                 "scrambled Halton points instead", n, d, float(n) ** d, max_points, max_points)
        return (b[:, 0] + u * (b[:, 1] - b[:, 0]), max_points ** (-1.0 / d),
                {"grid": "halton", "grid_points": max_points, "per_axis": None})
    try:
        pts = np.asarray(grid, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"grid must be an integer >= 2 or an (M, {d}) array of points; "
                         f"got {grid!r}") from None
    if pts.ndim != 2 or pts.shape[1] != d or pts.shape[0] < 1 or not np.all(np.isfinite(pts)):
        raise ValueError(f"grid must be an int or a finite (M, {d}) array; got shape "
                         f"{pts.shape}")
    return (np.clip(pts, b[:, 0], b[:, 1]), 1.0 / max(2.0, round(pts.shape[0] ** (1.0 / d))),
            {"grid": "given", "grid_points": int(pts.shape[0]), "per_axis": None})


def _refine(target: Any, starts: np.ndarray, f0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            method: str, spacing: float, xtol: float, pattern_xtol: float, max_iter: int,
            batch: int) -> tuple[np.ndarray, np.ndarray]:
    """The local optimiser from each start: the refined points and their log_probs."""
    if method != "pattern":
        return _scipy(target, starts, f0, lo, hi, method, xtol, max_iter)
    xs, fs = _pattern(target, starts, f0, lo, hi, 0.5 * spacing, max(xtol, pattern_xtol),
                      max_iter, batch)
    # Compass steps stall at kinks that no search direction follows; a Nelder-Mead
    # polish of the best point (its simplex adapts to the kink) finishes the job.
    j = int(np.argmax(fs))
    px, pf = _scipy(target, xs[j:j + 1], fs[j:j + 1], lo, hi, "nelder-mead", xtol, max_iter)
    xs[j], fs[j] = px[0], pf[0]
    return xs, fs
