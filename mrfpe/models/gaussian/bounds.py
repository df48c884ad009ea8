"""The auto-normal parameters' bounds: data-driven defaults, and overrides by name or array.

Default bounds (``GaussianMRF.default_bounds``; ``bounds=`` overrides any of them):

* ``coupling_t``: ``(1 / lambda_min(W_t), 1 / lambda_max(W_t))``, the exact
  interval in which ``Q`` is PD when the other couplings are 0 (for one
  coupling type: exactly the PD interval). On a periodic 4-neighbour lattice of
  even size that is ``(-1/4, 1/4)``; on a free ``H x W`` one it is a little wider,
  ``1 / (2 cos(pi/(H+1)) + 2 cos(pi/(W+1)))``. With several coupling types the
  box spans the PD region's axis intercepts: on the closed-form lattices that is
  exactly the region's bounding box (``log_prob`` is ``-inf`` in the box's corners
  outside the region); on a typed general graph the region may reach beyond the
  box where one coupling compensates another (widen it with ``bounds=``). A coupling type
  with no edges gets ``(-1, 1)``.
* ``precision``: ``(0, tau_PL max(2, 1 + 10 sqrt(2 / n_min)))``. ``tau_PL = n_terms /
  min RSS`` is the pseudolikelihood's maximum over the precision, the conditional
  residuals' sum of squares minimised over the mean, covariates and couplings (the
  couplings over their box; the mean and covariates unbounded, so it is never
  below the PL's own maximum), and ``tau sqrt(2 / n)`` the spread that the PL's
  curvature in ``tau`` gives with ``n`` terms, ``-d^2 PL / d tau^2 = n / (2 tau^2)``.
  ``n_min`` is the fewest terms an estimator has on these data (the smallest coding
  times the number of fields), so the box holds every estimator's spread ten times
  over, and at least twice the PL's maximum (on data the model fits poorly the
  exact likelihood's maximum was up to 1.16 times the PL's). It scales with the
  data: fields multiplied by ``c`` get a box divided by ``c^2``. The precision is
  the inverse *conditional* variance, which for strongly coupled fields is far
  above ``1 / var(x)``, so no fixed multiple of ``1 / var(x)`` bounds it; the
  former ``1e4 / var`` put the posterior in ``10^-4`` of its box. Data that a
  regression fits exactly (a constant field) get ``(0, 1e4 / s^2)``, ``s`` their
  range.
* covariate coefficient ``k``: ``+-10 s / s_k`` (``s``, ``s_k`` the ranges of
  the data and of covariate ``k``).
* ``mean``: ``[min x - s - c, max x + s + c]`` with ``c = sum_k 10 s / s_k max |z_k|``,
  the largest shift the covariate box allows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from mrfpe.models.gaussian.structure import CARStructure
from mrfpe.targets.maximise import grid_size

__all__ = ["MIN_FACTOR", "PRECISION_SDS", "data_bounds", "min_conditional_rss", "named_bounds",
           "precision_cap"]


#: How many of the PL's standard deviations (at the fewest terms) the precision's box
#: reaches beyond the PL's maximum.
PRECISION_SDS = 10.0
#: The precision's box reaches at least this multiple of the PL's maximum: on data the
#: model fits poorly the exact likelihood weighs the residuals differently and peaks
#: elsewhere (measured up to 1.16 times the PL's maximum on 32 x 32 fields).
MIN_FACTOR = 2.0


def data_bounds(st: CARStructure, x: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``(d, 2)`` default bounds (see the module docstring) of fields ``x`` (M, n), ``Z`` (n, K)."""
    lo_x, hi_x = float(x.min()), float(x.max())
    s = hi_x - lo_x if hi_x > lo_x else 1.0
    K = Z.shape[1]
    span_z = np.ptp(Z, axis=0) if K else np.zeros(0)
    span_z = np.where(span_z > 0, span_z, 1.0)
    gmax = 10.0 * s / span_z
    c = float(np.sum(gmax * np.abs(Z).max(axis=0))) if K else 0.0
    rows = [(lo_x - s - c, hi_x + s + c), *map(tuple, st.coupling_box()),
            (0.0, precision_cap(st, x, Z)), *((-g, g) for g in gmax)]
    return np.array(rows, dtype=np.float64)


