"""Lights, cameras, rays, triangle normals and two-view triangulation.

World frame: right-handed, ``x`` to the right, ``y`` down (along image rows),
``z`` along the viewing direction -- the OpenCV convention. The default
camera (thesis 7.2: "camera at the origin") is the orthographic
:class:`AffineCamera` at the origin looking along ``+z``: image point
``(x, y)`` is the ray ``(x, y, 0) + r (0, 0, 1)``, so a node's range label
``r`` is its depth and 1 world unit is 1 pixel width. The thesis's affine
normal 4.15, ``(-p, -q, 1)`` with height ``u``, is this frame's
``(p, q, -1)`` with ``u = -r`` (z towards the viewer there).

Image positions are in pixel units with node ``(row r, column c)`` at
``(x, y) = (c, r)`` (pixel corners; see :mod:`mrfpe.brdf.lattice`).

Every function here works element-wise on arrays of points (..., 3), with
explicit component arithmetic (no BLAS), so the same point gives the same bits
whatever the shape of the array it is part of -- the renderer and the targets
rely on that to agree exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "AffineCamera",
    "DirectionalLight",
    "PointLight",
    "ProjectiveCamera",
    "camera_from_dict",
    "cross",
    "dot",
    "light_from_dict",
    "triangle_normals",
    "triangulate_linear",
]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Component-wise dot product over the last axis (same rounding for any shape)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.sqrt(dot(a, a))[..., None]


def _points(X: Any, name: str = "X") -> np.ndarray:
    arr = np.asarray(X, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3); got {arr.shape}")
    return arr


def _image_points(xy: Any, name: str = "xy") -> np.ndarray:
    arr = np.asarray(xy, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., 2); got {arr.shape}")
    return arr


def _finite_array(x: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    arr = np.array(x, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    arr.flags.writeable = False
    return arr


# ---------------------------------------------------------------------------------- lights
class DirectionalLight:
    """Light source at infinity (thesis 4.2, 7.2).

    Parameters
    ----------
    direction : (3,)
        Direction *towards* the light (normalised here).
    irradiance : float
        Irradiance on a surface facing the light (``I`` in 4.17), >= 0.
    """

    kind = "directional"

    def __init__(self, direction: Any, irradiance: float = 1.0) -> None:
        d = _finite_array(direction, (3,), "direction")
        norm = float(np.sqrt(dot(d, d)))
        if norm == 0.0:
            raise ValueError("direction must be a non-zero vector")
        self.direction = _finite_array(d / norm, (3,), "direction")
        irr = float(irradiance)
        if not np.isfinite(irr) or irr < 0:
            raise ValueError(f"irradiance must be finite and >= 0; got {irradiance!r}")
        self.irradiance_value = irr

    def to_light(self, X: Any) -> np.ndarray:
        """Unit direction from each point towards the light, (..., 3)."""
        X = _points(X)
        return np.broadcast_to(self.direction, X.shape).copy()

    def irradiance(self, X: Any) -> np.ndarray:
        """Irradiance at each point, (...)."""
        X = _points(X)
        return np.full(X.shape[:-1], self.irradiance_value)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "direction": self.direction.tolist(),
                "irradiance": self.irradiance_value}

    def __repr__(self) -> str:
        return f"DirectionalLight(direction={self.direction.tolist()}, " \
               f"irradiance={self.irradiance_value})"


class PointLight:
    """Isotropic point light: irradiance ``intensity / |p - X|^2`` (inverse square).

    Parameters
    ----------
    position : (3,)
        World position of the light.
    intensity : float
        Radiant intensity (W/sr in consistent units), >= 0.
    """

    kind = "point"

    def __init__(self, position: Any, intensity: float = 1.0) -> None:
        self.position = _finite_array(position, (3,), "position")
        val = float(intensity)
        if not np.isfinite(val) or val < 0:
            raise ValueError(f"intensity must be finite and >= 0; got {intensity!r}")
        self.intensity = val

    def to_light(self, X: Any) -> np.ndarray:
        return _unit(self.position - _points(X))

    def irradiance(self, X: Any) -> np.ndarray:
        d = self.position - _points(X)
        return self.intensity / dot(d, d)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "position": self.position.tolist(),
                "intensity": self.intensity}

    def __repr__(self) -> str:
        return f"PointLight(position={self.position.tolist()}, intensity={self.intensity})"


def light_from_dict(d: dict) -> DirectionalLight | PointLight:
    """Inverse of ``light.to_dict()``."""
    kind = d.get("kind")
    if kind == "directional":
        light = DirectionalLight(d["direction"], d["irradiance"])
        # keep the stored unit vector bit for bit (renormalising may change the last bit)
        light.direction = _finite_array(d["direction"], (3,), "direction")
        return light
    if kind == "point":
        return PointLight(d["position"], d["intensity"])
    raise ValueError(f"light kind must be 'directional' or 'point'; got {kind!r}")


# --------------------------------------------------------------------------------- cameras
class AffineCamera:
    """Affine camera ``x = A X + b`` (A 2x3, b 2); orthographic at the origin by default.

    The viewing direction is the unit null vector of ``A`` oriented along
    ``a1 x a2`` (``+z`` for the default). The ray through image point ``xy``
    starts at the point of the plane through the world origin perpendicular to
    the viewing direction that projects to ``xy`` (``A^T (A A^T)^-1 (xy - b)``),
    and a range label ``r`` is the signed distance along the ray from there:
    for the default camera ``points(xy, r) = (x, y, r)`` exactly.
    """

    kind = "affine"

    def __init__(self, A: Any = None, b: Any = None) -> None:
        A = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] if A is None else A
        b = [0.0, 0.0] if b is None else b
        self.A = _finite_array(A, (2, 3), "A")
        self.b = _finite_array(b, (2,), "b")
        c = cross(self.A[0], self.A[1])
        nc = float(np.sqrt(dot(c, c)))
        if nc == 0.0:
            raise ValueError("A must have rank 2 (its rows are parallel)")
        self.direction = _finite_array(c / nc, (3,), "direction")
        self._G = self.A.T @ np.linalg.inv(self.A @ self.A.T)  # (3, 2) right inverse
        self.image_shape = None

    @property
    def center(self) -> None:
        """An affine camera's centre is at infinity."""
        return None

    def project(self, X: Any) -> np.ndarray:
        X = _points(X)
        A, b = self.A, self.b
        x = A[0, 0] * X[..., 0] + A[0, 1] * X[..., 1] + A[0, 2] * X[..., 2] + b[0]
        y = A[1, 0] * X[..., 0] + A[1, 1] * X[..., 1] + A[1, 2] * X[..., 2] + b[1]
        return np.stack([x, y], axis=-1)

    def ray(self, xy: Any) -> tuple[np.ndarray, np.ndarray]:
        """(origin, unit direction) of the ray through each image point, each (..., 3)."""
        xy = _image_points(xy)
        G = self._G
        dx = xy[..., 0] - self.b[0]
        dy = xy[..., 1] - self.b[1]
        origin = np.stack([G[k, 0] * dx + G[k, 1] * dy for k in range(3)], axis=-1)
        return origin, np.broadcast_to(self.direction, origin.shape).copy()

    def points(self, xy: Any, r: Any) -> np.ndarray:
        """3-D points at range ``r`` (...) along the rays through ``xy`` (..., 2)."""
        o, d = self.ray(xy)
        r = np.asarray(r, dtype=np.float64)
        return o + r[..., None] * d

    def to_camera(self, X: Any) -> np.ndarray:
        """Unit direction from each point to the camera (constant: ``-direction``)."""
        X = _points(X)
        return np.broadcast_to(-self.direction, X.shape).copy()

    def to_dict(self) -> dict:
        return {"kind": self.kind, "A": self.A.tolist(), "b": self.b.tolist()}

    def __repr__(self) -> str:
        return f"AffineCamera(A={self.A.tolist()}, b={self.b.tolist()})"


