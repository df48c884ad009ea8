"""Parametric BRDF models (thesis chapter 3) evaluated for batches of parameters.

Every model maps a batch of parameter vectors ``theta`` (N, d), in natural units,
and local geometry -- unit normal ``n``, unit direction to the light ``l``, unit
direction to the camera ``v`` and, for anisotropic models, a unit surface
tangent ``t`` (each (..., 3)) -- to BRDF values (N, ...) in 1/sr.

Conventions shared by all models
--------------------------------
* ``l`` and ``v`` point *away* from the surface (thesis 3.10-3.11, Fig. 3.1).
* Where ``n . l <= 0`` or ``n . v <= 0`` (light or camera below the tangent
  plane) the BRDF is defined as 0: the surface element receives no light or is
  not seen, and the thesis's rendering equation multiplies by ``max(n . l, 0)``.
* Inputs are assumed to be unit vectors; they are not renormalised.

Evaluation is split in two so that a target can precompute everything that
does not depend on ``theta`` once (``features``: a small stack of per-geometry
scalars, (k, ...)) and evaluate a batch of parameters cheaply
(``evaluate_features``), possibly in a numba kernel that mirrors the scalar
formula documented on each class. ``evaluate`` is exactly
``evaluate_features(theta, features(n, l, v, t))``.

Unit-cube reparameterisation (thesis 7.1-7.2): ``natural = unit_scale * u``
with ``rho``/``R`` scaled by 1, Ward ``alpha = 0.5 u`` and Phong ``n = 25 u``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf.geometry import cross, dot

__all__ = [
    "BRDF",
    "AshikhminShirley",
    "AshikhminShirleyIsotropic",
    "Lambertian",
    "Ward",
    "WardAnisotropic",
    "get",
    "names",
]

_PI = np.pi


def _vec(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3); got {arr.shape}")
    return arr


class BRDF:
    """Base class: parameter bookkeeping and the two-stage evaluation.

    Attributes
    ----------
    name : str
    param_names : tuple of str
    bounds : ndarray (d, 2)
        Closed bounds in natural units (thesis 7.1, 7.2).
    unit_scale : ndarray (d,)
        ``natural = unit_scale * u`` for ``u`` in the unit cube.
    anisotropic : bool
        Whether ``evaluate`` needs the tangent ``t``.
    feature_names : tuple of str
        Names of the rows returned by :meth:`features`.
    """

    name: str = ""
    param_names: tuple[str, ...] = ()
    unit_scale: np.ndarray = np.zeros(0)
    anisotropic: bool = False
    feature_names: tuple[str, ...] = ()

    @property
    def d(self) -> int:
        return len(self.param_names)

    @property
    def bounds(self) -> np.ndarray:
        return np.stack([np.zeros(self.d), np.asarray(self.unit_scale, float)], axis=1)

    # -- parameters ---------------------------------------------------------------
    def to_natural(self, u: Any) -> np.ndarray:
        """Unit-cube parameters -> natural units (thesis 7.1-7.2)."""
        u = np.asarray(u, dtype=np.float64)
        if u.shape[-1:] != (self.d,):
            raise ValueError(f"u must have trailing dimension {self.d}; got shape {u.shape}")
        return u * self.unit_scale

    def to_unit(self, theta: Any) -> np.ndarray:
        """Natural units -> unit-cube parameters (inverse of :meth:`to_natural`)."""
        theta = np.asarray(theta, dtype=np.float64)
        if theta.shape[-1:] != (self.d,):
            raise ValueError(
                f"theta must have trailing dimension {self.d}; got shape {theta.shape}")
        return theta / self.unit_scale

    def as_batch(self, theta: Any, name: str = "theta") -> np.ndarray:
        """Return ``theta`` as a finite float64 (N, d) batch (a (d,) vector becomes (1, d))."""
        arr = np.asarray(theta, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != self.d:
            raise ValueError(
                f"{name} must have shape (N, {self.d}) or ({self.d},) for {self.name} "
                f"{self.param_names}; got {np.shape(theta)}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite; got {arr}")
        return arr

    def in_bounds(self, theta: Any) -> np.ndarray:
        """Boolean mask (N,) of rows inside the closed natural bounds."""
        arr = self.as_batch(theta)
        b = self.bounds
        return np.all((arr >= b[:, 0]) & (arr <= b[:, 1]), axis=1)

    def check_theta(self, theta: Any, name: str = "theta") -> np.ndarray:
        """Validate natural-unit parameters against shape and bounds; return (N, d)."""
        arr = self.as_batch(theta, name)
        bad = ~self.in_bounds(arr)
        if bad.any():
            raise ValueError(
                f"{name} outside the {self.name} bounds {self.bounds.tolist()} "
                f"({self.param_names}, natural units): {arr[bad][:3].tolist()}")
        return arr

    # -- evaluation -----------------------------------------------------------------
    def features(self, n: Any, l: Any, v: Any, t: Any = None) -> np.ndarray:
        """Theta-independent geometry scalars, stacked as (k, ...) (see ``feature_names``)."""
        n, l, v = _vec(n, "n"), _vec(l, "l"), _vec(v, "v")
        if self.anisotropic:
            if t is None:
                raise ValueError(f"t (surface tangent) is required by the {self.name} model")
            t = _vec(t, "t")
        return self._features(n, l, v, t)

    def evaluate_features(self, theta: Any, feats: np.ndarray) -> np.ndarray:
        """BRDF (N, ...) from a parameter batch (N, d) and :meth:`features` output (k, ...)."""
        theta = self.as_batch(theta)
        feats = np.asarray(feats, dtype=np.float64)
        if feats.shape[:1] != (len(self.feature_names),):
            raise ValueError(
                f"feats must have leading dimension {len(self.feature_names)} "
                f"{self.feature_names}; got shape {feats.shape}")
        extra = (1,) * (feats.ndim - 1)
        cols = [theta[:, k].reshape((-1, *extra)) for k in range(self.d)]
        return self._evaluate(cols, feats)

    def evaluate(self, theta: Any, n: Any, l: Any, v: Any, t: Any = None) -> np.ndarray:
        """BRDF values (N, ...) in 1/sr for ``theta`` (N, d) and geometry (..., 3)."""
        return self.evaluate_features(theta, self.features(n, l, v, t))

    def _features(self, n, l, v, t) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _evaluate(self, cols, feats) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, params={self.param_names})"


def _visibility(n, l, v):
    """cos_i = n.l, cos_o = n.v and the mask where both are positive."""
    ci = dot(n, l)
    co = dot(n, v)
    valid = (ci > 0) & (co > 0)
    return ci, co, valid


class Lambertian(BRDF):
    """Lambertian reflector: ``rho = rho_d / pi`` (thesis 4.16).

    Features: ``lam`` (1 where n.l > 0 and n.v > 0, else 0).
    Scalar form: ``rho_d * lam / pi``.
    """

    name = "lambertian"
    param_names = ("rho_d",)
    unit_scale = np.array([1.0])
    feature_names = ("lam",)

    def _features(self, n, l, v, t):
        _, _, valid = _visibility(n, l, v)
        return valid.astype(np.float64)[None]

    def _evaluate(self, cols, feats):
        (rho_d,) = cols
        return rho_d * feats[0] / _PI


class Ward(BRDF):
    """Isotropic Gaussian Ward BRDF, thesis 3.1 (Ward 1992, eq. 4a).

    ``rho = rho_d/pi + rho_s exp(-tan^2(delta)/alpha^2) / (4 pi alpha^2 sqrt(cos_i cos_o))``
    with ``delta`` the angle between the half vector and the normal.

    ``tan^2 delta`` is computed without trigonometry from the *unnormalised*
    half vector ``h = l + v`` as ``|h - (h.n) n|^2 / (h.n)^2`` (the ratio does
    not depend on the length of ``h``). This is exactly 3.1; the thesis's
    "efficient" form 3.3-3.6 is not: 3.3 drops the squares on ``h.u/alpha_u``
    and ``h.v/alpha_v``, 3.4-3.5 write ``sin(theta) cos(theta)`` and
    ``sin(theta)^2`` where ``sin(theta) cos(phi)`` and ``sin(theta) sin(phi)``
    are meant, and even corrected, Ward's published 5b form
    ``exp(-2 [(h.u/a_u)^2 + (h.v/a_v)^2] / (1 + h.n))`` equals ``exp(-2(1 - cos
    delta)/alpha^2)`` in the isotropic case, which agrees with 3.1 only to
    second order in ``delta``. We implement 3.1/3.2 exactly.

    ``alpha = 0`` (the closed lower bound) makes the lobe a Dirac delta that
    is hit with probability zero; the specular term is then 0.

    Features: ``lam`` (visibility mask), ``spec_norm = lam / (4 pi sqrt(cos_i cos_o))``,
    ``tan2`` (``tan^2 delta``). Scalar form:
    ``rho_d lam / pi + rho_s spec_norm exp(-tan2/alpha^2) / alpha^2``.
    """

    name = "ward"
    param_names = ("rho_d", "rho_s", "alpha")
    unit_scale = np.array([1.0, 1.0, 0.5])
    feature_names = ("lam", "spec_norm", "tan2")

    def _features(self, n, l, v, t):
        ci, co, valid = _visibility(n, l, v)
        h = l + v
        hn = dot(h, n)
        hp = h - hn[..., None] * n
        ok = valid & (hn > 0)
        hn_s = np.where(ok, hn, 1.0)
        tan2 = np.where(ok, dot(hp, hp) / (hn_s * hn_s), 0.0)
        prod = np.where(ok, ci * co, 1.0)
        spec_norm = np.where(ok, 1.0 / (4.0 * _PI * np.sqrt(prod)), 0.0)
        return np.stack([ok.astype(np.float64), spec_norm, tan2])

    def _evaluate(self, cols, feats):
        rho_d, rho_s, alpha = cols
        pos = alpha > 0
        a2 = np.where(pos, alpha * alpha, 1.0)
        lobe = np.exp(-feats[2] / a2) / a2
        return rho_d * feats[0] / _PI + np.where(pos, rho_s, 0.0) * feats[1] * lobe


class WardAnisotropic(BRDF):
    """Anisotropic Ward BRDF, thesis 3.2 (Ward 1992, eq. 5a).

    ``rho = rho_d/pi + rho_s exp(-tan^2(delta) (cos^2 phi/alpha_u^2 + sin^2 phi/alpha_v^2))
    / (4 pi alpha_u alpha_v sqrt(cos_i cos_o))`` with ``phi`` the azimuth of the
    half vector about ``n`` measured from the tangent ``t`` (``u = t``,
    ``v = n x t``). Since ``tan^2 delta cos^2 phi = (h.u / h.n)^2`` and
    ``tan^2 delta sin^2 phi = (h.v / h.n)^2`` for any length of ``h``, we use
    the trigonometry-free exact form (Walter 2005, "Notes on the Ward BRDF")
    rather than the thesis's 3.3-3.6, whose typos are listed on :class:`Ward`.
    With ``alpha_u = alpha_v`` it equals :class:`Ward`. A zero roughness makes
    the specular term 0 (Dirac lobe).

    Features: ``lam``, ``spec_norm``, ``x2 = (h.u/h.n)^2``, ``y2 = (h.v/h.n)^2``.
    Scalar form: ``rho_d lam/pi + rho_s spec_norm exp(-(x2/a_u^2 + y2/a_v^2)) / (a_u a_v)``.
    """

    name = "ward_aniso"
    param_names = ("rho_d", "rho_s", "alpha_u", "alpha_v")
    unit_scale = np.array([1.0, 1.0, 0.5, 0.5])
    anisotropic = True
    feature_names = ("lam", "spec_norm", "x2", "y2")

    def _features(self, n, l, v, t):
        ci, co, valid = _visibility(n, l, v)
        h = l + v
        hn = dot(h, n)
        ok = valid & (hn > 0)
        hn_s = np.where(ok, hn, 1.0)
        b = cross(n, t)
        x = dot(h, t) / hn_s
        y = dot(h, b) / hn_s
        prod = np.where(ok, ci * co, 1.0)
        spec_norm = np.where(ok, 1.0 / (4.0 * _PI * np.sqrt(prod)), 0.0)
        return np.stack([ok.astype(np.float64), spec_norm,
                         np.where(ok, x * x, 0.0), np.where(ok, y * y, 0.0)])

    def _evaluate(self, cols, feats):
        rho_d, rho_s, au, av = cols
        pos = (au > 0) & (av > 0)
        au_s = np.where(pos, au, 1.0)
        av_s = np.where(pos, av, 1.0)
        lobe = np.exp(-(feats[2] / (au_s * au_s) + feats[3] / (av_s * av_s))) / (au_s * av_s)
        return rho_d * feats[0] / _PI + np.where(pos, rho_s, 0.0) * feats[1] * lobe


def _as_common(n, l, v):
    """Ashikhmin-Shirley geometry shared by both variants."""
    nl, nv, valid = _visibility(n, l, v)
    h = l + v
    hh = dot(h, h)
    ok = valid & (hh > 0)
    h = h / np.sqrt(np.where(ok, hh, 1.0))[..., None]
    nh = np.where(ok, dot(n, h), 1.0)
    kh = np.where(ok, dot(l, h), 1.0)  # = v.h for the unit half vector
    nl_s = np.where(ok, nl, 1.0)
    nv_s = np.where(ok, nv, 1.0)
    # 3.16 without R_d (1 - R_s): angle-dependent diffuse factor.
    fd = (28.0 / (23.0 * _PI)) * (1.0 - (1.0 - nl_s / 2.0) ** 5) * (1.0 - (1.0 - nv_s / 2.0) ** 5)
    g = 1.0 / (8.0 * _PI * kh * np.maximum(nl_s, nv_s))
    q5 = (1.0 - kh) ** 5  # Schlick's Fresnel factor (3.14)
    okf = ok.astype(np.float64)
    return h, ok, nh, fd * okf, g * okf, q5


class AshikhminShirley(BRDF):
    """Anisotropic Phong BRDF of Ashikhmin & Shirley (2000), thesis 3.12-3.16.

    ``rho = rho_d + rho_s`` with (``h`` the *unit* half vector, ``k`` = ``l`` or ``v``)

    * ``rho_s = sqrt((n_u+1)(n_v+1))/(8 pi) (n.h)^e / ((h.k) max(n.l, n.v)) F(k.h)``,
      ``e = (n_u (h.u)^2 + n_v (h.v)^2) / (1 - (h.n)^2)`` (3.15 = 3.13),
    * ``F(c) = R_s + (1 - R_s)(1 - c)^5`` (3.14),
    * ``rho_d = 28 R_d/(23 pi) (1 - R_s)(1 - (1 - n.l/2)^5)(1 - (1 - n.v/2)^5)`` (3.16).

    ``u`` is the tangent ``t`` and ``v = n x t``. These are the published
    formulas; 3.15 in this thesis text agrees with them. Where ``h = n`` the
    exponent is 0/0 but ``(n.h)^e = 1`` for any ``e``; the features then use
    equal weights 1/2.

    Features: ``fd`` (3.16's angular factor, without ``R_d (1-R_s)``),
    ``g = 1/(8 pi (k.h) max(n.l, n.v))``, ``nh``, ``q5 = (1 - k.h)^5``,
    ``a = (h.u)^2/(1-(h.n)^2)``, ``b = (h.v)^2/(1-(h.n)^2)``; all zero (``nh``
    one) where invisible. Scalar form:
    ``R_d (1-R_s) fd + sqrt((n_u+1)(n_v+1)) g nh^(n_u a + n_v b) (R_s + (1-R_s) q5)``.
    """

    name = "phong_aniso"
    param_names = ("R_d", "R_s", "n_u", "n_v")
    unit_scale = np.array([1.0, 1.0, 25.0, 25.0])
    anisotropic = True
    feature_names = ("fd", "g", "nh", "q5", "a", "b")

    def _features(self, n, l, v, t):
        h, ok, nh, fd, g, q5 = _as_common(n, l, v)
        s2 = 1.0 - nh * nh
        ok2 = ok & (s2 > 1e-300)
        s2_s = np.where(ok2, s2, 1.0)
        hu = dot(h, t)
        hv = dot(h, cross(n, t))
        a = np.where(ok2, hu * hu / s2_s, 0.5)
        b = np.where(ok2, hv * hv / s2_s, 0.5)
        return np.stack([fd, g, nh, q5, a, b])

    def _evaluate(self, cols, feats):
        rd, rs, nu, nv = cols
        fd, g, nh, q5, a, b = feats
        lobe = np.sqrt((nu + 1.0) * (nv + 1.0)) * g * nh ** (nu * a + nv * b)
        return rd * (1.0 - rs) * fd + lobe * (rs + (1.0 - rs) * q5)


class AshikhminShirleyIsotropic(BRDF):
    """Ashikhmin-Shirley with ``n_u = n_v = n`` (the thesis's "Phong", 4.21, 7.2).

    Then ``e = n`` because ``(h.u)^2 + (h.v)^2 = 1 - (h.n)^2``, and
    ``sqrt((n+1)^2) = n + 1``: see :class:`AshikhminShirley`.

    Features: ``fd``, ``g``, ``nh``, ``q5``. Scalar form:
    ``R_d (1-R_s) fd + (n+1) g nh^n (R_s + (1-R_s) q5)``.
    """

    name = "phong"
    param_names = ("R_d", "R_s", "n")
    unit_scale = np.array([1.0, 1.0, 25.0])
    feature_names = ("fd", "g", "nh", "q5")

    def _features(self, n, l, v, t):
        _, _, nh, fd, g, q5 = _as_common(n, l, v)
        return np.stack([fd, g, nh, q5])

    def _evaluate(self, cols, feats):
        rd, rs, ne = cols
        fd, g, nh, q5 = feats
        return rd * (1.0 - rs) * fd + (ne + 1.0) * g * nh ** ne * (rs + (1.0 - rs) * q5)


_MODELS: dict[str, BRDF] = {
    m.name: m
    for m in (Lambertian(), Ward(), WardAnisotropic(), AshikhminShirley(),
              AshikhminShirleyIsotropic())
}


def names() -> tuple[str, ...]:
    """Names of the built-in BRDF models."""
    return tuple(_MODELS)


def get(name: str | BRDF) -> BRDF:
    """The BRDF model called ``name`` (a model instance is returned unchanged)."""
    if isinstance(name, BRDF):
        return name
    try:
        return _MODELS[name]
    except (KeyError, TypeError):
        raise ValueError(f"brdf must be one of {names()}; got {name!r}") from None
