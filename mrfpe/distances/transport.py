"""Optimal-transport distances between weighted sample sets (thesis 8.2.3, Appendix B).

``emd`` -- the Earth Mover's Distance: every sample is a signature whose mass
is its normalised weight, the ground cost is the Euclidean distance between
samples (in the posterior's sampling space), and the distance is the minimal
total work ``Σᵢⱼ Tᵢⱼ ‖xᵢ − yⱼ‖`` over transport plans T with marginals πˣ, πʸ
(the 1-Wasserstein distance), solved exactly by POT's network simplex
(``ot.emd2``). The ground cost is the matrix of ``ot.dist(x, y,
metric="euclidean")`` but computed by :func:`scipy.spatial.distance.cdist`:
POT expands ‖x−y‖² = ‖x‖² + ‖y‖² − 2x·y, which loses about 1e-8 in absolute
accuracy (the square root of rounding) -- as large as the whole spread of a
converged posterior -- while cdist sums the squared differences directly.
Cost and memory grow as N·M (1000 × 1000 samples: 8 MB, well under a
second); for much larger sets use

``sliced_wasserstein`` -- POT's ``ot.sliced_wasserstein_distance``: the sets
are projected on ``n_projections`` random unit directions (drawn from
``numpy.random.default_rng(seed)``, the same directions for every pair), the
exact 1-D p-Wasserstein distance is computed per direction and
``(mean_k W_p^p)^(1/p)`` returned. It costs O((N + M) log(N + M)) per
direction and is a lower bound of the p-Wasserstein distance; with ``p=1``
it is at most ``emd``.

Samples with zero weight carry no mass and are dropped before solving.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from scipy.spatial.distance import cdist

from mrfpe.budget import check_memory
from mrfpe.distances.base import Distance, SampleSet
from mrfpe.validation import check_positive_int, check_range

__all__ = ["EMD", "SlicedWasserstein"]


def _masses(s: SampleSet) -> tuple[np.ndarray, np.ndarray]:
    """Samples with positive weight and their masses (renormalised to sum 1 exactly)."""
    w = s.weight
    keep = w > 0
    w = w[keep]
    return np.ascontiguousarray(s.theta[keep]), w / w.sum()


class EMD(Distance):
    """Earth Mover's Distance with Euclidean ground cost and the weights as masses (8.2.3)."""

    name = "emd"
    symmetric = True
    params: ClassVar[dict[str, Any]] = {"num_iter_max": 1_000_000}

    def check_params(self, p: dict[str, Any]) -> dict[str, Any]:
        p["num_iter_max"] = check_positive_int("num_iter_max", p["num_iter_max"])
        return p

    def features(self, s: SampleSet, p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        return _masses(s)

    def compare(self, fa: tuple, fb: tuple, p: dict[str, Any]) -> float:
        import ot

        (xa, wa), (xb, wb) = fa, fb
        cost = cdist(xa, xb, "euclidean")  # = ot.dist(xa, xb, "euclidean"), without cancellation
        # POT warns (UserWarning "numItermax reached before optimality") if the
        # simplex stops early; the value is then an upper bound
        value = ot.emd2(wa, wb, cost, numItermax=p["num_iter_max"])
        return max(float(value), 0.0)


class SlicedWasserstein(Distance):
    """Sliced p-Wasserstein distance (POT), seeded random projections: EMD for very large sets."""

    name = "sliced_wasserstein"
    symmetric = True
    params: ClassVar[dict[str, Any]] = {"n_projections": 200, "p": 2.0, "seed": 0}

    def check_params(self, p: dict[str, Any]) -> dict[str, Any]:
        p["n_projections"] = check_positive_int("n_projections", p["n_projections"])
        p["p"] = check_range("p", p["p"], 1.0, np.inf, high_open=True)
        # an integer seed only: ``None`` would draw other directions per posterior
        p["seed"] = check_positive_int("seed", p["seed"], minimum=0)
        return p

    def projections(self, d: int, p: dict[str, Any]) -> np.ndarray:
        """(d, n_projections) unit directions from ``default_rng(seed)``."""
        u = np.random.default_rng(p["seed"]).standard_normal((d, p["n_projections"]))
        return u / np.linalg.norm(u, axis=0, keepdims=True)

    def features(self, s: SampleSet, p: dict[str, Any]) -> tuple[np.ndarray, ...]:
        check_memory(8.0 * 2 * s.theta.shape[1] * p["n_projections"],
                     f"sliced_wasserstein's {p['n_projections']} projections",
                     "lower n_projections")
        # the directions depend only on (d, seed): every posterior, hence every
        # pair of a matrix, uses the same draw, so d(a, b) == d(b, a)
        return (*_masses(s), self.projections(s.theta.shape[1], p))

    def compare(self, fa: tuple, fb: tuple, p: dict[str, Any]) -> float:
        import ot

        (xa, wa, proj), (xb, wb, _) = fa, fb
        # POT projects both sets on every direction at once, then sorts: (S_a + S_b) x n
        check_memory(8.0 * 3 * (xa.shape[0] + xb.shape[0]) * p["n_projections"],
                     f"sliced_wasserstein with n_projections={p['n_projections']} on "
                     f"{xa.shape[0]} and {xb.shape[0]} samples", "lower n_projections")
        return max(float(ot.sliced_wasserstein_distance(xa, xb, wa, wb, p=p["p"],
                                                         projections=proj)), 0.0)
