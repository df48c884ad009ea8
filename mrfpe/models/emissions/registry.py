"""The ``mrfpe.emissions`` entry-point registry (as samplers and models have theirs).

An emission plugin is a callable -- an :class:`~mrfpe.models.emissions.base.Emission`
subclass or a factory function -- whose every parameter has a default and which returns
an :class:`~mrfpe.models.emissions.base.Emission`. The built-in ``gaussian``,
``poisson`` and ``categorical`` register through the same group; a broken plugin is
listed with its reason and never breaks the others.
"""

from __future__ import annotations

from typing import Any

from mrfpe._factories import build, check_builds, check_factory
from mrfpe._plugins import Registry
from mrfpe.models.emissions.base import Emission

__all__ = ["check_emission_factory", "get", "names", "registry", "validate_emission"]


_BASE = "mrfpe.models.emissions.Emission"


def validate_emission(obj: Any) -> None:
    """``TypeError`` unless ``obj`` is an Emission class or a factory callable with defaults."""
    check_factory(obj, Emission, "emission", _BASE)


def check_emission_factory(obj: Any) -> None:
    """``TypeError`` unless calling ``obj`` with no arguments returns an Emission."""
    check_builds(obj, Emission, _BASE)


registry = Registry("mrfpe.emissions", "emission", validate_emission, check_emission_factory)


def names() -> list[str]:
    """Names of the working registered emissions."""
    return registry.names()


def get(name: str, /, **kwargs: Any) -> Emission:
    """The emission registered as ``name``, built with ``kwargs`` (``shared_sd=False``).

    Raises
    ------
    ValueError
        For an unknown name (listing the registered ones), a broken plugin, settings it
        does not take, or a bad setting value.
    TypeError
        If the plugin does not return an Emission.
    """
    return build(registry, name, kwargs, Emission, _BASE)
