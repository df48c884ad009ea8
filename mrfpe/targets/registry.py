"""The ``mrfpe.targets`` entry-point registry: targets built by name from data.

A target plugin is a :class:`~mrfpe.targets.base.Target` subclass built as
``cls(data, **options)``. It declares its keyword options (``option_specs``,
:class:`~mrfpe.targets.options.Option`) and what it is built on (``data_kind``,
e.g. ``"scene"`` or ``"configurations"``), and may check that data with a
classmethod ``check_data(data)`` that raises ``ValueError`` before any work.
Built-in targets (the thesis's BRDF pseudolikelihoods of :mod:`mrfpe.brdf.targets`,
the Potts short forms of :mod:`mrfpe.models.short_forms`) register through the same
group (``pyproject.toml``) as a third party's; a broken plugin is listed with its
reason and never breaks the others.
"""

from __future__ import annotations

import inspect
from typing import Any

from mrfpe._plugins import Registry
from mrfpe.targets.base import Target

__all__ = ["registry", "validate_target_class"]


def validate_target_class(obj: Any) -> None:
    """Raise ``TypeError`` unless ``obj`` is a Target subclass declaring its options and data."""
    if not (inspect.isclass(obj) and issubclass(obj, Target)):
        raise TypeError(f"a target plugin must be an mrfpe.targets.Target subclass; got "
                        f"{type(obj).__name__} {obj!r}")
    if not isinstance(getattr(obj, "data_kind", None), str):
        raise TypeError(f"{obj.__name__}.data_kind must be a string (what the target is "
                        f"built on, e.g. 'scene')")
    try:
        specs = tuple(obj.option_specs)
    except TypeError:
        raise TypeError(f"{obj.__name__}.option_specs must be a sequence of "
                        f"mrfpe.targets.Option") from None
    if not all(hasattr(s, "name") and hasattr(s, "default") for s in specs):
        raise TypeError(f"{obj.__name__}.option_specs must hold mrfpe.targets.Option entries")


registry = Registry("mrfpe.targets", "target", validate_target_class)
