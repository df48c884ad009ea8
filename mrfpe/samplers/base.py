"""The Sampler contract shared by built-ins and plugins.

A sampler is a plain class constructed with keyword configuration and
providing ``run(target, *, seed, progress=False, callback=None)`` that returns
the posterior Dataset built by :func:`mrfpe.posterior.build`. Subclassing
:class:`Sampler` is optional; it gives ``get_config`` (the constructor's
keyword arguments, as scikit-learn's ``get_params``) and validation helpers.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

__all__ = ["Sampler", "check_choice", "check_positive_int", "check_range"]

Callback = Callable[[int, dict], Any]


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


class Sampler:
    """Optional base class: configuration introspection for samplers.

    Subclasses take every setting as an explicit keyword argument in
    ``__init__``, validate it there, and store it under the same attribute
    name, so that ``get_config()`` can rebuild the configuration.
    """

    name: str = ""

    @classmethod
    def config_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if (p.name != "self" and p.kind is p.KEYWORD_ONLY) or
                (p.kind is p.POSITIONAL_OR_KEYWORD and p.name != "self")]

    def get_config(self) -> dict[str, Any]:
        """The constructor's keyword arguments and their current values."""
        return {k: getattr(self, k) for k in self.config_names()}

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        cfg = ", ".join(f"{k}={v!r}" for k, v in self.get_config().items())
        return f"{type(self).__name__}({cfg})"
