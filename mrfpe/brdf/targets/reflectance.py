"""Every built-in BRDF's radiance in one separable form for the kernels.

The outgoing radiance of a triangle, ``L = BRDF(theta; n, l, v, t) * E * max(n.l, 0)``
(thesis 4.17 with 3.1, 3.2, 3.12-3.16; :func:`mrfpe.brdf.shading.radiance`), is
written as

    ``L = c0 F0 + (c1 F1 + c2 F2) * exp(e1 G1 + e2 G2)``

with theta-independent *features* ``(F0, F1, F2, G1, G2)`` per triangle
(computed once, at target construction, from :meth:`mrfpe.brdf.BRDF.features`
and the shading weight ``E max(n.l, 0)``) and per-particle *coefficients*
``(c0, c1, c2, e1, e2)``:

============  =====================  ============================================
model         features               coefficients
============  =====================  ============================================
lambertian    wL, 0, 0, 0, 0         rho_d/pi, 0, 0, 0, 0
ward          wL, wS, 0, tan2, 0     rho_d/pi, rho_s/a^2, 0, -1/a^2, 0
ward_aniso    wL, wS, 0, x2, y2      rho_d/pi, rho_s/(au av), 0, -1/au^2, -1/av^2
phong         w fd, w g, w g q5,     R_d(1-R_s), (n+1) R_s, (n+1)(1-R_s), n, 0
              log nh, 0
phong_aniso   w fd, w g, w g q5,     R_d(1-R_s), s R_s, s (1-R_s), n_u, n_v
              a log nh, b log nh     with s = sqrt((n_u+1)(n_v+1))
============  =====================  ============================================

(``w`` the shading weight, ``L``/``S`` the Ward ``lam``/``spec_norm`` features;
names as in :mod:`mrfpe.brdf`.) A zero Ward roughness makes the specular term 0,
as in :class:`mrfpe.brdf.Ward` (coefficients c1 = e1 = 0).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf import functions as _brdf

__all__ = ["coefficients", "features", "radiance"]

_PI = np.pi


def features(model: Any, feats: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Separable-form features (M, 5) from ``model.features`` (k, M) and weights (M,)."""
    model = _brdf.get(model)
    feats = np.asarray(feats, dtype=np.float64)
    w = np.asarray(weight, dtype=np.float64)
    out = np.zeros((w.shape[0], 5))
    name = model.name
    if name == "lambertian":
        out[:, 0] = w * feats[0]
    elif name == "ward":
        out[:, 0] = w * feats[0]
        out[:, 1] = w * feats[1]
        out[:, 3] = feats[2]
    elif name == "ward_aniso":
        out[:, 0] = w * feats[0]
        out[:, 1] = w * feats[1]
        out[:, 3] = feats[2]
        out[:, 4] = feats[3]
    elif name in ("phong", "phong_aniso"):
        fd, g, nh, q5 = feats[:4]
        # Visible triangles have n.h > 0 (h lies between l and v, both above the plane);
        # invisible ones carry nh = 1 and zero weights.
        lognh = np.log(np.maximum(nh, 1e-300))
        out[:, 0] = w * fd
        out[:, 1] = w * g
        out[:, 2] = w * g * q5
        if name == "phong":
            out[:, 3] = lognh
        else:
            out[:, 3] = feats[4] * lognh
            out[:, 4] = feats[5] * lognh
    else:  # pragma: no cover - guarded by brdf.get
        raise ValueError(f"no separable form for BRDF {name!r}")
    return out


def coefficients(model: Any, theta: np.ndarray) -> np.ndarray:
    """Per-particle coefficients (N, 5) from natural-unit parameters (N, d).

    A Ward roughness so small that ``alpha**2`` underflows (``alpha < ~1e-154``)
    gives non-finite coefficients silently (no RuntimeWarning); the targets map
    such rows to ``-inf`` (:meth:`mrfpe.brdf.targets.brdf_target.BRDFTarget._terms`).
    """
    model = _brdf.get(model)
    th = np.asarray(theta, dtype=np.float64)
    n = th.shape[0]
    out = np.zeros((n, 5))
    name = model.name
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        _fill(out, name, th)
    return out


def _fill(out: np.ndarray, name: str, th: np.ndarray) -> None:
    if name == "lambertian":
        out[:, 0] = th[:, 0] / _PI
    elif name == "ward":
        rd, rs, al = th.T
        pos = al > 0
        a2 = np.where(pos, al * al, 1.0)
        out[:, 0] = rd / _PI
        out[:, 1] = np.where(pos, rs / a2, 0.0)
        out[:, 3] = np.where(pos, -1.0 / a2, 0.0)
    elif name == "ward_aniso":
        rd, rs, au, av = th.T
        pos = (au > 0) & (av > 0)
        au_s = np.where(pos, au, 1.0)
        av_s = np.where(pos, av, 1.0)
        out[:, 0] = rd / _PI
        out[:, 1] = np.where(pos, rs / (au_s * av_s), 0.0)
        out[:, 3] = np.where(pos, -1.0 / (au_s * au_s), 0.0)
        out[:, 4] = np.where(pos, -1.0 / (av_s * av_s), 0.0)
    elif name == "phong":
        rd, rs, ne = th.T
        out[:, 0] = rd * (1.0 - rs)
        out[:, 1] = (ne + 1.0) * rs
        out[:, 2] = (ne + 1.0) * (1.0 - rs)
        out[:, 3] = ne
    elif name == "phong_aniso":
        rd, rs, nu, nv = th.T
        s = np.sqrt((nu + 1.0) * (nv + 1.0))
        out[:, 0] = rd * (1.0 - rs)
        out[:, 1] = s * rs
        out[:, 2] = s * (1.0 - rs)
        out[:, 3] = nu
        out[:, 4] = nv
    else:  # pragma: no cover
        raise ValueError(f"no separable form for BRDF {name!r}")


def radiance(coef: np.ndarray, feat: np.ndarray) -> np.ndarray:
    """Reference (numpy) evaluation of the separable form: (N, 5) x (M, 5) -> (N, M)."""
    c = np.asarray(coef)[:, :, None]
    f = np.asarray(feat).T[None]
    return c[:, 0] * f[:, 0] + (c[:, 1] * f[:, 1] + c[:, 2] * f[:, 2]) * np.exp(
        c[:, 3] * f[:, 3] + c[:, 4] * f[:, 4])
