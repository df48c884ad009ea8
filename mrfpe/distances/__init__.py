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
"""

from __future__ import annotations

from typing import Any

from mrfpe.distances.registry import registry, validate_distance

__all__ = ["available", "broken", "distance", "get", "registry", "table", "validate_distance"]


available = registry.names  # names of the working distances, sorted
broken = registry.errors  # broken distance plugins: {name: reason}
get = registry.get  # the distance class registered as ``name`` (ValueError lists the others)


def distance(name: str, a: Any, b: Any, **params: Any) -> float:
    """Distance ``name`` between posteriors ``a`` and ``b`` (distance form: lower = more alike).

    ``params`` are the distance's keyword parameters (see :func:`table`).
    """
    return float(get(name)()(a, b, **params))


def table(*, width: int | None = 100, verbose: bool = False) -> str:
    """Plain-text listing: name, package, version, kind, symmetry, parameters, description.

    ``width`` columns wide: descriptions are cut with "…", or wrapped when ``verbose``
    (``width=None``: one line per entry, never cut).
    """
    return registry.table(width=width, verbose=verbose)
