"""Conformance checks for targets (like scikit-learn's ``check_estimator``).

Run them on your own target::

    from mrfpe.testing import check_target
    check_target(my_target)                 # an instance
    check_target(lambda: MyTarget(scene))   # or a zero-argument factory

Every check is a public function ``check_target_<name>(target, **options)``
raising ``AssertionError`` with a clear message; :func:`check_target` runs them
all and reports every failure at once. What the Target contract
(:mod:`mrfpe.targets.base`) promises and the checks verify:

* ``param_names`` (distinct strings) and finite ``(d, 2)`` ``bounds``, lower < upper;
* ``log_prob`` of an ``(N, d)`` batch is a float ``(N,)`` array for N = 0, 1, 5,
  17; a single ``(d,)`` vector is a batch of one (``(1,)``); a row's value does
  not depend on the batch it is evaluated in (to ``rtol``);
* ``-inf`` exactly outside the (closed) bounds, never NaN and never ``+inf``
  inside them, on the faces and corners included;
* NaN rows and wrong shapes raise ``ValueError``;
* ``cost``, if present, is a finite number > 0;
* ``partition(k, kind)``, if present, for ``kind`` in ("strided", "block") and
  k in (1, 2, 3): the parts' log_probs sum to the whole's (to ``rtol``; where the
  whole is ``-inf`` some part is), their costs sum to the whole's, and each part
  satisfies the shape contract (the sub-lattice identity of thesis 5.66-5.68:
  ``log PL = Σ_j log PL^j`` because the sub-lattices partition the nodes);
* ``describe()``, if present, is JSON-serialisable.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from typing import Any

import numpy as np

from mrfpe.testing._collect import display_name, failure, run_all

__all__ = [
    "TARGET_CHECKS", "check_target", "check_target_bad_input", "check_target_batch",
    "check_target_bounds", "check_target_cost", "check_target_describe",
    "check_target_interface", "check_target_partition",
]


def _resolve(target_or_factory: Any) -> Any:
    t = target_or_factory
    if inspect.isclass(t) or (not callable(getattr(t, "log_prob", None)) and callable(t)):
        t = t()
    if not callable(getattr(t, "log_prob", None)):
        raise ValueError(f"target_or_factory must be a target (with log_prob) or a "
                         f"zero-argument callable returning one; got {type(t).__name__}")
    return t


_name = display_name


def _fail(t: Any, check: str, msg: str) -> AssertionError:
    return failure("target", t, check, msg)


def _bounds(t: Any) -> np.ndarray:
    return np.asarray(t.bounds, dtype=np.float64)


def _inside(t: Any, n: int, seed: int) -> np.ndarray:
    b = _bounds(t)
    u = np.random.default_rng(seed).random((n, b.shape[0]))
    return b[:, 0] + u * (b[:, 1] - b[:, 0])


def _lp(t: Any, theta: np.ndarray, check: str) -> np.ndarray:
    try:
        out = t.log_prob(theta)
    except Exception as exc:
        raise _fail(t, check, f"log_prob raised {type(exc).__name__}: {exc}") from exc
    return np.asarray(out)


def _close(a: np.ndarray, b: np.ndarray, rtol: float) -> np.ndarray:
    """Elementwise: equal infinities, or |a - b| <= rtol * (1 + max |.|)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    same_inf = (a == b) & ~np.isfinite(a)
    with np.errstate(invalid="ignore"):
        fin = np.isfinite(a) & np.isfinite(b) & (
            np.abs(a - b) <= rtol * (1.0 + np.maximum(np.abs(a), np.abs(b))))
    return same_inf | fin


