"""Argument validators shared by samplers, targets, distances and studies.

A leaf module (it imports only numpy): every public boundary checks its inputs
with these, so that a bad value gets a ``ValueError`` that names the argument
and says what was expected, before any expensive work starts.
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["BELIEF_SUM_ATOL", "MAX_SEED", "check_beliefs", "check_bool", "check_bounds",
           "check_choice", "check_keywords", "check_n_jobs", "check_positive_int", "check_range",
           "check_seed", "check_target", "keyword_names"]


def check_positive_int(name: str, value: Any, minimum: int = 1) -> int:
    """Return ``value`` as int, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or (not isinstance(value, (int,)) and not (
        hasattr(value, "__index__")
    )):
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value}")
    return value


def check_range(name: str, value: Any, low: float, high: float, *,
                low_open: bool = False, high_open: bool = False) -> float:
    """Return ``value`` as float if it lies in the interval, else raise ValueError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number; got {value!r}") from None
    lo_ok = v > low if low_open else v >= low
    hi_ok = v < high if high_open else v <= high
    if not (lo_ok and hi_ok) or v != v:
        lb, hb = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} must lie in {lb}{low}, {high}{hb}; got {value!r}")
    return v


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ValueError."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")
    return value


def check_n_jobs(name: str, value: Any) -> int:
    """Return a joblib worker count (non-zero; negative as joblib reads it, -1 = all cores)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value == 0:
        raise ValueError(f"{name} must be a non-zero integer (-1 = all cores); got {value!r}")
    return int(value)


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool, else raise ValueError naming ``name``."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False; got {value!r}")
    return bool(value)


#: Largest seed: posteriors and trial files store it as a signed 64-bit attribute.
MAX_SEED = 2**63 - 1


def check_seed(seed: Any, name: str = "seed") -> int | None:
    """Return ``seed`` if it is an integer in [0, :data:`MAX_SEED`] or None, else ValueError."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)
                             or not 0 <= seed <= MAX_SEED):
        raise ValueError(f"{name} must be an integer in [0, 2**63 - 1] or None; got {seed!r}")
    return None if seed is None else int(seed)


def check_bounds(bounds: Any, d: int, name: str = "bounds") -> np.ndarray:
    """``bounds`` as a finite (d, 2) float array with lower < upper, or ValueError."""
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite ({d}, 2) array of numbers; "
                         f"got {bounds!r}") from None
    if b.shape != (d, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise ValueError(f"{name} must be a finite ({d}, 2) array with lower < upper; "
                         f"got {b.tolist()}")
    return b


#: How far a node's beliefs may sum from 1 (:func:`check_beliefs`).
BELIEF_SUM_ATOL = 1e-6


def check_beliefs(beliefs: Any, shape: tuple[int, ...], name: str = "beliefs") -> np.ndarray:
    """Per-node label beliefs as a new float64 array of ``shape`` (``(H+1, W+1, B)``), or
    ValueError naming ``name``: finite, >= 0, and summing to 1 over each node's labels
    (within :data:`BELIEF_SUM_ATOL`). Shared by :class:`mrfpe.brdf.scene.Scene` and the ``pl3``
    target's ``beliefs`` option."""
    try:
        b = np.array(beliefs, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array: {exc}") from None
    if b.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}; got {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise ValueError(f"{name} must be finite and >= 0")
    if not np.allclose(b.sum(axis=2), 1.0, rtol=0, atol=BELIEF_SUM_ATOL):
        raise ValueError(f"{name} must be normalised per node (sum over labels = 1)")
    return b


def check_target(target: Any) -> np.ndarray:
    """The target's bounds as a finite (d, 2) float array, or ValueError naming the problem.

    A target provides ``param_names``, ``bounds`` and a batched ``log_prob``
    (the Target contract, :class:`mrfpe.targets.base.Target`).
    """
    for attr in ("param_names", "bounds", "log_prob"):
        if not hasattr(target, attr):
            raise ValueError(f"target must provide {attr!r} (the Target contract); "
                             f"got {type(target).__name__}")
    return check_bounds(target.bounds, len(target.param_names), "target.bounds")


def keyword_names(fn: Callable[..., Any], skip: int = 0) -> list[str] | None:
    """Keyword parameters of ``fn`` after its first ``skip``; ``None`` if it takes ``**kw``."""
    params = list(inspect.signature(fn).parameters.values())[skip:]
    if any(p.kind is p.VAR_KEYWORD for p in params):
        return None
    return [p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]


def check_keywords(given: Mapping[str, Any], valid: list[str] | None, what: str,
                   option: str = "") -> None:
    """Raise ``ValueError`` for a key of ``given`` that is not in ``valid`` (``None``:
    anything goes), naming the nearest valid one and listing them all.

    ``what`` names the receiver (e.g. ``"sampler 'pmc'"``); ``option`` prefixes the
    message with the option the keys came from (e.g. ``"--set"``).
    """
    if valid is None:
        return
    for key in given:
        if key not in valid:
            near = difflib.get_close_matches(key, valid, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            prefix = f"{option}: " if option else ""
            raise ValueError(f"{prefix}{what} has no parameter {key!r}{hint}; parameters: "
                             f"{', '.join(valid) or '(none)'}")
