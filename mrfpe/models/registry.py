"""The ``mrfpe.models`` entry-point registry (as samplers and distances).

A model plugin is a callable -- a :class:`mrfpe.models.base.Model` subclass or
a factory function -- whose every parameter has a default, and which returns
a :class:`~mrfpe.models.base.Model`. Built-in models register through the
same group (``pyproject.toml``); a broken plugin is listed with its reason and
never breaks the others.

Discovery calls each entry point's factory once with no arguments
(:func:`check_model_factory`): only a build says whether it returns a model, the
contract already requires a no-argument build, and the built-ins' builds take
microseconds and import nothing. A listing runs it first in its probe process for
a third-party plugin, so a build that hangs or ends the process is caught there.
"""

from __future__ import annotations

from typing import Any

from mrfpe._factories import build, check_builds, check_factory
from mrfpe._plugins import Registry
from mrfpe.models.base import Model

__all__ = ["check_model_factory", "get", "names", "registry", "validate_model"]


_BASE = "mrfpe.models.Model"


def validate_model(obj: Any) -> None:
    """Raise ``TypeError`` unless ``obj`` is a Model class or a factory callable with defaults."""
    check_factory(obj, Model, "model", _BASE)


def check_model_factory(obj: Any) -> None:
    """Raise ``TypeError`` unless calling ``obj`` with no arguments returns a Model.

    Run on discovery of a model entry point, after :func:`validate_model`; the
    error says what the call raised or returned.
    """
    check_builds(obj, Model, _BASE)


registry = Registry("mrfpe.models", "model", validate_model, check_model_factory)


def names() -> list[str]:
    """Names of the working registered models."""
    return registry.names()


def get(name: str, /, **kwargs: Any) -> Model:
    """The model registered as ``name``, built with ``kwargs`` (say ``n_states=3``).

    Only the entry point registered as ``name`` is imported.

    Raises
    ------
    ValueError
        For an unknown name (listing the registered ones), a broken plugin (naming it,
        its entry point and package, and why), settings it does not take, or a bad
        setting value.
    TypeError
        If the plugin does not return a Model (the message names it).
    mrfpe._plugins.PluginError
        If a third-party plugin fails otherwise while building (the message names it).
    """
    return build(registry, name, kwargs, Model, _BASE)
