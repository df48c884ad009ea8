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


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def _grad_flat(coef, full, flat, unary, obs, inv_sigma, chunk_ptr, a, b, out_val,
               out_grad):  # pragma: no cover - compiled
    """Node terms ``out_val`` (n,) and ``dl/dc`` ``out_grad`` (n, 5) of one particle.

    ``flat`` (:func:`_flat_tables`): the template fields of every (node, label) entry
    in one row per field, the node's intensities and fixed triangles repeated per
    label, so that the loop over a chunk's entries is long enough to vectorise
    (a loop over a node's 20 labels is shorter than LLVM's vector x interleave
    width and runs scalar). ``unary`` (n*B,) and ``inv_sigma`` in log2 units,
    ``coef`` (5,) float64 with ``e1, e2`` times log2 e; all in float64.
    """
    n_chunks = chunk_ptr.shape[0] - 1
    B = unary.shape[0] // max(1, obs.shape[0])
    C0, C1, C2, E1, E2 = coef[0], coef[1], coef[2], coef[3], coef[4]
    af = float(a)
    bf = float(b)
    isg = float(inv_sigma)
    isn = -isg * _LN2  # -1 / sigma_b: derivatives in natural units
    most = 0
    for c in range(n_chunks):
        most = max(most, (chunk_ptr[c + 1] - chunk_ptr[c]) * B)
    for c in prange(n_chunks):
        e0 = chunk_ptr[c] * B
        m_e = (chunk_ptr[c + 1] - chunk_ptr[c]) * B
        en = np.empty(most)
        g = np.empty((5, most))
        pw = np.empty(B)
        if full:
            for q in range(m_e):
                e = e0 + q
                x0 = exp2_64(E1 * flat[9, e] + E2 * flat[11, e])
                x1 = exp2_64(E1 * flat[13, e] + E2 * flat[15, e])
                x2 = exp2_64(E1 * flat[17, e] + E2 * flat[19, e])
                x3 = exp2_64(E1 * flat[21, e] + E2 * flat[23, e])
                x4 = exp2_64(E1 * flat[25, e] + E2 * flat[27, e])
                x5 = exp2_64(E1 * flat[29, e] + E2 * flat[31, e])
                xa = exp2_64(E1 * flat[33, e] + E2 * flat[35, e])
                xb = exp2_64(E1 * flat[37, e] + E2 * flat[39, e])
                s10 = flat[8, e] * x0 + flat[12, e] * x1
                s20 = flat[10, e] * x0 + flat[14, e] * x1
                s11 = flat[16, e] * x2 + flat[20, e] * x3
                s21 = flat[18, e] * x2 + flat[22, e] * x3
                s12 = flat[32, e] * xa + flat[24, e] * x4
                s22 = flat[34, e] * xa + flat[26, e] * x4
                s13 = flat[36, e] * xb + flat[28, e] * x5
                s23 = flat[38, e] * xb + flat[30, e] * x5
                q0 = (C1 * flat[8, e] + C2 * flat[10, e]) * x0
                q1 = (C1 * flat[12, e] + C2 * flat[14, e]) * x1
                q2 = (C1 * flat[16, e] + C2 * flat[18, e]) * x2
                q3 = (C1 * flat[20, e] + C2 * flat[22, e]) * x3
                q4 = (C1 * flat[24, e] + C2 * flat[26, e]) * x4
                q5 = (C1 * flat[28, e] + C2 * flat[30, e]) * x5
                qa = (C1 * flat[32, e] + C2 * flat[34, e]) * xa
                qb = (C1 * flat[36, e] + C2 * flat[38, e]) * xb
                t0 = flat[4, e] - C0 * flat[0, e] - C1 * s10 - C2 * s20
                t1 = flat[5, e] - C0 * flat[1, e] - C1 * s11 - C2 * s21
                t2 = flat[6, e] - C0 * flat[2, e] - C1 * s12 - C2 * s22
                t3 = flat[7, e] - C0 * flat[3, e] - C1 * s13 - C2 * s23
                k0 = (t0 > 0) * 1.0 - (t0 < 0) * 1.0
                k1 = (t1 > 0) * 1.0 - (t1 < 0) * 1.0
                k2 = (t2 > 0) * 1.0 - (t2 < 0) * 1.0
                k3 = (t3 > 0) * 1.0 - (t3 < 0) * 1.0
                en[q] = unary[e] + isg * (abs(t0) + abs(t1) + abs(t2) + abs(t3))
                g[0, q] = isn * (k0 * flat[0, e] + k1 * flat[1, e] + k2 * flat[2, e]
                                 + k3 * flat[3, e])
                g[1, q] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                g[2, q] = isn * (k0 * s20 + k1 * s21 + k2 * s22 + k3 * s23)
                g[3, q] = isn * (k0 * (q0 * flat[9, e] + q1 * flat[13, e])
                                 + k1 * (q2 * flat[17, e] + q3 * flat[21, e])
                                 + k2 * (qa * flat[33, e] + q4 * flat[25, e])
                                 + k3 * (qb * flat[37, e] + q5 * flat[29, e]))
                g[4, q] = isn * (k0 * (q0 * flat[11, e] + q1 * flat[15, e])
                                 + k1 * (q2 * flat[19, e] + q3 * flat[23, e])
                                 + k2 * (qa * flat[35, e] + q4 * flat[27, e])
                                 + k3 * (qb * flat[39, e] + q5 * flat[31, e]))
        else:
            for q in range(m_e):
                e = e0 + q
                p0 = flat[8, e] * exp2_64(E1 * flat[9, e])
                p1 = flat[10, e] * exp2_64(E1 * flat[11, e])
                p2 = flat[12, e] * exp2_64(E1 * flat[13, e])
                p3 = flat[14, e] * exp2_64(E1 * flat[15, e])
                p4 = flat[16, e] * exp2_64(E1 * flat[17, e])
                p5 = flat[18, e] * exp2_64(E1 * flat[19, e])
                pa = flat[20, e] * exp2_64(E1 * flat[21, e])
                pb = flat[22, e] * exp2_64(E1 * flat[23, e])
                s10 = p0 + p1
                s11 = p2 + p3
                s12 = pa + p4
                s13 = pb + p5
                t0 = flat[4, e] - C0 * flat[0, e] - C1 * s10
                t1 = flat[5, e] - C0 * flat[1, e] - C1 * s11
                t2 = flat[6, e] - C0 * flat[2, e] - C1 * s12
                t3 = flat[7, e] - C0 * flat[3, e] - C1 * s13
                k0 = (t0 > 0) * 1.0 - (t0 < 0) * 1.0
                k1 = (t1 > 0) * 1.0 - (t1 < 0) * 1.0
                k2 = (t2 > 0) * 1.0 - (t2 < 0) * 1.0
                k3 = (t3 > 0) * 1.0 - (t3 < 0) * 1.0
                en[q] = unary[e] + isg * (abs(t0) + abs(t1) + abs(t2) + abs(t3))
                g[0, q] = isn * (k0 * flat[0, e] + k1 * flat[1, e] + k2 * flat[2, e]
                                 + k3 * flat[3, e])
                g[1, q] = isn * (k0 * s10 + k1 * s11 + k2 * s12 + k3 * s13)
                g[2, q] = 0.0
                g[3, q] = isn * C1 * (k0 * (p0 * flat[9, e] + p1 * flat[11, e])
                                      + k1 * (p2 * flat[13, e] + p3 * flat[15, e])
                                      + k2 * (pa * flat[21, e] + p4 * flat[17, e])
                                      + k3 * (pb * flat[23, e] + p5 * flat[19, e]))
                g[4, q] = 0.0
        for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
            q0 = (i - chunk_ptr[c]) * B
            o = q0 + obs[i]
            m = en[q0]
            for s in range(1, B):
                m = min(m, en[q0 + s])
            tot = 0.0
            for s in range(B):
                pw[s] = exp2_64(m - en[q0 + s])
                tot += pw[s]
            out_val[i] = _LN2 * (af * -en[o] - bf * m) + bf * np.log(tot)
            for k in range(5):
                acc = 0.0
                for s in range(B):
                    acc += pw[s] * g[k, q0 + s]
                out_grad[i, k] = -af * g[k, o] - bf * acc / tot


