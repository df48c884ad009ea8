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

from typing import Any

from mrfpe.samplers.registry import registry, validate_sampler

__all__ = ["available", "broken", "get", "registry", "table", "validate_sampler"]


def available() -> list[str]:
    """Names of the working samplers, sorted."""
    return sorted(registry.available())


def broken() -> dict[str, str]:
    """Broken sampler plugins: ``{name: reason}``."""
    return {k: v.error or "" for k, v in registry.broken().items()}


def get(name: str) -> Any:
    """The sampler class registered as ``name``.

    Raises
    ------
    ValueError
        If ``name`` is unknown (the message lists the available samplers) or broken.
    """
    if not isinstance(name, str):
        raise ValueError(f"sampler name must be a string; got {name!r}")
    return registry.get(name)


def table() -> str:
    """Plain-text table: name, package, version, one-line description (or why broken)."""
    return registry.table()
