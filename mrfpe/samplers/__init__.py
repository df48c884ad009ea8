"""Samplers: built-ins and third-party plugins behind one entry-point registry.

>>> import mrfpe.samplers as s
>>> sorted(s.available())            # doctest: +SKIP
['dw_q', 'dw_r', 'emcee', 'lm_multiseed', 'mh', 'nlopt_multiseed', 'pmc', 'ppf', 'sir', ...]
>>> post = s.get("pmc")(n_samples=500).run(target, seed=0)   # doctest: +SKIP

Listing imports each plugin module (not its heavy optional dependencies, which
plugins import inside ``run``). A plugin that fails to import, does not
implement the interface or reuses a name is reported by :func:`broken` and in
:func:`table`, and is left out of :func:`available`.
"""

from __future__ import annotations

from mrfpe.samplers.registry import registry, validate_sampler
from mrfpe.samplers.result import check_result

__all__ = ["available", "broken", "check_result", "get", "registry", "table",
           "validate_sampler"]


available = registry.names  # names of the working samplers, sorted
broken = registry.errors  # broken sampler plugins: {name: reason}
get = registry.get  # the class registered as ``name`` (ValueError lists the others), or a class


def table(*, width: int | None = 100, verbose: bool = False) -> str:
    """Plain-text table: name, package, version, one-line description (or why broken).

    ``width`` columns wide: descriptions are cut with "…", or wrapped when ``verbose``
    (``width=None``: one line per entry, never cut).
    """
    return registry.table(width=width, verbose=verbose)