# --------------------------------------------------------------------------
def check_target_interface(target: Any) -> None:
    """``param_names`` distinct strings; ``bounds`` finite (d, 2) with lower < upper."""
    t = _resolve(target)
    names = getattr(t, "param_names", None)
    if names is None or isinstance(names, str) or not all(isinstance(p, str) for p in names):
        raise _fail(t, "check_target_interface", f"param_names must be a sequence of str; "
                    f"got {names!r}")
    if len(set(names)) != len(names) or len(names) == 0:
        raise _fail(t, "check_target_interface", f"param_names must be distinct and non-empty; "
                    f"got {names!r}")
    b = _bounds(t)
    if b.shape != (len(names), 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise _fail(t, "check_target_interface", f"bounds must be a finite ({len(names)}, 2) "
                    f"array with lower < upper; got {b.tolist()}")


def check_target_batch(target: Any, *, rtol: float = 1e-9, seed: int = 0) -> None:
    """(N, d) -> float (N,) for N in 0, 1, 5, 17; (d,) -> (1,); batch-independent rows."""
    t = _resolve(target)
    d = len(t.param_names)
    x = _inside(t, 17, seed)
    full = _lp(t, x, "check_target_batch")
    for n in (0, 1, 5, 17):
        out = _lp(t, x[:n], "check_target_batch")
        if out.shape != (n,) or out.dtype.kind != "f":
            raise _fail(t, "check_target_batch", f"log_prob of a ({n}, {d}) batch must be a "
                        f"float ({n},) array; got {out.dtype} {out.shape}")
        if n and not np.all(_close(out, full[:n], rtol)):
            bad = np.flatnonzero(~_close(out, full[:n], rtol))
            raise _fail(t, "check_target_batch", f"rows evaluated in a batch of {n} differ from "
                        f"the same rows in a batch of 17 (rows {bad[:5].tolist()}: "
                        f"{out[bad[:3]].tolist()} vs {full[bad[:3]].tolist()})")
    one = _lp(t, x[3], "check_target_batch")
    if one.shape != (1,) or not np.all(_close(one, full[3:4], rtol)):
        raise _fail(t, "check_target_batch", f"a single ({d},) vector must give a (1,) array "
                    f"equal to its row of a batch; got {one.shape} {one.tolist()} vs "
                    f"{full[3]}")


def check_target_bounds(target: Any, *, seed: int = 0) -> None:
    """-inf outside the closed bounds; inside, on faces and corners: never NaN or +inf."""
    t = _resolve(target)
    b = _bounds(t)
    d = b.shape[0]
    lo, hi = b[:, 0], b[:, 1]
    width = hi - lo
    centre = (lo + hi) / 2
    outside, faces = [], []
    for j in range(d):
        for val in (lo[j] - 1e-9 * width[j] - 1e-12, hi[j] + 1e-9 * width[j] + 1e-12,
                    lo[j] - 10 * width[j], hi[j] + 10 * width[j], -np.inf, np.inf):
            p = centre.copy()
            p[j] = val
            outside.append(p)
        for val in (lo[j], hi[j]):
            p = centre.copy()
            p[j] = val
            faces.append(p)
    faces += [lo.copy(), hi.copy()]
    out = _lp(t, np.array(outside), "check_target_bounds")
    if not np.all(out == -np.inf):
        bad = np.flatnonzero(out != -np.inf)
        raise _fail(t, "check_target_bounds", f"log_prob must be -inf outside the bounds; got "
                    f"{out[bad[:3]].tolist()} at {np.array(outside)[bad[:3]].tolist()}")
    inside = np.vstack([np.array(faces), _inside(t, 64, seed)])
    vals = _lp(t, inside, "check_target_bounds")
    bad = np.isnan(vals) | (vals == np.inf)
    if bad.any():
        raise _fail(t, "check_target_bounds", f"log_prob must never be NaN or +inf inside the "
                    f"closed bounds; got {vals[bad][:3].tolist()} at "
                    f"{inside[bad][:3].tolist()}")


def check_target_bad_input(target: Any) -> None:
    """NaN rows, a wrong trailing dimension and 3-D arrays raise ValueError."""
    t = _resolve(target)
    d = len(t.param_names)
    x = _inside(t, 2, 0)
    nan = x.copy()
    nan[1, 0] = np.nan
    for what, bad in (("a NaN row", nan), (f"shape (2, {d + 1})", np.zeros((2, d + 1))),
                      (f"shape (2, 2, {d})", np.zeros((2, 2, d)))):
        try:
            t.log_prob(bad)
        except ValueError:
            continue
        except Exception as exc:
            raise _fail(t, "check_target_bad_input", f"{what} must raise ValueError; got "
                        f"{type(exc).__name__}: {exc}") from exc
        raise _fail(t, "check_target_bad_input", f"{what} must raise ValueError")


def check_target_cost(target: Any) -> None:
    """``cost`` (if present) is a finite number > 0."""
    t = _resolve(target)
    if not hasattr(t, "cost"):
        return
    c = t.cost
    if isinstance(c, bool) or not isinstance(c, int | float | np.floating | np.integer) \
            or not (np.isfinite(c) and c > 0):
        raise _fail(t, "check_target_cost", f"cost must be a finite number > 0; got {c!r}")


def check_target_partition(target: Any, *, rtol: float = 1e-9, seed: int = 0,
                           ks: tuple[int, ...] = (1, 2, 3)) -> None:
    """Parts of ``partition(k, kind)`` sum to the whole (log_prob and cost); each conforms."""
    t = _resolve(target)
    if not callable(getattr(t, "partition", None)):
        return
    x = np.vstack([_inside(t, 9, seed), _bounds(t)[:, 0]])
    whole = _lp(t, x, "check_target_partition")
    for kind in ("strided", "block"):
        for k in ks:
            try:
                parts = list(t.partition(k, kind))
            except ValueError:
                if k == 1:
                    raise _fail(t, "check_target_partition",
                                f"partition(1, {kind!r}) raised ValueError") from None
                continue  # fewer than k sites
            if len(parts) != k:
                raise _fail(t, "check_target_partition", f"partition({k}, {kind!r}) returned "
                            f"{len(parts)} parts")
            vals = np.array([_lp(p, x, "check_target_partition") for p in parts])
            for p in parts:
                check_target_batch(p, rtol=rtol, seed=seed)
                check_target_bounds(p, seed=seed)
            with np.errstate(invalid="ignore"):
                total = vals.sum(axis=0)
            if not np.all(_close(total, whole, rtol)):
                bad = np.flatnonzero(~_close(total, whole, rtol))
                raise _fail(t, "check_target_partition", f"the {k} {kind} parts' log_probs "
                            f"sum to {total[bad[:3]].tolist()}, the whole's are "
                            f"{whole[bad[:3]].tolist()}")
            if hasattr(t, "cost"):
                csum = float(sum(float(p.cost) for p in parts))
                if not np.isclose(csum, float(t.cost), rtol=1e-9, atol=1e-12):
                    raise _fail(t, "check_target_partition", f"the {k} {kind} parts' costs "
                                f"sum to {csum}, the whole's is {t.cost}")


def check_target_describe(target: Any) -> None:
    """``describe()`` (if present) returns a JSON-serialisable dict."""
    t = _resolve(target)
    if not callable(getattr(t, "describe", None)):
        return
    desc = t.describe()
    try:
        json.dumps(desc)
    except (TypeError, ValueError) as exc:
        raise _fail(t, "check_target_describe", f"describe() is not JSON-serialisable: "
                    f"{exc}") from exc
    if not isinstance(desc, dict):
        raise _fail(t, "check_target_describe", f"describe() must return a dict; got "
                    f"{type(desc).__name__}")


#: The checks :func:`check_target` runs, by name.
TARGET_CHECKS: dict[str, Callable[..., None]] = {
    "interface": check_target_interface,
    "batch": check_target_batch,
    "bounds": check_target_bounds,
    "bad_input": check_target_bad_input,
    "cost": check_target_cost,
    "partition": check_target_partition,
    "describe": check_target_describe,
}
_TOLERANT = ("batch", "partition")


def check_target(target_or_factory: Any, *, rtol: float = 1e-9,
                 skip: tuple[str, ...] = ()) -> dict[str, str]:
    """Run every target check; return ``{check: "passed" | "skipped"}``.

    Parameters
    ----------
    target_or_factory : a target, or a zero-argument callable returning one.
    rtol : float
        Relative tolerance of the batch-independence and partition-sum checks
        (e.g. 1e-5 for float32 kernels).
    skip : names of :data:`TARGET_CHECKS` not to run (documented limitations).

    Raises
    ------
    AssertionError
        Listing every failed check.
    ValueError
        If ``target_or_factory`` is not a target or ``skip`` names an unknown check.
    """
    t = _resolve(target_or_factory)
    unknown = sorted(set(skip) - set(TARGET_CHECKS))
    if unknown:
        raise ValueError(f"skip names unknown checks {unknown}; checks: "
                         f"{', '.join(TARGET_CHECKS)}")
    def call(name: str, fn: Callable) -> Callable[[], str]:
        def check() -> str:
            if name in skip:
                return "skipped"
            fn(t, rtol=rtol) if name in _TOLERANT else fn(t)
            return "passed"
        return check

    return run_all({name: call(name, fn) for name, fn in TARGET_CHECKS.items()}, "target")
