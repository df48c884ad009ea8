"""The thesis's BRDF MRF through the model door.

The BRDF MRF (thesis ch. 4-6) has corner-vertex nodes labelled with depths
and potentials that are not log-linear in the BRDF parameters: its targets
are the fused-kernel pseudolikelihoods of :mod:`mrfpe.targets.pseudolikelihood`.
:class:`BRDFModel` offers them as estimators of one declared model, so that
``models.get("brdf").target("pl", scene)`` and ``mrfpe.targets.get("pl",
scene)`` build the very same target, and adds Besag's coding estimator on the
node lattice's four codings (:meth:`mrfpe.lattice.Lattice.codings`).
"""

from __future__ import annotations

from typing import Any, ClassVar

from mrfpe.models.base import Model
from mrfpe.targets.base import Target
from mrfpe.targets.options import Option
from mrfpe.targets.pseudolikelihood import PL, PL2, PL3, PLS, CompositeMarginalLikelihood, ImageFit
from mrfpe.validation import check_positive_int

__all__ = ["BRDFModel"]

_CLASSES = {"pl": PL, "pl2": PL2, "pl3": PL3, "pls": PLS, "fit": ImageFit,
            "pml": CompositeMarginalLikelihood}


def _coding_index(name: str, value: Any) -> int:
    return check_positive_int(name, value, minimum=0)


class BRDFModel(Model):
    """The BRDF MRF of the thesis, whose data are a Scene (depth labels and an image).

    Estimators: ``pl`` (4.23-4.24, 5.64-5.66), ``pl2`` (6.54-6.59), ``pl3``
    (6.60-6.62), ``pls`` (7.5-7.7), ``fit`` and ``pml`` (beyond the thesis) and
    ``coding``: the PL summed over one of the node lattice's four codings.
    """

    name = "brdf"
    estimators = (*_CLASSES, "coding")
    estimator_options: ClassVar[dict[str, tuple[Option, ...]]] = {
        **{k: tuple(c.option_specs) for k, c in _CLASSES.items()},
        "coding": (*PL.option_specs, Option("coding", "int in 0..3", 0, _coding_index,
                                            "which of the node lattice's four codings"))}

    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        if estimator != "coding":
            return _CLASSES[estimator](data, **options)
        k = options.pop("coding")
        parts = PL(data, **options).codings()
        if k >= len(parts):
            raise ValueError(f"coding must be in [0, {len(parts) - 1}]; got {k}")
        return parts[k]

    def param_names(self, brdf: str = "ward") -> tuple[str, ...]:
        """Unit-cube parameters of the scene's BRDF model (``"ward"`` or ``"phong"``)."""
        from mrfpe.brdf import get as get_brdf

        return tuple(get_brdf(brdf).param_names)

    def n_codings(self, shape: Any) -> int:
        """4 (2 x 2 codings of the ``(H+1, W+1)`` node lattice of an ``(H, W)`` image)."""
        from mrfpe.lattice import Lattice

        H, W = (int(s) for s in shape)
        return len(Lattice(H, W).codings())
