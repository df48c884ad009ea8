"""Softening / sharpening of a target, thesis 5.69-5.72 (and 6.63, 6.65, 7.9).

Raising every importance weight to a power ``l`` and renormalising (5.69) is,
for weights proportional to a target density, the same as sampling the
density ``p(theta)^l`` (5.70): ``l < 1`` softens, ``l > 1`` sharpens. In log
space that is ``l * log p``; the composed importance function 5.72,
``g^n = s(exp(PL^n))``, is ``softened(target.partition(k)[n], l)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.targets.base import Target, as_theta_batch

__all__ = ["Softened", "softened"]


class Softened(Target):
    """``log_prob = power * target.log_prob`` (5.69-5.72); everything else is passed through.

    ``-inf`` stays ``-inf`` (power > 0). ``partition`` softens each part, so the
    parts of a softened target sum to the softened whole.
    """

    def __init__(self, target: Any, power: float) -> None:
        try:
            p = float(power)
        except (TypeError, ValueError):
            raise ValueError(f"power must be a positive number; got {power!r}") from None
        if not (np.isfinite(p) and p > 0):
            raise ValueError(f"power must be a positive finite number; got {power!r}")
        if not callable(getattr(target, "log_prob", None)):
            raise ValueError(f"target must have a log_prob method; got {type(target).__name__}")
        self.target = target
        self.power = p
        self.param_names = tuple(target.param_names)
        self.bounds = np.asarray(target.bounds, dtype=np.float64)
        self.cost = float(getattr(target, "cost", 1.0))

    def log_prob(self, theta: Any, *, progress: bool = False) -> np.ndarray:
        theta = as_theta_batch(theta, self.ndim)
        lp = np.asarray(self.target.log_prob(theta, progress=progress) if progress
                        else self.target.log_prob(theta), dtype=np.float64)
        out = self.power * lp
        return np.where(np.isnan(out), -np.inf, out)

    def to_natural(self, theta: Any) -> np.ndarray:
        return self.target.to_natural(theta)

    def partition(self, k: int, kind: str = "strided") -> list[Softened]:
        """Softened parts of the wrapped target's partition."""
        if not callable(getattr(self.target, "partition", None)):
            raise ValueError(f"{type(self.target).__name__} has no partition()")
        return [Softened(p, self.power) for p in self.target.partition(k, kind)]

    def describe(self) -> dict:
        inner = self.target.describe() if callable(getattr(self.target, "describe", None)) \
            else {"class": type(self.target).__name__}
        return {"name": "softened", "class": "Softened", "power": self.power,
                "param_names": list(self.param_names), "bounds": self.bounds.tolist(),
                "cost": self.cost, "target": inner}

    def __getattr__(self, name: str) -> Any:
        # Extras of the wrapped target (true_theta, scene, ...) stay reachable, but not
        # those whose values would need softening too.
        if name in ("target", "residuals", "node_terms") or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.target, name)

    def __repr__(self) -> str:
        return f"Softened({self.target!r}, power={self.power})"


def softened(target: Any, power: float) -> Softened:
    """The target ``p(theta)^power`` (5.69-5.72): ``power < 1`` softens, ``> 1`` sharpens."""
    out = Softened(target, power)  # validates power
    if isinstance(target, Softened):  # (p^a)^b = p^(a b)
        return Softened(target.target, target.power * out.power)
    return out
