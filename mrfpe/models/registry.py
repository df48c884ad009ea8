"""The ``mrfpe.models`` entry-point registry (as samplers and distances).

A model plugin is a callable -- a :class:`mrfpe.models.base.Model` subclass or
a factory function -- whose every parameter has a default, and which returns
a :class:`~mrfpe.models.base.Model`. Built-in models register through the
same group (``pyproject.toml``); a broken plugin is listed with its reason and
never breaks the others.
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import Registry
from mrfpe.models.base import Model

__all__ = ["get", "names", "registry", "validate_model"]


def validate_model(obj: Any) -> None:
    """Raise ``TypeError`` unless ``obj`` is a Model class or a factory callable with defaults."""
    if not callable(obj):
        raise TypeError(f"a model must be a Model class or a factory function; got "
                        f"{type(obj).__name__} {obj!r}")
    if inspect.isclass(obj) and not issubclass(obj, Model):
        raise TypeError(f"{obj.__name__} is a class but not an mrfpe.models.Model subclass")
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # pragma: no cover - builtins without signatures
        return
    required = [p.name for p in sig.parameters.values()
                if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if required:
        raise TypeError(f"{getattr(obj, '__name__', obj)}() must be callable with no "
                        f"arguments; parameters without defaults: {', '.join(required)}")


registry = Registry("mrfpe.models", "model", validate_model)


def names() -> list[str]:
    """Names of the working registered models."""
    return registry.names()


def get(name: str, /, **kwargs: Any) -> Model:
    """The model registered as ``name``, built with ``kwargs`` (say ``n_states=3``).

    Raises
    ------
    ValueError
        For an unknown or broken name (listing the available ones).
    TypeError
        If the plugin does not return a Model.
    """
    factory = registry.get(name)
    try:
        model = factory(**kwargs)
    except TypeError as exc:
        params = ", ".join(inspect.signature(factory).parameters)
        raise ValueError(f"model {name!r} takes {params or 'no settings'}; got "
                         f"{', '.join(kwargs) or 'none'} ({exc})") from None
    if not isinstance(model, Model):
        raise TypeError(f"model plugin {name!r} returned {type(model).__name__}, not an "
                        f"mrfpe.models.Model")
    return model
