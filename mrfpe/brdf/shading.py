"""Shading of surface triangles: the one code path shared by renderer and data terms.

A surface triangle ``(p0, p1, p2)`` (3-D points of three corner-vertex nodes)
is shaded at its centroid:

* normal ``n`` from 4.18, oriented towards the camera;
* ``l`` = direction to the light and ``irradiance`` E at the centroid;
* ``v`` = direction to the camera at the centroid (constant for affine cameras);
* ``t`` = ``tangent_ref`` projected onto the triangle's plane and normalised
  (the ``u`` axis of the anisotropic models, Fig. 3.1).

The outgoing radiance is the rendering equation for one light source (thesis
4.17 with a general BRDF, as used in 4.12/4.20/4.21):

    ``L = BRDF(theta; n, l, v, t) * E * max(n . l, 0)``.

A pixel's intensity is the mean of its two triangles' radiances
(:func:`pixel_intensity`): each triangle of the lattice's per-pixel split
projects onto exactly half the pixel (its vertices lie on the rays through the
pixel corners), so the mean is the image-area-weighted mean. It is *exact* for
the piecewise-planar surface under a directional light and an affine camera
(``n``, ``l``, ``v``, E are constant on each triangle). With a projective
camera ``v`` varies over a triangle, and with a point light ``l`` and E do:
evaluating them at the centroid is then a one-point quadrature of the radiance
over the triangle (second-order accurate in the triangle size).

Bit-for-bit agreement: every function here is element-wise, so evaluating the
same vertex triple (in the same vertex order) gives identical bits whatever
the array it is embedded in. Targets must pass vertices in the order of the
columns of :attr:`mrfpe.brdf.lattice.Lattice.triangles`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.brdf import functions as _brdf
from mrfpe.brdf.geometry import dot, triangle_normals

__all__ = [
    "TriangleGeometry",
    "pixel_intensity",
    "radiance",
    "radiance_from_features",
    "shading_features",
    "triangle_geometry",
]


@dataclass(frozen=True)
class TriangleGeometry:
    """Per-triangle shading geometry, each field (..., 3) or (...).

    Attributes
    ----------
    n : unit normal facing the camera
    l : unit direction to the light
    v : unit direction to the camera
    t : unit tangent (``tangent_ref`` projected on the triangle plane)
    irradiance : irradiance E from the light at the centroid
    """

    n: np.ndarray
    l: np.ndarray
    v: np.ndarray
    t: np.ndarray
    irradiance: np.ndarray

    @property
    def cos_light(self) -> np.ndarray:
        """``max(n . l, 0)``, the foreshortening factor of the rendering equation."""
        return np.maximum(dot(self.n, self.l), 0.0)


def _tangent(n: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``ref`` projected onto the plane with normal ``n``, normalised.

    Where ``ref`` is (nearly) parallel to ``n`` the projection is ill-defined;
    the projection of whichever world axis is least aligned with ``n`` is used there.
    """
    t = ref - dot(ref, n)[..., None] * n
    tt = dot(t, t)
    bad = tt < 1e-12
    if np.any(bad):
        axis = np.argmin(np.abs(n), axis=-1)
        alt = np.zeros_like(n)
        np.put_along_axis(alt, axis[..., None], 1.0, axis=-1)
        alt = alt - dot(alt, n)[..., None] * n
        t = np.where(bad[..., None], alt, t)
        tt = dot(t, t)
    return t / np.sqrt(np.where(tt > 0, tt, 1.0))[..., None]


def triangle_geometry(p0: Any, p1: Any, p2: Any, camera: Any, light: Any,
                      tangent_ref: Any = (1.0, 0.0, 0.0)) -> TriangleGeometry:
    """Shading geometry of triangles (p0, p1, p2), each (..., 3), at their centroids.

    Parameters
    ----------
    p0, p1, p2 : (..., 3)
        Triangle vertices (pass them in the lattice's vertex order, see module doc).
    camera : :class:`~mrfpe.brdf.geometry.AffineCamera` or
        :class:`~mrfpe.brdf.geometry.ProjectiveCamera`
    light : :class:`~mrfpe.brdf.geometry.DirectionalLight` or
        :class:`~mrfpe.brdf.geometry.PointLight`
    tangent_ref : (3,)
        Reference direction whose projection is the anisotropy axis ``u``.
    """
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    p2 = np.asarray(p2, dtype=np.float64)
    ref = np.asarray(tangent_ref, dtype=np.float64)
    if ref.shape != (3,) or not np.all(np.isfinite(ref)) or not np.any(ref != 0):
        raise ValueError(f"tangent_ref must be a finite non-zero (3,) vector; got {tangent_ref!r}")
    centroid = (p0 + p1 + p2) / 3.0
    v = camera.to_camera(centroid)
    n = triangle_normals(p0, p1, p2, v)
    return TriangleGeometry(
        n=n,
        l=light.to_light(centroid),
        v=v,
        t=_tangent(n, np.broadcast_to(ref, n.shape)),
        irradiance=light.irradiance(centroid),
    )


def shading_features(model: Any, geom: TriangleGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Theta-independent part of :func:`radiance`: ``(features (k, ...), weight (...))``.

    ``weight = E * max(n . l, 0)``; a target computes this once per
    (node, label, triangle) and then ``radiance_from_features`` per theta batch.
    """
    model = _brdf.get(model)
    feats = model.features(geom.n, geom.l, geom.v, geom.t if model.anisotropic else None)
    return feats, geom.irradiance * geom.cos_light


def radiance_from_features(model: Any, theta: Any, feats: np.ndarray,
                           weight: np.ndarray) -> np.ndarray:
    """Radiance (N, ...) = ``model.evaluate_features(theta, feats) * weight``."""
    model = _brdf.get(model)
    return model.evaluate_features(theta, feats) * weight


def radiance(model: Any, theta: Any, geom: TriangleGeometry) -> np.ndarray:
    """Outgoing radiance (N, ...) of triangles: ``BRDF * E * max(n·l, 0)`` (4.17).

    ``theta`` is (N, d) (or (d,)) in natural units of ``model`` (name or instance).
    """
    feats, weight = shading_features(model, geom)
    return radiance_from_features(model, theta, feats, weight)


def pixel_intensity(radiance_a: Any, radiance_b: Any) -> np.ndarray:
    """Intensity of a pixel from the radiances of its two triangles: ``0.5 (a + b)``.

    The two triangles cover equal halves of the pixel in the image, so this is
    the area-weighted mean (see the module docstring for when it is exact).
    """
    return 0.5 * (np.asarray(radiance_a) + np.asarray(radiance_b))
