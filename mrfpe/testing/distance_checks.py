"""Conformance checks for distances (like scikit-learn's ``check_estimator``).

Run them on your own distance::

    from mrfpe.testing import check_distance
    check_distance(MyDistance)          # a class, an instance, or a registered name

Every check is a public function ``check_distance_<name>(distance)`` raising
``AssertionError`` with a clear message; :func:`check_distance` runs them all
and reports every failure at once. What the distance contract
(:mod:`mrfpe.distances.base`) promises and the checks verify, on small
weighted 2-D sample sets (on one shared grid when ``requires_grid``):

* ``finite``: a finite float on different sets, including collapsed ones (all
  samples at one point, or all weight on one sample) -- or a ``ValueError``
  naming the problem, never NaN or another exception;
* ``symmetric``: ``d(a, b) == d(b, a)`` when the class says ``symmetric``;
* ``identity``: ``d(a, a) == 0`` for a distance (``kind="distance"``); for a
  similarity, ``d(a, a) <= d(a, b)`` is *not* promised (an inner product can
  prefer a sharper set), so the check is that ``similarity`` and
  ``log_similarity`` agree with the distance form;
* ``nonnegative``: ``d >= 0`` when the class says ``nonnegative``;
* ``weights``: a duplicated sample equals one sample with doubled weight, the
  sample order does not matter, and an added zero-weight sample changes nothing
  (for grid measures it is added to both sets, at a new grid point, and
  only the inner product promises invariance: a zero entry is part of the
  weight vectors Eq. 8.9 correlates);
* ``pairwise``: ``pairwise([a, b, c])`` equals the pair calls.

A distance may declare ``conformance = {"<check>": False}`` for a check that
does not apply (reported as skipped); document why.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.testing._collect import display_name, failure, run_all

__all__ = [
    "DISTANCE_CHECKS", "check_distance", "check_distance_finite", "check_distance_identity",
    "check_distance_nonnegative", "check_distance_pairwise", "check_distance_symmetric",
    "check_distance_weights", "sample_sets",
]

_TOL = 1e-9


def _resolve(distance: Any) -> Any:
    if isinstance(distance, str):
        from mrfpe.distances import get

        return get(distance)()
    if inspect.isclass(distance):
        return distance()
    if not callable(distance):
        raise ValueError(f"distance must be a distance class, instance or registered name; "
                         f"got {type(distance).__name__}")
    return distance


_name = display_name


def _fail(d: Any, check: str, msg: str) -> AssertionError:
    return failure("distance", d, check, msg)


def _post(theta: np.ndarray, log_weight: np.ndarray) -> xr.Dataset:
    from mrfpe.posterior import build

    theta = np.asarray(theta, dtype=np.float64)
    lw = np.asarray(log_weight, dtype=np.float64)
    return build(theta, np.where(np.isfinite(lw), lw, -1e300), param_names=["u", "v"],
                 log_weight=lw, sampler="check_distance")


def _grid() -> np.ndarray:
    ax = np.linspace(0.1, 0.9, 4)
    return np.stack(np.meshgrid(ax, ax, indexing="ij"), -1).reshape(-1, 2)


def sample_sets(requires_grid: bool, seed: int = 0) -> dict[str, xr.Dataset]:
    """The named weighted 2-D sets the checks compare (``a``, ``b``, ``c``, collapsed ones)."""
    rng = np.random.default_rng(seed)
    if requires_grid:
        g = _grid()
        pts = {"a": g, "b": g, "c": g}
    else:
        pts = {"a": 0.5 + 0.1 * rng.standard_normal((24, 2)),
               "b": 0.55 + 0.12 * rng.standard_normal((30, 2)),
               "c": 0.3 + 0.05 * rng.standard_normal((20, 2))}
    sets = {k: _post(v, rng.standard_normal(v.shape[0])) for k, v in pts.items()}
    n = pts["a"].shape[0]
    one = np.full(n, -np.inf)
    one[2] = 0.0
    sets["one_heavy"] = _post(pts["a"], one)  # all weight on one sample
    if not requires_grid:
        sets["point"] = _post(np.tile([[0.4, 0.6]], (8, 1)), np.zeros(8))  # all at one point
    return sets


def _call(d: Any, a: xr.Dataset, b: xr.Dataset, check: str, *, allow_value_error: bool = False
          ) -> float | None:
    try:
        v = d(a, b)
    except ValueError:
        if allow_value_error:
            return None
        raise
    except Exception as exc:
        raise _fail(d, check, f"raised {type(exc).__name__}: {exc}") from exc
    if not isinstance(v, float | np.floating):
        raise _fail(d, check, f"must return a float; got {type(v).__name__}")
    return float(v)


def _close(x: float, y: float, tol: float = _TOL) -> bool:
    return abs(x - y) <= tol * (1.0 + max(abs(x), abs(y)))


# --------------------------------------------------------------------------
def check_distance_finite(distance: Any) -> None:
    """Finite on different and collapsed sets (or a ValueError), never NaN."""
    d = _resolve(distance)
    s = sample_sets(d.requires_grid)
    pairs = [("a", "b"), ("b", "c"), ("a", "one_heavy"), ("one_heavy", "one_heavy")]
    if "point" in s:
        pairs += [("a", "point"), ("point", "point")]
    for x, y in pairs:
        collapsed = "one_heavy" in (x, y) or "point" in (x, y)
        v = _call(d, s[x], s[y], "check_distance_finite", allow_value_error=collapsed)
        if v is not None and not np.isfinite(v):
            raise _fail(d, "check_distance_finite", f"d({x}, {y}) = {v}; expected a finite "
                        "value (or a ValueError naming the problem for collapsed sets)")


def check_distance_symmetric(distance: Any) -> None:
    """``d(a, b) == d(b, a)`` when ``symmetric``."""
    d = _resolve(distance)
    if not d.symmetric:
        return
    s = sample_sets(d.requires_grid)
    for x, y in (("a", "b"), ("b", "c"), ("a", "one_heavy")):
        u = _call(d, s[x], s[y], "check_distance_symmetric")
        v = _call(d, s[y], s[x], "check_distance_symmetric")
        if not _close(u, v):
            raise _fail(d, "check_distance_symmetric", f"symmetric, but d({x}, {y}) = {u!r} "
                        f"and d({y}, {x}) = {v!r}")


def check_distance_identity(distance: Any) -> None:
    """``d(a, a) == 0`` for distances; similarity forms consistent for similarities."""
    d = _resolve(distance)
    s = sample_sets(d.requires_grid)
    if d.kind == "distance":
        for x in ("a", "b"):
            v = _call(d, s[x], s[x], "check_distance_identity")
            if abs(v) > 1e-7:
                raise _fail(d, "check_distance_identity", f"d({x}, {x}) = {v!r}; a distance "
                            "must be 0 on identical sets")
        return
    for x, y in (("a", "a"), ("a", "b")):
        v = _call(d, s[x], s[y], "check_distance_identity")
        sim = float(d.similarity(s[x], s[y]))
        expect = float(d.similarity_from_distance(v))
        if not (_close(sim, expect) or (np.isinf(sim) and sim == expect)):
            raise _fail(d, "check_distance_identity", f"similarity({x}, {y}) = {sim!r} but "
                        f"similarity_from_distance(d) = {expect!r}")
        if sim > 0:
            ls = float(d.log_similarity(s[x], s[y]))
            if not _close(ls, float(np.log(sim)), 1e-7) and np.isfinite(np.log(sim)):
                raise _fail(d, "check_distance_identity", f"log_similarity({x}, {y}) = "
                            f"{ls!r}, log(similarity) = {np.log(sim)!r}")


def check_distance_nonnegative(distance: Any) -> None:
    """``d >= 0`` on every pair when ``nonnegative``."""
    d = _resolve(distance)
    if not getattr(d, "nonnegative", True):
        return
    s = sample_sets(d.requires_grid)
    for x in ("a", "b", "c"):
        for y in ("a", "b", "c", "one_heavy"):
            v = _call(d, s[x], s[y], "check_distance_nonnegative")
            if v < -1e-12:
                raise _fail(d, "check_distance_nonnegative", f"nonnegative, but d({x}, {y}) "
                            f"= {v!r}")


def _with(ds: xr.Dataset, theta: np.ndarray, lw: np.ndarray) -> xr.Dataset:
    return _post(theta, lw)


def check_distance_weights(distance: Any) -> None:
    """Duplicate == doubled weight; sample order irrelevant; zero weights change nothing."""
    d = _resolve(distance)
    s = sample_sets(d.requires_grid)
    a, b = s["a"], s["b"]
    th, lw = a["theta"].values, a["log_weight"].values
    ref = _call(d, a, b, "check_distance_weights")
    dup = _with(a, np.vstack([th, th[3:4]]), np.append(lw, lw[3]))
    lw2 = lw.copy()
    lw2[3] += np.log(2.0)
    dbl = _with(a, th, lw2)
    u = _call(d, dup, b, "check_distance_weights")
    v = _call(d, dbl, b, "check_distance_weights")
    if not _close(u, v, 1e-7):
        raise _fail(d, "check_distance_weights", f"a duplicated sample gives {u!r}, the same "
                    f"sample with doubled weight {v!r}; the weights must be honoured")
    perm = np.random.default_rng(1).permutation(th.shape[0])
    w = _call(d, _with(a, th[perm], lw[perm]), b, "check_distance_weights")
    if not _close(w, ref, 1e-7):
        raise _fail(d, "check_distance_weights", f"permuting the samples changes d from "
                    f"{ref!r} to {w!r}")
    if d.requires_grid and d.name != "inner_product":
        return  # a zero-weight grid point is an entry of the compared weight vectors
    far = np.array([[0.95, 0.05]])
    za = _with(a, np.vstack([th, far]), np.append(lw, -np.inf))
    if d.requires_grid:
        bt, bw = b["theta"].values, b["log_weight"].values
        b = _with(b, np.vstack([bt, far]), np.append(bw, -np.inf))
    z = _call(d, za, b, "check_distance_weights")
    if not _close(z, ref, 1e-7):
        raise _fail(d, "check_distance_weights", f"adding a zero-weight sample changes d from "
                    f"{ref!r} to {z!r}")


def check_distance_pairwise(distance: Any) -> None:
    """``pairwise([a, b, c])`` equals the individual calls (if the distance has it)."""
    d = _resolve(distance)
    if not callable(getattr(d, "pairwise", None)):
        return
    s = sample_sets(d.requires_grid)
    keys = ("a", "b", "c")
    m = np.asarray(d.pairwise([s[k] for k in keys]))
    if m.shape != (3, 3):
        raise _fail(d, "check_distance_pairwise", f"pairwise of 3 sets must be (3, 3); got "
                    f"{m.shape}")
    for i, x in enumerate(keys):
        for j, y in enumerate(keys):
            v = _call(d, s[x], s[y], "check_distance_pairwise")
            if not _close(float(m[i, j]), v, 1e-7):
                raise _fail(d, "check_distance_pairwise", f"pairwise[{i}, {j}] = {m[i, j]!r} "
                            f"but d({x}, {y}) = {v!r}")


#: The checks :func:`check_distance` runs, by name.
DISTANCE_CHECKS: dict[str, Callable[[Any], None]] = {
    "finite": check_distance_finite,
    "symmetric": check_distance_symmetric,
    "identity": check_distance_identity,
    "nonnegative": check_distance_nonnegative,
    "weights": check_distance_weights,
    "pairwise": check_distance_pairwise,
}


def check_distance(distance: Any) -> dict[str, str]:
    """Run every distance check; return ``{check: "passed" | "skipped: declared"}``.

    ``distance`` is a class, an instance or a registered name. A class may
    declare ``conformance = {check: False}`` for checks that do not apply.

    Raises
    ------
    AssertionError
        Listing every failed check.
    """
    d = _resolve(distance)
    declared = getattr(d, "conformance", {}) or {}
    unknown = sorted(set(declared) - set(DISTANCE_CHECKS))
    if unknown:
        raise AssertionError(f"{_name(d)}.conformance names unknown checks {unknown}; "
                             f"known: {', '.join(DISTANCE_CHECKS)}")
    def call(name: str, fn: Callable) -> Callable[[], str]:
        def check() -> str:
            if declared.get(name, True) is False:
                return "skipped: declared"
            try:
                fn(d)
            except ValueError as exc:  # a distance refusing valid input is a failure too
                raise AssertionError(f"check_distance_{name} failed for distance {_name(d)}: "
                                     f"ValueError: {exc}") from None
            return "passed"
        return check

    return run_all({name: call(name, fn) for name, fn in DISTANCE_CHECKS.items()}, "distance")
