"""Importance functions: sub-lattice parts of a target and their softening (5.67–5.72)."""

from __future__ import annotations

from typing import Any

__all__ = ["THESIS2_POWER", "THESIS_POWER", "partition_or_none", "softened"]

#: Default softening power (5.69) of the thesis's algorithms (PMC (I)/(II), PPF, SIR
#: 5.2.2). The thesis does not state its value; a prototype measured that with PMC (II)
#: powers >= 0.03 collapse the cloud into bad regions and <= 0.01 leave it diffuse
#: (an early measurement), so the largest non-collapsing value.
THESIS_POWER = 0.01

#: Softening power of PMC (II) read as compounding (``PMC(variant="thesis2")``). On the
#: ``pmc_convergence`` study's 100×100, 20-label Ward scenes, l = 1e-4 reproduces Table
#: 7.1's fall of the MAP distance (30 scenes: 0.260 → 0.141, the thesis 0.286 → 0.104) and
#: its weight variances (median 8.3e-6 → 1.3e-8, the thesis 3.6e-6 → 1.8e-8); l = 1e-3
#: gives better MAPs but variances 100–1000× the thesis's
#: (``docs/results/pmc_thesis2_readings/report.md``).
THESIS2_POWER = 1e-4


def softened(target: Any, power: float) -> Any:
    """The softened importance function ``s(g) = g^l`` (5.69–5.72) of ``target``
    (``mrfpe.targets.softening.softened``; the target itself when ``power == 1``)."""
    if power == 1.0:
        return target
    from mrfpe.targets.softening import softened as _softened

    return _softened(target, power)


def partition_or_none(target: Any, k: int, kind: str) -> list[Any] | None:
    """``target.partition(k, kind)`` if the target offers it (and k > 1), else None."""
    if k <= 1 or not callable(getattr(target, "partition", None)):
        return None
    parts = list(target.partition(k, kind=kind))
    return parts or None