def precision_cap(st: CARStructure, x: np.ndarray, Z: np.ndarray) -> float:
    """The precision's upper bound ``tau_PL max(MIN_FACTOR, 1 + PRECISION_SDS sqrt(2 /
    n_min))`` (module docstring); ``1e4 / range^2`` where a regression fits the data exactly."""
    M, n = x.shape
    rss = min_conditional_rss(st, x, Z)
    n_min = M * min((c.size for c in st.graph.colour_classes()), default=n)
    total = float(np.sum((x - x.mean()) ** 2))
    if not (np.isfinite(rss) and rss > 1e-12 * max(total, 1e-300)):
        s = float(np.ptp(x)) or 1.0
        return 1e4 / (s * s)
    tau_pl = M * n / rss
    return float(tau_pl * max(MIN_FACTOR, 1.0 + PRECISION_SDS * np.sqrt(2.0 / max(n_min, 1))))


def min_conditional_rss(st: CARStructure, x: np.ndarray, Z: np.ndarray) -> float:
    """``min sum_i e_i^2`` over the couplings (in their box) and the mean and covariates.

    ``e = (I - sum_t beta_t W_t)(x - mu)`` is linear in ``b = c (x) a`` with ``c = (1,
    -beta_1, ..., -beta_T)`` and ``u = x - mu = C a``, ``C = [x, 1, Z]``, ``a_0 = 1``
    (:mod:`mrfpe.models.gaussian.pseudolikelihood`): for fixed ``beta`` the minimum over
    ``a`` is a Schur complement (least squares), and ``beta`` is searched on a grid of
    about 4096 points, refined twice around its best point.
    """
    M, n = x.shape
    C = np.concatenate([x[:, :, None], np.ones((M, n, 1)),
                        np.broadcast_to(Z, (M, n, Z.shape[1]))], axis=2)
    C[:, :, 0] -= x.mean()
    P, T = C.shape[2], st.T
    G = np.concatenate([C] + [np.stack([W @ Cm for Cm in C]) for W in st.W], axis=2)
    Gf = G.reshape(-1, G.shape[2])
    S = (Gf.T @ Gf).reshape(1 + T, P, 1 + T, P)
    box = st.coupling_box()
    k = max(3, grid_size(4096, T))
    lo, hi, best = box[:, 0], box[:, 1], np.inf
    for _ in range(3):
        axes = [np.linspace(a, b, k) for a, b in zip(lo, hi, strict=True)]
        beta = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, T)
        r = _profiled_rss(S, beta)
        j = int(np.argmin(r))
        best = min(best, float(r[j]))
        step = (hi - lo) / (k - 1)
        lo = np.maximum(beta[j] - step, box[:, 0])
        hi = np.minimum(beta[j] + step, box[:, 1])
    return best


def _profiled_rss(S: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """``min_a (c (x) a)' S (c (x) a)`` with ``a_0 = 1``, per coupling vector (N, T)."""
    c = np.concatenate([np.ones((beta.shape[0], 1)), -beta], axis=1)
    Sc = np.einsum("ns,spuq,nu->npq", c, S, c)
    cross = Sc[:, 1:, 0]  # a constant or repeated covariate column: the pseudo-inverse
    sol = np.einsum("npq,nq->np", np.linalg.pinv(Sc[:, 1:, 1:], hermitian=True), cross)
    return Sc[:, 0, 0] - np.einsum("np,np->n", cross, sol)


def named_bounds(names: Sequence[str], value: Any, what: str) -> dict[str, tuple[float, float]]:
    """Bounds ``value`` (a ``(d, 2)`` array or a mapping name -> (low, high)) by parameter name.

    Each pair must be finite with low < high; ``what`` names ``value`` in the ValueError.
    """
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in names]
        if unknown:
            raise ValueError(f"{what} names unknown parameter(s) "
                             f"{', '.join(map(repr, unknown))}; parameters: {names}")
        items = list(value.items())
    else:
        b = np.asarray(value, dtype=np.float64)
        if b.shape != (len(names), 2):
            raise ValueError(f"{what} must be ({len(names)}, 2), one row per parameter "
                             f"{names}; got {b.shape}")
        items = list(zip(names, b, strict=True))
    out = {}
    for k, pair in items:
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ValueError(f"{what}[{k!r}] must be (low, high); got {pair!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"{what}[{k!r}] must be finite with low < high; got "
                             f"({lo}, {hi})")
        out[k] = (lo, hi)
    return out