def _flat_tables(t: Any, full: bool) -> np.ndarray:
    """Per-(node, label) rows of every template field (float64), kept on the tables."""
    key = "_lean_flat_full" if full else "_lean_flat"
    if key not in t.__dict__:
        lt = lean_tables(t, full)
        n, _, B = lt.rec.shape
        nf = 4 if full else 2
        rec = lt.rec.astype(np.float64)
        nrec = lt.nrec.astype(np.float64)
        flat = np.empty((8 + 8 * nf, n * B))
        flat[0:4] = rec[:, 0:4].transpose(1, 0, 2).reshape(4, -1)  # A_0..3
        flat[4:8] = np.repeat(nrec[:, 0:4].T, B, axis=1)  # y_0..3
        flat[8:8 + 6 * nf] = rec[:, 4:].transpose(1, 0, 2).reshape(6 * nf, -1)
        flat[8 + 6 * nf:] = np.repeat(nrec[:, 4:].T, B, axis=1)  # fixed triangles
        object.__setattr__(t, key, np.ascontiguousarray(flat))
    return t.__dict__[key]


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
    coef = reflectance.coefficients(model, target.to_natural(theta[None]))[0]
    ck = coef.copy()
    ck[3:] *= LOG2E
    n = t.n_nodes
    val = np.empty(n)
    grad = np.empty((n, 5))
    if n:
        with thread_budget(t.brdf_evals_per_particle * 2):
            _grad_flat(ck, full, _flat_tables(t, full),
                       _log2_units(target._unary_e).astype(np.float64).reshape(-1),
                       target._obs, LOG2E / target.sigma_b, target._chunks, float(target._a),
                       float(target._b), val, grad)
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