class ProjectiveCamera:
    """Finite projective camera ``x ~ P [X; 1]`` with ``P = [M | p4]`` (Hartley-Zisserman 6.1).

    Parameters
    ----------
    P : (3, 4)
        Projection matrix; ``M`` must be invertible.
    image_shape : (H, W) or None
        Size of the image this camera took, checked against a scene's image.

    Notes
    -----
    The centre is ``C = -M^-1 p4``; the ray through ``xy`` is ``C + r d`` with
    ``d = sign(det M) M^-1 (x, y, 1) / |.|`` (points in front of the camera, HZ 6.2.3),
    so range labels are distances from the camera centre (thesis 4.2.1, first
    parameterisation).
    """

    kind = "projective"

    def __init__(self, P: Any, image_shape: Any = None) -> None:
        self.P = _finite_array(P, (3, 4), "P")
        M = self.P[:, :3]
        det = float(np.linalg.det(M))
        if det == 0.0 or not np.isfinite(det) or abs(det) < 1e-12 * np.abs(M).max() ** 3:
            raise ValueError("P must be a finite camera: its left 3x3 block M must be invertible")
        self._Minv = np.linalg.inv(M) * np.sign(det)
        self._center = _finite_array(-np.linalg.solve(M, self.P[:, 3]), (3,), "center")
        if image_shape is not None:
            shp = tuple(int(s) for s in np.asarray(image_shape).reshape(-1))
            if len(shp) != 2 or min(shp) < 1:
                raise ValueError(f"image_shape must be (H, W) with H, W >= 1; got {image_shape!r}")
            image_shape = shp
        self.image_shape = image_shape

    @property
    def center(self) -> np.ndarray:
        return self._center

    def project(self, X: Any) -> np.ndarray:
        X = _points(X)
        P = self.P
        h = [P[k, 0] * X[..., 0] + P[k, 1] * X[..., 1] + P[k, 2] * X[..., 2] + P[k, 3]
             for k in range(3)]
        return np.stack([h[0] / h[2], h[1] / h[2]], axis=-1)

    def ray(self, xy: Any) -> tuple[np.ndarray, np.ndarray]:
        xy = _image_points(xy)
        Mi = self._Minv
        d = np.stack([Mi[k, 0] * xy[..., 0] + Mi[k, 1] * xy[..., 1] + Mi[k, 2]
                      for k in range(3)], axis=-1)
        d = _unit(d)
        return np.broadcast_to(self._center, d.shape).copy(), d

    def points(self, xy: Any, r: Any) -> np.ndarray:
        o, d = self.ray(xy)
        r = np.asarray(r, dtype=np.float64)
        return o + r[..., None] * d

    def to_camera(self, X: Any) -> np.ndarray:
        return _unit(self._center - _points(X))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "P": self.P.tolist(),
                "image_shape": None if self.image_shape is None else list(self.image_shape)}

    def __repr__(self) -> str:
        return f"ProjectiveCamera(P={self.P.tolist()}, image_shape={self.image_shape})"


