"""The ``mrfpe.emissions`` entry-point registry (as samplers and models have theirs).

An emission plugin is a callable -- an :class:`~mrfpe.models.emissions.base.Emission`
subclass or a factory function -- whose every parameter has a default and which returns
an :class:`~mrfpe.models.emissions.base.Emission`. The built-in ``gaussian``,
``poisson`` and ``categorical`` register through the same group; a broken plugin is
listed with its reason and never breaks the others.
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import Registry, short_repr
from mrfpe.models.emissions.base import Emission

__all__ = ["check_emission_factory", "get", "names", "registry", "validate_emission"]


def validate_emission(obj: Any) -> None:
    """``TypeError`` unless ``obj`` is an Emission class or a factory callable with defaults."""
    if not callable(obj):
        raise TypeError(f"an emission must be an Emission class or a factory function; got "
                        f"{type(obj).__name__} {short_repr(obj)}")
    if inspect.isclass(obj) and not issubclass(obj, Emission):
        raise TypeError(f"{obj.__name__} is a class but not an mrfpe.models.emissions.Emission "
                        f"subclass")
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # pragma: no cover - builtins without signatures
        return
    required = [p.name for p in sig.parameters.values()
                if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if required:
        raise TypeError(f"{getattr(obj, '__name__', obj)}() must be callable with no "
                        f"arguments; parameters without defaults: {', '.join(required)}")


def check_emission_factory(obj: Any) -> None:
    """``TypeError`` unless calling ``obj`` with no arguments returns an Emission."""
    what = f"{getattr(obj, '__name__', 'the factory')}()"
    try:
        built = obj()
    except Exception as exc:
        raise TypeError(f"{what} raised {type(exc).__name__}: {exc}") from None
    if not isinstance(built, Emission):
        raise TypeError(f"{what} returned {type(built).__name__} {short_repr(built)}, not an "
                        f"mrfpe.models.emissions.Emission")


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
    info = registry.info(name)
    factory = info.obj
    try:
        inspect.signature(factory).bind(**kwargs)
    except TypeError as exc:
        params = ", ".join(inspect.signature(factory).parameters)
        raise ValueError(f"emission {name!r} takes {params or 'no settings'}; got "
                         f"{', '.join(kwargs) or 'none'} ({exc})") from None
    with registry.calling(info):
        built = factory(**kwargs)
    if not isinstance(built, Emission):
        raise TypeError(f"{registry.label(info)} returned {type(built).__name__}, not an "
                        f"mrfpe.models.emissions.Emission")
    return built
