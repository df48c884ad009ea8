"""Average Gaussian Mixture Model Probability (AGMMP), thesis 8.2.1, Eqs. 8.3-8.8.

Each weighted set {x, π^x} is read as a Gaussian mixture with one isotropic
component per sample, Σ = σ·I (Eq. 8.4: σ is the component *variance*), and
with the sample weights as mixture priors. The log density of a point under
the mixture of set y (Eqs. 8.3-8.5) is

    log p(xᵢ | y) = log Σⱼ πʸⱼ N(xᵢ; yⱼ, σI)
                  = logsumexp_j(log πʸⱼ − ‖xᵢ − yⱼ‖²/(2σ)) − (d/2) log(2πσ),

computed in log space, so that 1000-sample sets with σ = 1e-4 stay finite
(the densities themselves under- or overflow). The set log likelihood is

* ``form="thesis"`` (Eqs. 8.6-8.7, literally): L(x|y) = Σᵢ log p(xᵢ | y), the
  product over the samples of x *ignoring x's weights* -- as the thesis notes
  below Eq. 8.7, only the second set's weights enter;
* ``form="weighted"`` (default): L(x|y) = Σᵢ πˣᵢ log p(xᵢ | y), each sample of x
  counted by its normalised weight (the importance-weighted mean log
  likelihood). For equally weighted sets of N samples it is L_thesis / N.

and, symmetrised by Eq. 8.8,

    AGMMP(x, y) = [exp L(x|y) + exp L(y|x)] / 2,
    log AGMMP   = logaddexp(L(x|y), L(y|x)) − log 2.

Why ``weighted`` is the default: the literal Eq. 8.7 counts a sample twice if
it is duplicated but once if its weight is doubled, so it does not honour the
weights (a property every mrfpe distance must have), and it scales with the
sample count, so sets of different sizes are not comparable. ``weighted`` fixes
both, is what Eq. 8.8's symmetrisation aims at ("to incorporate this
information [the first set's weights] into our measure"), and equals the
thesis form for equal weights up to the power 1/N. Use ``form="thesis"`` to
reproduce Tables 8.3-8.9.

Notes on the thesis text: Eq. 8.5 carries a factor 1/M inside each sample's
sum and Eq. 8.7 a single 1/M outside the product; with normalised weights
πʸ (Σ πʸ = 1) neither belongs to "the usual equation for the probability of
data given a Gaussian mixture model" that Eq. 8.7 says it is, so neither is
applied. For sets of equal size (all of the thesis's, 1000 samples) both
factors are the same constant for every pair and change no ranking. Eq. 8.6's
``p(xᵢ, y)`` is read as ``p(xᵢ | y)``.

Distance form: ``-log AGMMP`` (decreasing in the similarity; it can be
negative, because mixture *densities* exceed 1 for small σ).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from mrfpe.distances.base import SampleSet, Similarity
from mrfpe.mixture import log_mixture_density as shared_log_mixture_density
from mrfpe.validation import check_choice, check_range

__all__ = ["AGMMP", "log_mixture_density", "set_log_likelihood"]

def log_mixture_density(x: np.ndarray, y: np.ndarray, log_wy: np.ndarray,
                        sigma: float) -> np.ndarray:
    """``log Σⱼ exp(log_wyⱼ) N(xᵢ; yⱼ, σI)`` for every row of ``x`` (Eqs. 8.3-8.5).

    ``x`` (N, d), ``y`` (M, d), ``log_wy`` (M,) normalised log weights, ``σ`` the
    component *variance* (Eq. 8.4). Computed by the shared
    :func:`mrfpe.mixture.log_mixture_density` with scale ``sqrt(σ)``, which takes
    the differences ``xᵢ − yⱼ`` directly (no ``|x|² + |y|² − 2x·y`` cancellation
    for near-coincident points) and bounds memory by chunking;
    ``tests/distances/test_agmmp.py`` checks it against a cdist-based route to 1e-10.
    """
    keep = np.isfinite(log_wy)  # zero-weight components add nothing to the mixture
    if not keep.any():
        raise ValueError("log_wy must hold at least one finite log weight")
    return shared_log_mixture_density(np.asarray(x, dtype=np.float64),
                                      np.asarray(y, dtype=np.float64)[keep],
                                      np.asarray(log_wy, dtype=np.float64)[keep],
                                      float(np.sqrt(sigma)))


def set_log_likelihood(lp: np.ndarray, log_wx: np.ndarray, form: str) -> float:
    """L(x|y) from the per-sample log densities ``lp`` = log p(xᵢ | y) (Eq. 8.7)."""
    if form == "thesis":
        return float(lp.sum())
    w = np.exp(log_wx)
    return float(w[w > 0] @ lp[w > 0])


class AGMMP(Similarity):
    """Average Gaussian Mixture Model Probability similarity (Eqs. 8.3-8.8); distance −log AGMMP.

    Parameters: ``sigma`` -- the variance of each mixture component
    (Σ = σI, Eq. 8.4; the thesis tries 0.5 ... 1e-4), ``form`` -- ``"weighted"``
    (default) or ``"thesis"`` (Eq. 8.7 literally), see the module docstring.
    """

    name = "agmmp"
    symmetric = True
    nonnegative = False
    params: ClassVar[dict[str, Any]] = {"sigma": 0.005, "form": "weighted"}

    def check_params(self, p: dict[str, Any]) -> dict[str, Any]:
        p["sigma"] = check_range("sigma", p["sigma"], 0.0, np.inf, low_open=True,
                                 high_open=True)
        p["form"] = check_choice("form", p["form"], ("weighted", "thesis"))
        return p

    def features(self, s: SampleSet, p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        return s.theta, s.log_weight

    def _directional(self, fx: tuple, fy: tuple, p: dict[str, Any]) -> float:
        (x, lwx), (y, lwy) = fx, fy
        if p["form"] == "weighted":  # zero-weight samples of x count 0 times
            keep_x = np.isfinite(lwx)
            x, lwx = x[keep_x], lwx[keep_x]
        lp = log_mixture_density(x, y, lwy, p["sigma"])
        return set_log_likelihood(lp, lwx, p["form"])

    def log_agmmp(self, fa: tuple, fb: tuple, p: dict[str, Any]) -> float:
        """log AGMMP = logaddexp(L(a|b), L(b|a)) − log 2 (Eq. 8.8)."""
        return float(np.logaddexp(self._directional(fa, fb, p), self._directional(fb, fa, p))
                     - np.log(2.0))

    def compare(self, fa: tuple, fb: tuple, p: dict[str, Any]) -> float:
        return -self.log_agmmp(fa, fb, p)

    def pairwise_features(self, feats: Any, p: dict[str, Any], *, n_jobs: int = 1,
                          progress: bool = False) -> np.ndarray:
        """All directional L(xₐ|y_b) once each, then Eq. 8.8 on the matrix."""
        from mrfpe.distances.base import pair_loop

        feats = list(feats)
        lmat = pair_loop(lambda i, j: self._directional(feats[i], feats[j], p), len(feats),
                         symmetric=False, n_jobs=n_jobs, progress=progress, desc=self.name)
        return -(np.logaddexp(lmat, lmat.T) - np.log(2.0))

    def similarity_from_distance(self, d: Any) -> Any:
        """AGMMP = exp(−d); may overflow to inf or underflow to 0 -- prefer the log."""
        with np.errstate(over="ignore", under="ignore"):
            return np.exp(-np.asarray(d, dtype=np.float64))

    def log_similarity_from_distance(self, d: Any) -> Any:
        return -np.asarray(d, dtype=np.float64)

    def score(self, d: Any) -> Any:
        """Similarity-matrix entry: log AGMMP (finite where AGMMP itself is not)."""
        return self.log_similarity_from_distance(d)