def camera_from_dict(d: dict) -> AffineCamera | ProjectiveCamera:
    """Inverse of ``camera.to_dict()``."""
    kind = d.get("kind")
    if kind == "affine":
        return AffineCamera(d["A"], d["b"])
    if kind == "projective":
        return ProjectiveCamera(d["P"], d.get("image_shape"))
    raise ValueError(f"camera kind must be 'affine' or 'projective'; got {kind!r}")


# ------------------------------------------------------------------------------- triangles
def triangle_normals(p0: Any, p1: Any, p2: Any, to_camera: Any) -> np.ndarray:
    """Unit normals of triangles (p0, p1, p2), each (..., 3), facing the camera (4.18).

    ``n = (p1 - p0) x (p2 - p0) / |.|``, flipped where ``n . to_camera < 0`` (the
    thesis requires the normal to point towards the camera). Degenerate
    (zero-area) triangles give a zero vector, which every BRDF maps to 0.
    """
    p0, p1, p2 = _points(p0, "p0"), _points(p1, "p1"), _points(p2, "p2")
    c = cross(p1 - p0, p2 - p0)
    nn = np.sqrt(dot(c, c))
    ok = nn > 0
    n = c / np.where(ok, nn, 1.0)[..., None]
    flip = dot(n, np.asarray(to_camera, dtype=np.float64)) < 0
    return np.where(flip[..., None], -n, n)


def triangulate_linear(P1: Any, P2: Any, x1: Any, x2: Any) -> np.ndarray:
    """Linear (DLT) two-view triangulation, thesis 6.52-6.53 (Hartley-Zisserman 12.2).

    Stacks ``x p3^T - p1^T``, ``y p3^T - p2^T`` for both cameras into ``A`` (4x4)
    and takes the right singular vector of the smallest singular value.

    Parameters
    ----------
    P1, P2 : (3, 4)
    x1, x2 : (..., 2)
        Corresponding image points.

    Returns
    -------
    ndarray (..., 3)
        World points (homogeneous coordinate divided out).
    """
    P1 = _finite_array(P1, (3, 4), "P1")
    P2 = _finite_array(P2, (3, 4), "P2")
    x1, x2 = _image_points(x1, "x1"), _image_points(x2, "x2")
    if x1.shape != x2.shape:
        raise ValueError(f"x1 and x2 must have the same shape; got {x1.shape} and {x2.shape}")
    rows = [
        x1[..., 0, None] * P1[2] - P1[0],
        x1[..., 1, None] * P1[2] - P1[1],
        x2[..., 0, None] * P2[2] - P2[0],
        x2[..., 1, None] * P2[2] - P2[1],
    ]
    A = np.stack(rows, axis=-2)  # 6.53, unscaled (as cv2.triangulatePoints)
    Z = np.linalg.svd(A)[2][..., -1, :]
    return Z[..., :3] / Z[..., 3:4]
