"""Analytic Jacobians of the per-node terms and residuals of the BRDF pseudolikelihood family.

For Levenberg-Marquardt (7.3.2, ``lm_multiseed``): one kernel pass over the
lean template tables (:mod:`mrfpe.brdf.engine.gradient`) gives, for one particle, every
node's term ``l_i`` and its derivatives with respect to the five separable-form
coefficients ``c = (c0, c1, c2, e1, e2)``:

    ``dl_i/dc = -a dE_i(x_i)/dc - b sum_s p_i(s) dE_i(s)/dc``, ``p_i = softmax(-E_i)``,
    ``dE_i(s)/dc = (1/sigma_b) sum_slots sign(t) dt/dc``, ``t = y - c0 A - c1 S1 - c2 S2``,

with ``dt/dc0 = -A``, ``dt/dc1 = -S1``, ``dt/dc2 = -S2`` and ``dt/de_k = -sum_tri (c1 wF1 +
c2 wF2) X G_k`` (``X`` a triangle's exponential). The L1 data energy has a kink
where ``t = 0``; there the one-sided derivative of the sign taken is used
(forward differences straddle it the same way). The chain to the unit-cube
parameters ``theta`` goes through :func:`mrfpe.brdf.targets.reflectance.coefficients`
(five cheap numbers per particle, differenced centrally in NumPy) and the
residual transform of :mod:`mrfpe.brdf.targets.residuals`.

Cost: about 1.2 value passes of the small-batch kernel for Ward and 1.5 for the
full form (one core, 20 labels: Ward 100×100 3.1 ms against 2.6 ms for the residuals
alone; Phong 50×50 1.7 ms against 1.1 ms), against ``d + 1`` for forward differences,
and exact. The label loops are split so that each has at most four store streams:
with five or more (beside ~20 load streams) LLVM left the loop scalar, 2.6× slower
for Ward (measured on numba 0.68; see docs/targets.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf.engine.gradient import grad_nodes
from mrfpe.fastmath import LOG2E
from mrfpe.threads import thread_budget

__all__ = ["node_terms_and_jacobian", "node_terms_and_jacobians", "residuals_and_jacobian",
           "residuals_and_jacobians", "supports"]

_COEF_STEP = 1e-6  # central differences of the coefficient map (unit cube)


def supports(target: Any) -> bool:
    """Whether ``target`` has the tables this module differentiates (the lean template)."""
    tables = getattr(target, "_engine_tables", None)
    return tables is not None and getattr(target, "model", None) is not None and \
        tables.lean is not None


def _coefficients_and_jacobian(model: Any, to_natural: Any,
                               theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The coefficients ``c`` (5,) of one unit-cube point and ``dc/dtheta`` (5, d).

    Central differences (one-sided at 0), all in one ``coefficients`` call of 1 + 2d rows.
    """
    from mrfpe.brdf.targets import reflectance

    d = theta.size
    h = np.full(d, _COEF_STEP)
    lo_ok = theta - h >= 0
    pts = np.repeat(theta[None], 1 + 2 * d, axis=0)
    pts[1 + np.arange(d), np.arange(d)] += h
    pts[1 + d + np.arange(d), np.arange(d)] -= np.where(lo_ok, h, 0.0)
    c = reflectance.coefficients(model, to_natural(pts))
    return c[0], ((c[1:1 + d] - c[1 + d:]) / (h * np.where(lo_ok, 2.0, 1.0))[:, None]).T


def node_terms_and_jacobian(target: Any, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-node terms (n,) and their Jacobian (n, d) at one unit-cube point ``theta`` (d,).

    ``target`` is a BRDF pseudolikelihood target for which :func:`supports` holds;
    the terms equal ``target.node_terms(theta[None])[0]``.
    """
    val, jac = node_terms_and_jacobians(target, np.asarray(theta, dtype=np.float64).reshape(1, -1))
    return val[0], jac[0]


def node_terms_and_jacobians(target: Any, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`node_terms_and_jacobian` of K points (K, d) in one kernel pass: (K, n), (K, n, d).

    Each row is bit-identical to the single-point call (the kernel computes every
    particle alike whatever K), at a fraction of its cost per point from K of a few
    on: the pass reads the tables once for all K.
    """
    thetas = np.atleast_2d(np.asarray(thetas, dtype=np.float64))
    model = target.model
    full = model.name not in ("lambertian", "ward")
    tables = target._engine_tables
    t, lt = tables.data, tables.lean
    pairs = [_coefficients_and_jacobian(model, target.to_natural, th) for th in thetas]
    ck = np.array([c for c, _ in pairs]).T.copy()  # (5, K)
    ck[3:] *= LOG2E
    n, k = t.n_nodes, thetas.shape[0]
    val = np.empty((k, n))
    grad = np.empty((k, n, 5))
    if n:
        with thread_budget(t.brdf_evals_per_particle * k):  # as k residual rows
            grad_nodes(ck, full, lt.isotropic, lt.recT, lt.nrecT, tables.unary_log2_t,
                       tables.obs, LOG2E / target.sigma_b, n, float(target._a), float(target._b),
                       val, grad)
    jac = np.stack([grad[q] @ dc for q, (_, dc) in enumerate(pairs)])  # row by row, as K = 1
    return val + target._const, jac


def residuals_and_jacobian(target: Any, theta: np.ndarray,
                           kind: str = "inverse") -> tuple[np.ndarray, np.ndarray]:
    """Residuals (n,) of :meth:`~mrfpe.brdf.targets.brdf_target.BRDFTarget.residuals` and
    ``dr/dtheta``.

    Same clipping as :func:`mrfpe.brdf.targets.residuals.transform`; where a residual is
    clipped (or infinite) its row of the Jacobian is 0.
    """
    r, jac = residuals_and_jacobians(target, np.asarray(theta, dtype=np.float64).reshape(1, -1),
                                     kind)
    return r[0], jac[0]


def residuals_and_jacobians(target: Any, thetas: np.ndarray,
                            kind: str = "inverse") -> tuple[np.ndarray, np.ndarray]:
    """:func:`residuals_and_jacobian` of K points (K, d) in one pass: (K, n), (K, n, d)."""
    from mrfpe.brdf.targets.residuals import LOG_CLIP, transform

    ell, jl = node_terms_and_jacobians(target, thetas)
    r = transform(ell, kind)
    if kind == "inverse":
        fac = np.where(-ell < LOG_CLIP, -r, 0.0)
    elif kind == "one_minus":
        fac = np.where(ell < 0, -np.exp(np.minimum(ell, 0.0)), 0.0)
    else:
        with np.errstate(divide="ignore"):
            fac = np.where(r > 0, -0.5 / r, 0.0)
    fac = np.where(np.isfinite(r), fac, 0.0)
    return r, fac[..., None] * jl
