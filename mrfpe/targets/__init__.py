"""Log-density targets over MRF parameter vectors.

``mrfpe.targets.get(name, data, **options)`` builds a target by name. What
``data`` is depends on the target (:func:`data_kind`):

* ``"scene"`` -- the BRDF pseudolikelihoods on a :class:`mrfpe.brdf.scene.Scene`
  (unit-cube sampling space, :mod:`mrfpe.brdf.targets.pseudolikelihood`): ``pl``
  (4.23-4.24, 5.64-5.66), ``pl2`` (6.54-6.59), ``pl3`` (6.60-6.62), ``pls``
  (7.5-7.7), and beyond the thesis ``fit`` and ``pml``;
* ``"configurations"`` -- the generic auto-logistic Ising/Potts model on observed
  (H, W) or (M, H, W) integer configurations (:mod:`mrfpe.models.short_forms`):
  ``potts`` (pseudolikelihood) and ``potts_exact`` (exact log-likelihood by
  enumeration, tiny lattices).

Every target declares its options (:func:`options`, :mod:`mrfpe.targets.options`);
an unknown one is rejected with the valid ones and the nearest match.
``softened(target, power)`` (5.69-5.72) and ``maximise(target)`` (dense grid +
local optimiser) work on any target. Builds and evaluations respect a memory
budget (:func:`memory_budget`, :func:`set_memory_budget`, ``MRFPE_MEMORY_BUDGET``).
"""

from __future__ import annotations

from typing import Any

from mrfpe.budget import MemoryBudgetError, memory_budget, set_memory_budget
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.maximise import maximise
from mrfpe.targets.options import Option, describe_options, resolve_options
from mrfpe.targets.softening import Softened, softened

__all__ = ["MemoryBudgetError", "Option", "Softened", "Target", "as_theta_batch", "data_kind",
           "describe", "get", "maximise", "memory_budget", "names", "options",
           "set_memory_budget",
           "softened", "target_class"]

def names() -> tuple[str, ...]:
    """Names accepted by :func:`get`: the working targets of the ``mrfpe.targets``
    entry-point group (:mod:`mrfpe.targets.registry`), sorted."""
    from mrfpe.targets.registry import registry

    return tuple(registry.names())


def target_class(name: str) -> type:
    """The class registered as ``name``, importing no other target plugin (ValueError
    listing the names, nearest first, for an unknown one; naming the reason for a broken
    one)."""
    import difflib

    from mrfpe.targets.registry import registry

    if isinstance(name, str):
        try:
            return registry.info(name).obj
        except ValueError as exc:
            if "is broken" in str(exc):  # known but broken: its reason, not the names
                raise
    known = names()
    close = difflib.get_close_matches(str(name), known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ValueError(f"name must be one of {', '.join(known)}; got {name!r}{hint}")


def options(name: str) -> tuple[Option, ...]:
    """The declared options of target ``name`` (name, type, default, check, help)."""
    return tuple(target_class(name).option_specs)


def data_kind(name: str) -> str:
    """What :func:`get` takes as ``data`` for target ``name``, e.g. "scene" or "configurations"."""
    return str(target_class(name).data_kind)


def get(name: str, data: Any, /, **options: Any) -> Target:
    """Build target ``name`` on ``data`` with keyword ``options``.

    Parameters
    ----------
    name : str
        One of :func:`names`.
    data : Scene or array
        A :class:`mrfpe.brdf.scene.Scene` for the BRDF targets; observed integer
        configurations (H, W) or (M, H, W) for ``potts`` and ``potts_exact``
        (:func:`data_kind`).
    **options
        The target's declared options (:func:`options`; e.g. ``sigma_b``,
        ``data_term``, ``dtype``, ``progress`` for every BRDF target,
        ``prior_weight`` for ``pls``, ``n_states`` and ``bounds`` for Potts).

    Raises
    ------
    ValueError
        For an unknown name, the wrong kind of ``data``, an unknown option
        (listing the valid ones, nearest match first) or a bad option value --
        all before any table is built.
    mrfpe.targets.MemoryBudgetError
        If the build's estimated memory exceeds :func:`memory_budget`.
    """
    cls = target_class(name)
    resolve_options(name, cls.option_specs, options)  # fail fast, before the data is touched
    check = getattr(cls, "check_data", None)
    if callable(check):
        check(data)
    return cls(data, **options)


def describe(name: str) -> str:
    """Plain-text listing of target ``name``'s options."""
    return describe_options(options(name))
