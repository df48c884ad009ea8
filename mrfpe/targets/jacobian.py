"""Analytic Jacobians of the per-node terms and residuals of the BRDF pseudolikelihood family.

For Levenberg-Marquardt (7.3.2, ``lm_multiseed``): one kernel pass over the
lean template tables (:mod:`mrfpe.targets.lean`) gives, for one particle, every
node's term ``l_i`` and its derivatives with respect to the five separable-form
coefficients ``c = (c0, c1, c2, e1, e2)``:

    ``dl_i/dc = -a dE_i(x_i)/dc - b sum_s p_i(s) dE_i(s)/dc``, ``p_i = softmax(-E_i)``,
    ``dE_i(s)/dc = (1/sigma_b) sum_slots sign(t) dt/dc``, ``t = y - c0 A - c1 S1 - c2 S2``,

with ``dt/dc0 = -A``, ``dt/dc1 = -S1``, ``dt/dc2 = -S2`` and ``dt/de_k = -sum_tri (c1 wF1 +
c2 wF2) X G_k`` (``X`` a triangle's exponential). The L1 data energy has a kink
where ``t = 0``; there the one-sided derivative of the sign taken is used
(forward differences straddle it the same way). The chain to the unit-cube
parameters ``theta`` goes through :func:`mrfpe.targets.reflectance.coefficients`
(five cheap numbers per particle, differenced centrally in NumPy) and the
residual transform of :mod:`mrfpe.targets.residuals`.

Cost: one pass of about 1.5 value passes, against ``d`` value passes for
forward differences.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from mrfpe.targets.kernels import _FM
from mrfpe.targets.lean import LOG2E, exp2_64, lean_tables
from mrfpe.threads import thread_budget

__all__ = ["node_terms_and_jacobian", "residuals_and_jacobian", "supports"]

_LN2 = 0.6931471805599453
_COEF_STEP = 1e-6  # central differences of the coefficient map (unit cube)


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def _sgn(t):
    return (t > 0) * 1.0 - (t < 0) * 1.0


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
def _sgn(t):
    return (t > 0) * 1.0 - (t < 0) * 1.0


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def _grad_labels(coef, full, rec, nrec, unary, obs, inv_sigma, chunk_ptr, a, b,
                 out_val, out_grad):  # pragma: no cover - compiled
    """Node terms ``out_val`` (n,) and ``dl/dc`` ``out_grad`` (n, 5) of one particle.

    Arguments as :func:`mrfpe.targets.lean.lean_terms` without the block (``unary`` and
    ``inv_sigma`` in log2 units, ``coef`` (5,) float64 with ``e1, e2`` times
    log2 e); float64 whatever the tables' precision; a node's labels are the
    loop of a straight-line body, as in the value kernel.
    """
    n_chunks = chunk_ptr.shape[0] - 1
    B = unary.shape[1]
    C0, C1, C2, E1, E2 = coef[0], coef[1], coef[2], coef[3], coef[4]
    af = float(a)
    bf = float(b)
    isg = float(inv_sigma)
    isn = -isg * _LN2  # -1 / sigma_b: derivatives in natural units
    for c in prange(n_chunks):
        en = np.empty(B)
        g = np.empty((5, B))
        pw = np.empty(B)
        for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
            r = rec[i]
            nr = nrec[i]
            ui = unary[i]
            y0, y1, y2, y3 = float(nr[0]), float(nr[1]), float(nr[2]), float(nr[3])
            if full:
                xa = exp2_64(E1 * nr[5] + E2 * nr[7])
                xb = exp2_64(E1 * nr[9] + E2 * nr[11])
                ha1, ha2, hb1, hb2 = nr[4] * xa, nr[6] * xa, nr[8] * xb, nr[10] * xb
                qa = C1 * ha1 + C2 * ha2
                qb = C1 * hb1 + C2 * hb2
                wa1, wa2, wb1, wb2 = qa * nr[5], qa * nr[7], qb * nr[9], qb * nr[11]
                for s in range(B):
                    x0 = exp2_64(E1 * r[5, s] + E2 * r[7, s])
                    x1 = exp2_64(E1 * r[9, s] + E2 * r[11, s])
                    x2 = exp2_64(E1 * r[13, s] + E2 * r[15, s])
                    x3 = exp2_64(E1 * r[17, s] + E2 * r[19, s])
                    x4 = exp2_64(E1 * r[21, s] + E2 * r[23, s])
                    x5 = exp2_64(E1 * r[25, s] + E2 * r[27, s])
                    q0 = (C1 * r[4, s] + C2 * r[6, s]) * x0
                    q1 = (C1 * r[8, s] + C2 * r[10, s]) * x1
                    q2 = (C1 * r[12, s] + C2 * r[14, s]) * x2
                    q3 = (C1 * r[16, s] + C2 * r[18, s]) * x3
                    q4 = (C1 * r[20, s] + C2 * r[22, s]) * x4
                    q5 = (C1 * r[24, s] + C2 * r[26, s]) * x5
                    s10 = r[4, s] * x0 + r[8, s] * x1
                    s20 = r[6, s] * x0 + r[10, s] * x1
                    s11 = r[12, s] * x2 + r[16, s] * x3
                    s21 = r[14, s] * x2 + r[18, s] * x3
                    s12 = ha1 + r[20, s] * x4
                    s22 = ha2 + r[22, s] * x4
                    s13 = hb1 + r[24, s] * x5
                    s23 = hb2 + r[26, s] * x5
                    t0 = y0 - C0 * r[0, s] - C1 * s10 - C2 * s20
                    t1 = y1 - C0 * r[1, s] - C1 * s11 - C2 * s21
                    t2 = y2 - C0 * r[2, s] - C1 * s12 - C2 * s22
                    t3 = y3 - C0 * r[3, s] - C1 * s13 - C2 * s23
                    k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                    en[s] = ui[s] + isg * (abs(t0) + abs(t1) + abs(t2) + abs(t3))
                    g[0, s] = isn * (k0 * r[0, s] + k1 * r[1, s] + k2 * r[2, s] + k3 * r[3, s])
                    g[1, s] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                    g[2, s] = isn * (k0 * s20 + k1 * s21 + k2 * s22 + k3 * s23)
                    g[3, s] = isn * (k0 * (q0 * r[5, s] + q1 * r[9, s])
                                     + k1 * (q2 * r[13, s] + q3 * r[17, s])
                                     + k2 * (wa1 + q4 * r[21, s]) + k3 * (wb1 + q5 * r[25, s]))
                    g[4, s] = isn * (k0 * (q0 * r[7, s] + q1 * r[11, s])
                                     + k1 * (q2 * r[15, s] + q3 * r[19, s])
                                     + k2 * (wa2 + q4 * r[23, s]) + k3 * (wb2 + q5 * r[27, s]))
            else:
                ha = nr[4] * exp2_64(E1 * nr[5])
                hb = nr[6] * exp2_64(E1 * nr[7])
                wa = ha * nr[5]
                wb = hb * nr[7]
                for s in range(B):
                    p0 = r[4, s] * exp2_64(E1 * r[5, s])
                    p1 = r[6, s] * exp2_64(E1 * r[7, s])
                    p2 = r[8, s] * exp2_64(E1 * r[9, s])
                    p3 = r[10, s] * exp2_64(E1 * r[11, s])
                    p4 = r[12, s] * exp2_64(E1 * r[13, s])
                    p5 = r[14, s] * exp2_64(E1 * r[15, s])
                    s10 = p0 + p1
                    s11 = p2 + p3
                    s12 = ha + p4
                    s13 = hb + p5
                    t0 = y0 - C0 * r[0, s] - C1 * s10
                    t1 = y1 - C0 * r[1, s] - C1 * s11
                    t2 = y2 - C0 * r[2, s] - C1 * s12
                    t3 = y3 - C0 * r[3, s] - C1 * s13
                    k0, k1, k2, k3 = _sgn(t0), _sgn(t1), _sgn(t2), _sgn(t3)
                    en[s] = ui[s] + isg * (abs(t0) + abs(t1) + abs(t2) + abs(t3))
                    g[0, s] = isn * (k0 * r[0, s] + k1 * r[1, s] + k2 * r[2, s] + k3 * r[3, s])
                    g[1, s] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                    g[2, s] = 0.0
                    g[3, s] = isn * C1 * (k0 * (p0 * r[5, s] + p1 * r[7, s])
                                          + k1 * (p2 * r[9, s] + p3 * r[11, s])
                                          + k2 * (wa + p4 * r[13, s]) + k3 * (wb + p5 * r[15, s]))
                    g[4, s] = 0.0
            o = obs[i]
            m = en[0]
            for s in range(1, B):
                m = min(m, en[s])
            for s in range(B):
                pw[s] = exp2_64(m - en[s])
            tot = 0.0
            for s in range(B):
                tot += pw[s]
            out_val[i] = _LN2 * (af * -en[o] - bf * m) + bf * np.log(tot)
            for k in range(5):
                acc = 0.0
                gk = g[k]
                for s in range(B):
                    acc += pw[s] * gk[s]
                out_grad[i, k] = -af * gk[o] - bf * acc / tot


def supports(target: Any) -> bool:
    """Whether ``target`` has the tables this module differentiates (the lean template)."""
    t = getattr(target, "_tables", None)
    model = getattr(target, "model", None)
    if t is None or model is None or not hasattr(target, "_unary_e"):
        return False
    return lean_tables(t, model.name not in ("lambertian", "ward")) is not None


def _coef_jacobian(model: Any, to_natural: Any, theta: np.ndarray) -> np.ndarray:
    """``dc/dtheta`` (5, d) of one unit-cube point by central differences (one-sided at 0)."""
    from mrfpe.targets import reflectance

    d = theta.size
    h = np.full(d, _COEF_STEP)
    up = np.repeat(theta[None], d, axis=0) + np.diag(h)
    lo_ok = theta - h >= 0
    dn = np.repeat(theta[None], d, axis=0) - np.diag(np.where(lo_ok, h, 0.0))
    cu = reflectance.coefficients(model, to_natural(up))
    cd = reflectance.coefficients(model, to_natural(dn))
    return ((cu - cd) / (h * np.where(lo_ok, 2.0, 1.0))[:, None]).T


def node_terms_and_jacobian(target: Any, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-node terms (n,) and their Jacobian (n, d) at one unit-cube point ``theta`` (d,).

    ``target`` is a BRDF pseudolikelihood target for which :func:`supports` holds;
    the terms equal ``target.node_terms(theta[None])[0]``.
    """
    from mrfpe.targets import reflectance
    from mrfpe.targets.dispatch import _log2_units

    theta = np.asarray(theta, dtype=np.float64).reshape(-1)
    model = target.model
    full = model.name not in ("lambertian", "ward")
    t = target._tables
    lt = lean_tables(t, full)
    coef = reflectance.coefficients(model, target.to_natural(theta[None]))[0]
    ck = coef.copy()
    ck[3:] *= LOG2E
    n = t.n_nodes
    val = np.empty(n)
    grad = np.empty((n, 5))
    if n:
        with thread_budget(t.brdf_evals_per_particle):  # as one residual call
            _grad_labels(ck, full, lt.rec, lt.nrec, _log2_units(target._unary_e),
                         target._obs, LOG2E / target.sigma_b, target._chunks,
                         float(target._a), float(target._b), val, grad)
    jac = grad @ _coef_jacobian(model, target.to_natural, theta)
    return val + target._const, jac


def residuals_and_jacobian(target: Any, theta: np.ndarray,
                           kind: str = "inverse") -> tuple[np.ndarray, np.ndarray]:
    """Residuals (n,) of :meth:`~mrfpe.targets.brdf_target.BRDFTarget.residuals` and ``dr/dtheta``.

    Same clipping as :func:`mrfpe.targets.residuals.transform`; where a residual is
    clipped (or infinite) its row of the Jacobian is 0.
    """
    from mrfpe.targets.residuals import LOG_CLIP, transform

    ell, jl = node_terms_and_jacobian(target, theta)
    r = transform(ell, kind)
    if kind == "inverse":
        fac = np.where(-ell < LOG_CLIP, -r, 0.0)
    elif kind == "one_minus":
        fac = np.where(ell < 0, -np.exp(np.minimum(ell, 0.0)), 0.0)
    else:
        with np.errstate(divide="ignore"):
            fac = np.where(r > 0, -0.5 / r, 0.0)
    fac = np.where(np.isfinite(r), fac, 0.0)
    return r, fac[:, None] * jl

