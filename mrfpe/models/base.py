"""The Model contract: a declared MRF that builds its estimators and draws its data.

A model is a plain class registered under the ``mrfpe.models`` entry-point
group (as samplers and distances are). What it offers:

* ``estimators``: the names ``target`` accepts (``"pl"``, ``"coding"``,
  ``"block"``, ``"exact"``, ``"likelihood"`` ...);
* ``target(estimator, data, **options)`` -> :class:`mrfpe.targets.Target`,
  batched over parameter vectors, in log space, every option declared
  (:class:`mrfpe.targets.options.Option`) and checked before any work;
* ``param_names(**data_options)`` and ``n_codings(shape)``;
* ``simulate(theta, shape=..., n=..., seed=...)`` where it has a simulator.

:func:`estimator_options` and :func:`check_estimator` are the shared helpers
that validate an estimator name and its options the same way for every
model, built-in or plugin.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from typing import Any

from mrfpe.targets.base import Target
from mrfpe.targets.options import Option, resolve_options

__all__ = ["Model", "check_estimator"]


def check_estimator(model: Model, estimator: Any) -> str:
    """``estimator`` if ``model`` offers it; else a ValueError naming the valid ones."""
    valid = tuple(model.estimators)
    if not isinstance(estimator, str) or estimator not in valid:
        close = difflib.get_close_matches(str(estimator), valid, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"estimator must be one of {', '.join(valid)} for model "
                         f"{model.name!r}; got {estimator!r}{hint}")
    return estimator


class Model:
    """Base class of declared MRFs (see the module docstring).

    Subclasses set ``name`` and ``estimators``, declare each estimator's options
    in ``estimator_options`` and implement ``_build(estimator, data, options)``.
    """

    name: str = "model"
    #: Estimator names :meth:`target` accepts.
    estimators: tuple[str, ...] = ()
    #: ``{estimator: (Option, ...)}``: what :meth:`target` accepts per estimator.
    estimator_options: Mapping[str, Sequence[Option]] = {}

    def options(self, estimator: str) -> tuple[Option, ...]:
        """The declared options of ``estimator``."""
        return tuple(self.estimator_options.get(check_estimator(self, estimator), ()))

    def target(self, estimator: str, data: Any, /, **options: Any) -> Target:
        """Build the target of ``estimator`` on ``data`` (options checked before any work).

        Raises
        ------
        ValueError
            For an estimator the model does not offer (listing those it does), an
            unknown option (listing the valid ones) or a bad value.
        """
        check_estimator(self, estimator)
        resolved = resolve_options(f"{self.name} {estimator}", self.options(estimator), options)
        return self._build(estimator, data, resolved)

    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        raise NotImplementedError

    def param_names(self, **data_options: Any) -> tuple[str, ...]:
        raise NotImplementedError

    def n_codings(self, shape: Any) -> int:
        """How many Besag codings (colour classes) the graph of ``shape`` has."""
        raise NotImplementedError

    def simulate(self, theta: Any, **kwargs: Any) -> Any:
        raise NotImplementedError(f"model {self.name!r} has no simulator")

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__,
                "estimators": list(self.estimators)}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"
