"""Distances between posteriors: built-ins and third-party plugins behind one registry.

>>> import mrfpe
>>> mrfpe.distance("bhattacharyya", post_a, post_b)           # doctest: +SKIP
>>> mrfpe.distance("chernoff", post_a, post_b, alpha=0.7)     # doctest: +SKIP
>>> mrfpe.distances.available()                               # doctest: +SKIP
['agmmp', 'bhattacharyya', 'chernoff', 'correlation', 'emd', ...]

Every entry is called the same way, POT-style: ``distance(name, a, b, **params)``
returns a float in *distance form* (lower = more alike), also for the
similarities (``agmmp``, ``correlation``, ``inner_product``), whose classes
additionally provide ``similarity`` and ``log_similarity``. ``mrfpe distances``
lists them with their kind and parameters. See ``docs/distances.md``.

:func:`distance` checks what it returns: a NaN, a non-number or a negative value from
a distance declaring ``nonnegative`` is a ``ValueError`` naming the plugin and the
value, and a third-party plugin that raises is named by the error
(:class:`mrfpe._plugins.PluginError`).
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import PluginInfo
from mrfpe.distances.registry import check_value, registry, validate_distance

__all__ = ["available", "broken", "distance", "get", "registry", "table", "validate_distance"]


available = registry.names  # names of the working distances, sorted
broken = registry.errors  # broken distance plugins: {name: reason}
get = registry.get  # the distance class registered as ``name`` (ValueError lists the others)


def distance(name: str | type, a: Any, b: Any, **params: Any) -> float:
    """Distance ``name`` between posteriors ``a`` and ``b`` (distance form: lower = more alike).

    ``params`` are the distance's keyword parameters (see :func:`table`). ``name``
    may also be a distance class. Only the entry point registered as ``name`` is
    imported.

    Raises
    ------
    ValueError
        For bad posteriors or parameters, and for a result that is NaN, not a
        number, or negative from a distance declaring ``nonnegative`` (naming the
        plugin and the value).
    mrfpe._plugins.PluginError
        If a third-party plugin fails otherwise (the message names it).
    """
    if inspect.isclass(name):
        cls = get(name)
        module = cls.__module__
        info = PluginInfo(cls.__name__, f"{module}:{cls.__qualname__}", "mrfpe" if
                          module.startswith("mrfpe.") else "(unregistered)", "", "", cls)
    else:
        info = registry.info(name)
    with registry.calling(info):
        value = info.obj()(a, b, **params)
    return check_value(info, value)


def table(*, width: int | None = 100, verbose: bool = False) -> str:
    """Plain-text listing: name, package, version, kind, symmetry, parameters, description.

    ``width`` columns wide: descriptions are cut with "…", or wrapped when ``verbose``
    (``width=None``: one line per entry, never cut).
    """
    return registry.table(width=width, verbose=verbose)
