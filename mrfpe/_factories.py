"""Checks of a factory plugin: a class, or a function, that builds one kind of object.

Models and emissions are registered as factories (a subclass of their base, or a
function returning an instance) whose every parameter has a default. Their
registries (:mod:`mrfpe.models.registry`, :mod:`mrfpe.models.emissions.registry`)
check the factory on discovery with :func:`check_factory` and, once, what it
builds with :func:`check_builds`.
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import Registry, short_repr

__all__ = ["build", "check_builds", "check_factory", "not_an_instance"]


def check_factory(obj: Any, base: type, kind: str, base_name: str) -> None:
    """``TypeError`` unless ``obj`` is a ``base`` subclass or a callable, either callable
    with no arguments. ``kind`` names the plugin ("model"), ``base_name`` the class."""
    if not callable(obj):
        raise TypeError(f"a {kind} must be a {base.__name__} class or a factory function; "
                        f"got {type(obj).__name__} {short_repr(obj)}")
    if inspect.isclass(obj) and not issubclass(obj, base):
        raise TypeError(f"{obj.__name__} is a class but not an {base_name} subclass")
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # pragma: no cover - builtins without signatures
        return
    required = [p.name for p in sig.parameters.values()
                if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if required:
        raise TypeError(f"{getattr(obj, '__name__', obj)}() must be callable with no "
                        f"arguments; parameters without defaults: {', '.join(required)}")


def not_an_instance(what: str, built: Any, base_name: str) -> TypeError:
    """The error for a factory ``what`` that returned ``built``, not a ``base_name``."""
    return TypeError(f"{what} returned {type(built).__name__} {short_repr(built)}, not an "
                     f"{base_name}")


def check_builds(obj: Any, base: type, base_name: str) -> None:
    """``TypeError`` unless calling ``obj`` with no arguments returns a ``base``; the error
    says what the call raised or returned."""
    what = f"{getattr(obj, '__name__', 'the factory')}()"
    try:
        built = obj()
    except Exception as exc:
        raise TypeError(f"{what} raised {type(exc).__name__}: {exc}") from None
    if not isinstance(built, base):
        raise not_an_instance(what, built, base_name)


def build(registry: Registry, name: str, kwargs: dict[str, Any], base: type,
          base_name: str) -> Any:
    """The plugin registered as ``name`` in ``registry``, built with ``kwargs``.

    Settings the factory does not take are a ``ValueError`` naming them; a third-party
    plugin's failure is named as its own (:meth:`Registry.calling`); a result that is
    not a ``base`` is a ``TypeError`` naming the plugin.
    """
    info = registry.info(name)
    factory = info.obj
    try:
        inspect.signature(factory).bind(**kwargs)
    except TypeError as exc:
        params = ", ".join(inspect.signature(factory).parameters)
        raise ValueError(f"{registry.kind} {name!r} takes {params or 'no settings'}; got "
                         f"{', '.join(kwargs) or 'none'} ({exc})") from None
    except ValueError:  # pragma: no cover - no signature to check against
        pass
    with registry.calling(info):
        built = factory(**kwargs)
    if not isinstance(built, base):
        raise not_an_instance(registry.label(info), built, base_name)
    return built
