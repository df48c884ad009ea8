"""The ``mrfpe.samplers`` entry-point registry (modelled on xarray's backends).

Built-in samplers register through the same entry-point group as third-party
plugins (see ``pyproject.toml``). A plugin is *valid* when the entry point loads
a class that can be constructed with no arguments (every setting has a
default) and whose ``run`` accepts ``target`` and the keyword arguments
``seed``, ``progress`` and ``callback``. Anything else is listed as broken,
with the reason, and never breaks the other plugins or the command line.
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import Registry, check_no_arg_constructible

__all__ = ["registry", "validate_sampler"]

_RUN_KEYWORDS = ("seed", "progress", "callback")


def validate_sampler(obj: Any) -> None:
    """Raise ``TypeError`` unless ``obj`` implements the sampler interface.

    The checks are structural only (no sampler is constructed, so listing
    stays cheap and side-effect free): ``obj`` is a class, every constructor
    parameter has a default, and ``run(target, *, seed, progress, callback)``
    can be called with those names.
    """
    if not inspect.isclass(obj):
        raise TypeError(f"a sampler must be a class; got {type(obj).__name__} {obj!r}")
    check_no_arg_constructible(obj, obj.__name__)
    run = getattr(obj, "run", None)
    if not callable(run):
        raise TypeError(f"{obj.__name__} has no callable 'run' method")
    params = inspect.signature(run).parameters
    has_var_kw = any(p.kind is p.VAR_KEYWORD for p in params.values())
    positional = [p for p in params.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    has_var_pos = any(p.kind is p.VAR_POSITIONAL for p in params.values())
    # run is looked up on the class: the first positional parameter is ``self``.
    if len(positional) < 2 and not has_var_pos:
        raise TypeError(f"{obj.__name__}.run must accept the target as its first argument")
    missing = [k for k in _RUN_KEYWORDS
               if (k not in params and not has_var_kw)
               or (k in params and params[k].kind is params[k].POSITIONAL_ONLY)]
    if missing:
        raise TypeError(f"{obj.__name__}.run must accept the keyword arguments "
                        f"{', '.join(_RUN_KEYWORDS)}; missing: {', '.join(missing)}")


registry = Registry("mrfpe.samplers", "sampler", validate_sampler)
