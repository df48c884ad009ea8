"""Log-density targets over MRF parameter vectors.

``mrfpe.targets.get(name, scene, **options)`` builds a target by name:

* BRDF pseudolikelihoods on a :class:`mrfpe.scene.Scene` (unit-cube sampling
  space, :mod:`mrfpe.targets.pseudolikelihood`): ``pl`` (4.23-4.24, 5.64-5.66),
  ``pl2`` (6.54-6.59), ``pl3`` (6.60-6.62), ``pls`` (7.5-7.7), and beyond the
  thesis ``fit`` and ``pml``;
* the generic auto-logistic Ising/Potts model on an observed configuration
  (:mod:`mrfpe.targets.potts`): ``potts`` (pseudolikelihood) and
  ``potts_exact`` (exact log-likelihood by enumeration, tiny lattices).

``softened(target, power)`` (5.69-5.72) and ``maximise(target)`` (dense grid +
local optimiser) work on any target.
"""

from __future__ import annotations

from typing import Any

from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.maximise import maximise
from mrfpe.targets.softening import Softened, softened

__all__ = ["Softened", "Target", "as_theta_batch", "get", "maximise", "names", "softened"]

# name -> (module, class); imported on first use so that `import mrfpe.targets` stays light.
_TARGETS = {
    "pl": ("mrfpe.targets.pseudolikelihood", "PL"),
    "pl2": ("mrfpe.targets.pseudolikelihood", "PL2"),
    "pl3": ("mrfpe.targets.pseudolikelihood", "PL3"),
    "pls": ("mrfpe.targets.pseudolikelihood", "PLS"),
    "fit": ("mrfpe.targets.pseudolikelihood", "ImageFit"),
    "pml": ("mrfpe.targets.pseudolikelihood", "CompositeMarginalLikelihood"),
    "potts": ("mrfpe.targets.potts", "PottsPseudoLikelihood"),
    "potts_exact": ("mrfpe.targets.potts", "PottsExactLikelihood"),
}


def names() -> tuple[str, ...]:
    """Names accepted by :func:`get`."""
    return tuple(_TARGETS)


def get(name: str, scene: Any, **options: Any) -> Target:
    """Build target ``name`` on ``scene`` (a Scene, or a configuration for ``potts*``).

    Options common to the BRDF targets: ``sigma_b`` (float or "auto"),
    ``data_term`` ("pixel" or "triplet"), ``dtype`` ("float64"); see each class
    for its own (e.g. ``prior_weight`` for ``pls``).
    """
    import importlib

    if name not in _TARGETS:
        raise ValueError(f"name must be one of {names()}; got {name!r}")
    mod, cls = _TARGETS[name]
    return getattr(importlib.import_module(mod), cls)(scene, **options)
