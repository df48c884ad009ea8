"""Measures for unevolved sample sets on one shared grid (thesis 8.2.2), and MAP distance.

Before any PMC iteration every material's samples sit at the same evenly
spaced grid points of parameter space and differ only in their weights (the
pseudolikelihood, Eq. 6.62). The weights can then be compared point by point
as vectors π₁, π₂ (normalised: Σ π = 1):

``correlation`` (Eq. 8.9)
    r = Σₘ (π₁ᵐ − π̄₁)(π₂ᵐ − π̄₂) / √(Σₘ (π₁ᵐ − π̄₁)² · Σₘ (π₂ᵐ − π̄₂)²) ∈ [−1, 1];
    distance form 1 − r ∈ [0, 2]. If a weight vector is constant (a flat
    posterior) r is 0/0; it is then defined as 1 when both are constant (the
    two weight vectors are then identical) and 0 when only one is (no linear
    association), so the measure never returns NaN.
``inner_product`` (Eq. 8.10)
    r = Σₘ π₁ᵐ π₂ᵐ ∈ [0, 1]; distance form 1 − r ∈ [0, 1].

"The same grid" is checked, not assumed: each set is reduced to its distinct
points (rows of ``theta``) with the summed weight of the samples on each, in
lexicographic order, so the sample order does not matter and a duplicated
sample is the same as one with double weight; the two point lists must then
agree (to 1e-9 relative, 1e-12 absolute) or ``ValueError`` is raised.

``map_euclidean`` -- the Euclidean distance between the two MAP estimates
(the "MAP" columns of Tables 8.6-8.11): the last step of ``map_theta`` (the
sampler's best-so-far trace) when the posterior has it and it is finite, else
the distinct sample point with the largest total weight (ties: the first in
lexicographic order).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from scipy.spatial.distance import cdist

from mrfpe.distances.base import Distance, SampleSet, Similarity

__all__ = ["Correlation", "InnerProduct", "MapEuclidean", "correlation_matrix", "grid_masses",
           "map_point"]

_GRID_RTOL, _GRID_ATOL = 1e-9, 1e-12
_FLAT_RTOL = 1e-9  # a weight vector whose spread is below this (relative) is constant


def grid_masses(s: SampleSet) -> tuple[np.ndarray, np.ndarray]:
    """Distinct points (K, d) in lexicographic order and the total weight on each (K,)."""
    points, inverse = np.unique(s.theta, axis=0, return_inverse=True)
    mass = np.bincount(inverse.reshape(-1), weights=s.weight, minlength=points.shape[0])
    return points, mass


def _check_same_grid(label: str, feats: Sequence[tuple[np.ndarray, np.ndarray]],
                     names: Sequence[str]) -> None:
    p0 = feats[0][0]
    for k in range(1, len(feats)):
        pk = feats[k][0]
        why = None
        if pk.shape != p0.shape:
            why = (f"{names[0]} has {p0.shape[0]} distinct points, "
                   f"{names[k]} has {pk.shape[0]}")
        elif not np.allclose(pk, p0, rtol=_GRID_RTOL, atol=_GRID_ATOL):
            why = f"their points differ by up to {np.max(np.abs(pk - p0)):.3g}"
        if why:
            raise ValueError(
                f"{label} compares sample weights point by point and needs every set on the "
                f"same grid (the unevolved, evenly spaced initial sets of thesis 8.2.2): "
                f"{names[0]} and {names[k]} are not: {why}")


def correlation_matrix(w: np.ndarray) -> np.ndarray:
    """Pearson correlation (Eq. 8.9) between the rows of ``w`` (n, K), with the flat fallback."""
    c = w - w.mean(axis=1, keepdims=True)
    norm = np.sqrt(np.einsum("ij,ij->i", c, c))
    flat = norm <= _FLAT_RTOL * np.sqrt(np.einsum("ij,ij->i", w, w))
    safe = np.where(flat, 1.0, norm)
    r = np.clip((c @ c.T) / np.outer(safe, safe), -1.0, 1.0)
    r[flat[:, None] | flat[None, :]] = 0.0
    r[flat[:, None] & flat[None, :]] = 1.0
    return r


class _GridMeasure(Similarity):
    requires_grid: ClassVar[bool] = True

    def features(self, s: SampleSet, p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        return grid_masses(s)

    def check_features(self, feats: Sequence[Any], p: dict[str, Any],
                       names: Sequence[str]) -> None:
        _check_same_grid(self.name, feats, names)

    def _similarities(self, w: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def compare(self, fa: tuple, fb: tuple, p: dict[str, Any]) -> float:
        return float(1.0 - self._similarities(np.stack([fa[1], fb[1]]))[0, 1])

    def pairwise_features(self, feats: Any, p: dict[str, Any], *, n_jobs: int = 1,
                          progress: bool = False) -> np.ndarray:
        return 1.0 - self._similarities(np.stack([f[1] for f in feats]))

    def similarity_from_distance(self, d: Any) -> Any:
        """r = 1 − d."""
        return 1.0 - np.asarray(d, dtype=np.float64)


class Correlation(_GridMeasure):
    """Correlation of the weight vectors of two sets on a shared grid (Eq. 8.9); distance 1 − r."""

    name = "correlation"
    symmetric = True

    def _similarities(self, w: np.ndarray) -> np.ndarray:
        return correlation_matrix(w)


class InnerProduct(_GridMeasure):
    """Inner product of the weight vectors of two sets on one grid (Eq. 8.10); distance 1 − r."""

    name = "inner_product"
    symmetric = True

    def _similarities(self, w: np.ndarray) -> np.ndarray:
        return np.clip(w @ w.T, 0.0, 1.0)


def map_point(s: SampleSet) -> np.ndarray:
    """The MAP estimate of a sample set: last finite ``map_theta`` step, else the heaviest point."""
    src = s.source
    if "map_theta" in src and src["map_theta"].dims == ("step", "param") \
            and src.sizes["step"] > 0:
        m = np.asarray(src["map_theta"].values[-1], dtype=np.float64)
        if np.isfinite(m).all():
            return m
    points, mass = grid_masses(s)
    return points[int(np.argmax(mass))]


class MapEuclidean(Distance):
    """Euclidean distance between the MAP estimates of two posteriors ("MAP" in Tables 8.6-8.11)."""

    name = "map_euclidean"
    symmetric = True

    def features(self, s: SampleSet, p: dict[str, Any]) -> np.ndarray:
        return map_point(s)

    def compare(self, fa: np.ndarray, fb: np.ndarray, p: dict[str, Any]) -> float:
        return float(np.linalg.norm(fa - fb))

    def pairwise_features(self, feats: Any, p: dict[str, Any], *, n_jobs: int = 1,
                          progress: bool = False) -> np.ndarray:
        m = np.stack(list(feats))
        return cdist(m, m)
