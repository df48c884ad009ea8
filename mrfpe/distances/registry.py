"""The ``mrfpe.distances`` entry-point registry.

Built on the same :class:`mrfpe._plugins.Registry` as the samplers: built-in
distances register through the entry-point group ``mrfpe.distances`` in
``pyproject.toml`` exactly like third-party plugins. A plugin is *valid* when
the entry point loads a class that

* can be constructed with no arguments,
* has ``kind`` = ``"distance"`` or ``"similarity"``, a bool ``symmetric`` and a
  mapping ``params`` (parameter name -> default),
* defines ``__call__(a, b, **params)`` returning the distance form (lower = more alike),
* and, for similarities, callable ``similarity`` and ``log_similarity``.

Anything else is listed as broken, with the reason. The listing
(:meth:`DistanceRegistry.table`, i.e. ``mrfpe distances``) shows each
entry's kind, symmetry and parameters with their defaults. What a distance
returns through the front doors is checked (:func:`check_value`): a number,
not NaN, and not negative if it declares ``nonnegative`` (the default).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Mapping
from typing import Any

from mrfpe._plugins import PluginInfo, Registry, check_no_arg_constructible, short_repr

__all__ = ["NEGATIVE_TOLERANCE", "DistanceRegistry", "check_value", "describe", "registry",
           "validate_distance"]

KINDS = ("distance", "similarity")

#: How far below zero rounding may bring a distance that declares ``nonnegative``
#: (such a value is returned as it is; anything lower is refused).
NEGATIVE_TOLERANCE = 1e-9


def _own_attr(cls: type, attr: str) -> bool:
    """Whether ``attr`` is defined by ``cls`` or a base other than ``object``/``type``."""
    return any(attr in vars(k) for k in cls.__mro__ if k is not object)


def validate_distance(obj: Any) -> None:
    """Raise ``TypeError`` unless ``obj`` implements the distance interface (structurally).

    Nothing is constructed or computed, so listing stays cheap.
    """
    if not inspect.isclass(obj):
        raise TypeError(f"a distance must be a class; got {type(obj).__name__} {obj!r}")
    name = obj.__name__
    kind = getattr(obj, "kind", None)
    if kind not in KINDS:
        raise TypeError(f"{name}.kind must be 'distance' or 'similarity'; got {kind!r}")
    if not isinstance(getattr(obj, "symmetric", None), bool):
        raise TypeError(f"{name}.symmetric must be a bool")
    if not isinstance(getattr(obj, "params", None), Mapping):
        raise TypeError(f"{name}.params must be a mapping of parameter names to defaults")
    check_no_arg_constructible(obj, name)
    if not _own_attr(obj, "__call__"):
        raise TypeError(f"{name} must define __call__(a, b, **params)")
    sig = inspect.signature(obj.__call__)
    positional = [p for p in sig.parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) < 3 and not any(p.kind is p.VAR_POSITIONAL
                                       for p in sig.parameters.values()):
        raise TypeError(f"{name}.__call__ must accept two posteriors (a, b)")
    if kind == "similarity":
        missing = [m for m in ("similarity", "log_similarity")
                   if not callable(getattr(obj, m, None))]
        if missing:
            raise TypeError(f"similarity {name} lacks {', '.join(missing)}")


def describe(info: PluginInfo) -> str:
    """``[distance, symmetric] alpha=0.7 eps=1e-09 ...`` for the listing."""
    obj = info.obj
    sym = "symmetric" if obj.symmetric else "asymmetric"
    params = " ".join(f"{k}={v!r}" for k, v in obj.params.items()) or "(no parameters)"
    return f"[{obj.kind}, {sym}] {params} |"


class DistanceRegistry(Registry):
    """The distance registry; its :meth:`table` shows kind and parameters by default."""

    def table(self, extra: Callable[[PluginInfo], str] | None = None, **kwargs: Any) -> str:
        return super().table(extra if extra is not None else describe, **kwargs)


registry = DistanceRegistry("mrfpe.distances", "distance", validate_distance)


def check_value(info: PluginInfo, value: Any) -> float:
    """``value``, returned by distance ``info``, as a float once checked.

    Raises
    ------
    ValueError
        Naming the plugin and the value, if the value is not a number, is NaN, or
        is negative (below ``-NEGATIVE_TOLERANCE``) while the class declares
        ``nonnegative`` (true unless it says otherwise, as for :class:`Distance`).
    """
    label = registry.label(info)
    try:
        v = float(value)
    except Exception:  # whatever a plugin's object raises on float()
        raise ValueError(f"{label} returned {type(value).__name__} {short_repr(value)}, not "
                         "a number") from None
    if math.isnan(v):
        raise ValueError(f"{label} returned NaN: the distance means nothing for these "
                         "posteriors")
    if v < -NEGATIVE_TOLERANCE and getattr(info.obj, "nonnegative", True):
        raise ValueError(f"{label} returned {v!r}, a negative distance, though it declares "
                         "nonnegative (a class whose distance form can be negative sets "
                         "nonnegative = False)")
    return v
