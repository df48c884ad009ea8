"""The Sampler contract shared by built-ins and plugins.

A sampler is a plain class constructed with keyword configuration and
providing ``run(target, *, seed, progress=False, callback=None)`` that returns
the posterior Dataset built by :func:`mrfpe.posterior.build`. Subclassing
:class:`Sampler` is optional; it gives ``get_config`` (the constructor's
keyword arguments, as scikit-learn's ``get_params``) and validation helpers.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from mrfpe.validation import check_choice, check_positive_int, check_range

__all__ = ["Sampler", "check_choice", "check_positive_int", "check_range"]

Callback = Callable[[int, dict], Any]


class Sampler:
    """Optional base class: configuration introspection for samplers.

    Subclasses take every setting as an explicit keyword argument in
    ``__init__``, validate it there, and store it under the same attribute
    name, so that ``get_config()`` can rebuild the configuration.
    """

    name: str = ""

    @classmethod
    def config_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if (p.name != "self" and p.kind is p.KEYWORD_ONLY) or
                (p.kind is p.POSITIONAL_OR_KEYWORD and p.name != "self")]

    def get_config(self) -> dict[str, Any]:
        """The constructor's keyword arguments and their current values."""
        return {k: getattr(self, k) for k in self.config_names()}

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        cfg = ", ".join(f"{k}={v!r}" for k, v in self.get_config().items())
        return f"{type(self).__name__}({cfg})"
