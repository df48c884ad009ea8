"""Stereo calibration and rectification: thin wrappers around OpenCV (thesis 6.1 steps 1, 4, 5).

The thesis calibrates with Zhang's method [140] and rectifies with [55]/[36];
OpenCV implements the same methods: :func:`find_chessboard`
(``cv2.findChessboardCorners`` + ``cv2.cornerSubPix``), :func:`calibrate_stereo`
(``cv2.calibrateCamera`` per camera, then ``cv2.stereoCalibrate``),
:func:`stereo_rectify` (``cv2.stereoRectify`` + ``cv2.initUndistortRectifyMap``)
and :func:`rectify_pair` (``cv2.remap``).

Pixel conventions. OpenCV puts pixel *centres* at integer coordinates;
mrfpe's lattice puts pixel *corners* there (node ``(r, c)`` at ``(x, y) =
(c, r)``, pixel ``(r, c)`` covering ``[c, c+1] x [r, r+1]``, so its centre is
at ``(c + 1/2, r + 1/2)``). :func:`to_lattice_convention` converts a projection
matrix: ``P_mrfpe = [[1, 0, 1/2], [0, 1, 1/2], [0, 0, 1]] P_opencv``.

World frame. ``cv2.stereoRectify``'s ``P1, P2`` map points given in the
*rectified* first-camera frame; :meth:`Rectification.projection_matrices`
returns them for points in the original first-camera frame (the frame of
``R, T`` and of any light direction measured with the calibration), i.e.
``P_i diag(R1, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "Rectification",
    "StereoCalibration",
    "calibrate_from_images",
    "calibrate_stereo",
    "chessboard_points",
    "find_chessboard",
    "rectify_pair",
    "stereo_rectify",
    "to_lattice_convention",
]


def _pattern(pattern_size: Any) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in pattern_size)
    except (TypeError, ValueError):
        raise ValueError(f"pattern_size must be (columns, rows) of inner corners; "
                         f"got {pattern_size!r}") from None
    if cols < 2 or rows < 2:
        raise ValueError("pattern_size must have >= 2 inner corners each way; "
                         f"got {pattern_size!r}")
    return cols, rows


def _grey_u8(image: Any, name: str = "image") -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = img[:, :, :3].mean(axis=2)
    if img.ndim != 2:
        raise ValueError(f"{name} must be (H, W) or (H, W, 3); got shape {np.shape(image)}")
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    img = np.asarray(img, dtype=np.float64)
    if not np.all(np.isfinite(img)):
        raise ValueError(f"{name} contains NaN or inf")
    scale = 255.0 if img.max() <= 1.0 else 1.0
    return np.clip(np.rint(img * scale), 0, 255).astype(np.uint8)


def chessboard_points(pattern_size: Any, square_size: float = 1.0) -> np.ndarray:
    """3-D inner-corner positions on the board plane ``z = 0``, row by row, (N, 3) float32."""
    cols, rows = _pattern(pattern_size)
    if not float(square_size) > 0:
        raise ValueError(f"square_size must be > 0; got {square_size!r}")
    g = np.zeros((rows * cols, 3), np.float32)
    g[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * float(square_size)
    return g


def find_chessboard(image: Any, pattern_size: Any, *, refine: bool = True) -> np.ndarray | None:
    """Inner chessboard corners in OpenCV pixel coordinates, (N, 2) float32, or None.

    The corners come row by row; the order is made canonical (first corner
    nearer the image's top-left than the last) so that both views of a stereo
    pair list the corners in the same order.
    """
    import cv2

    cols, rows = _pattern(pattern_size)
    grey = _grey_u8(image)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(grey, (cols, rows), flags=flags)
    if not ok:
        return None
    if refine:
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        corners = cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), crit)
    pts = corners.reshape(-1, 2).astype(np.float32)
    if pts[0].sum() > pts[-1].sum():
        pts = pts[::-1].copy()
    return pts


@dataclass
class StereoCalibration:
    """Intrinsics ``K1, K2`` (3x3), distortion ``D1, D2``, pose of camera 2 in camera 1's
    frame (``X_2 = R X_1 + T``), essential ``E`` and fundamental ``F`` matrices,
    ``image_size`` (W, H) and the RMS reprojection error ``rms`` (pixels)."""

    K1: np.ndarray
    D1: np.ndarray
    K2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    image_size: tuple[int, int]
    rms: float


def calibrate_stereo(object_points: Any, left_points: Any, right_points: Any,
                     image_size: Any, *, flags: int | None = None) -> StereoCalibration:
    """Calibrate a stereo pair from corresponding board views (Zhang [140] via OpenCV).

    Parameters
    ----------
    object_points : list of (N, 3)
        Board points of each view (e.g. :func:`chessboard_points`).
    left_points, right_points : list of (N, 2)
        Detected image points in each view (OpenCV pixel coordinates).
    image_size : (W, H)
    flags : int or None
        ``cv2.stereoCalibrate`` flags; default ``CALIB_USE_INTRINSIC_GUESS``
        (joint refinement starting from the single-camera calibrations).
    """
    import cv2

    n = len(object_points)
    if n < 3 or len(left_points) != n or len(right_points) != n:
        raise ValueError("object_points, left_points and right_points must be lists of the same "
                         f"length >= 3; got {n}, {len(left_points)}, {len(right_points)}")
    try:
        W, H = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ValueError(f"image_size must be (W, H); got {image_size!r}") from None
    obj = [np.asarray(o, np.float32).reshape(-1, 1, 3) for o in object_points]
    lp = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in left_points]
    rp = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in right_points]
    for k, (o, a, b) in enumerate(zip(obj, lp, rp, strict=True)):
        if not (len(o) == len(a) == len(b)):
            raise ValueError(f"view {k}: object, left and right point counts differ "
                             f"({len(o)}, {len(a)}, {len(b)})")
    _, K1, D1, _, _ = cv2.calibrateCamera(obj, lp, (W, H), None, None)
    _, K2, D2, _, _ = cv2.calibrateCamera(obj, rp, (W, H), None, None)
    flags = cv2.CALIB_USE_INTRINSIC_GUESS if flags is None else int(flags)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-9)
    rms, K1, D1, K2, D2, R, T, E, F = cv2.stereoCalibrate(
        obj, lp, rp, K1, D1, K2, D2, (W, H), flags=flags, criteria=crit)
    return StereoCalibration(K1=K1, D1=D1.ravel(), K2=K2, D2=D2.ravel(), R=R, T=T.ravel(), E=E,
                             F=F, image_size=(W, H), rms=float(rms))


def calibrate_from_images(left_images: Any, right_images: Any, pattern_size: Any,
                          square_size: float = 1.0) -> StereoCalibration:
    """Detect a chessboard in every image pair and calibrate (pairs where either view fails
    are skipped; at least 3 must remain)."""
    if len(left_images) != len(right_images):
        raise ValueError("left_images and right_images must have the same length; got "
                         f"{len(left_images)} and {len(right_images)}")
    obj, lp, rp, size = [], [], [], None
    board = chessboard_points(pattern_size, square_size)
    for a, b in zip(left_images, right_images, strict=True):
        shape = np.shape(a)[:2]
        if np.shape(b)[:2] != shape or (size is not None and size != shape[::-1]):
            raise ValueError("all calibration images must have the same size")
        size = shape[::-1]
        pa, pb = find_chessboard(a, pattern_size), find_chessboard(b, pattern_size)
        if pa is not None and pb is not None:
            obj.append(board)
            lp.append(pa)
            rp.append(pb)
    if len(obj) < 3:
        raise ValueError(f"the chessboard was found in only {len(obj)} image pairs; need >= 3")
    return calibrate_stereo(obj, lp, rp, size)


@dataclass
class Rectification:
    """Output of :func:`stereo_rectify`: rectifying rotations ``R1, R2``, rectified
    projection matrices ``P1, P2`` (OpenCV convention, rectified camera-1 frame),
    disparity-to-depth ``Q``, valid regions ``roi1, roi2`` and ``remap`` tables."""

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    roi1: tuple[int, int, int, int]
    roi2: tuple[int, int, int, int]
    maps1: tuple[np.ndarray, np.ndarray]
    maps2: tuple[np.ndarray, np.ndarray]
    image_size: tuple[int, int]

    def projection_matrices(self, convention: str = "lattice") -> tuple[np.ndarray, np.ndarray]:
        """Rectified ``(P_left, P_right)`` for points in the original camera-1 frame.

        ``convention="lattice"`` (default) returns them in mrfpe's pixel-corner
        convention (:func:`to_lattice_convention`), ready for
        :func:`mrfpe.brdf.stereo.scene_from_stereo`; ``"opencv"`` keeps OpenCV's.
        """
        if convention not in ("lattice", "opencv"):
            raise ValueError(f"convention must be 'lattice' or 'opencv'; got {convention!r}")
        B = np.eye(4)
        B[:3, :3] = self.R1
        Ps = (self.P1 @ B, self.P2 @ B)
        if convention == "lattice":
            Ps = tuple(to_lattice_convention(P) for P in Ps)
        return Ps


def stereo_rectify(calib: StereoCalibration, *, alpha: float = 0.0,
                   zero_disparity: bool = True) -> Rectification:
    """``cv2.stereoRectify`` (Bouguet) + ``cv2.initUndistortRectifyMap`` for both cameras.

    ``alpha`` = 0 keeps only valid pixels, 1 keeps every source pixel.
    ``zero_disparity`` makes the principal points equal, so that the
    disparity of a point at infinity is 0 and all disparities are >= 0.
    """
    import cv2

    if not 0.0 <= float(alpha) <= 1.0:
        raise ValueError(f"alpha must be in [0, 1]; got {alpha!r}")
    size = tuple(int(v) for v in calib.image_size)
    R1, R2, P1, P2, Q, roi1, roi2 = cv2.stereoRectify(
        calib.K1, calib.D1, calib.K2, calib.D2, size, calib.R, calib.T.reshape(3, 1),
        flags=cv2.CALIB_ZERO_DISPARITY if zero_disparity else 0, alpha=float(alpha))
    maps1 = cv2.initUndistortRectifyMap(calib.K1, calib.D1, R1, P1, size, cv2.CV_32FC1)
    maps2 = cv2.initUndistortRectifyMap(calib.K2, calib.D2, R2, P2, size, cv2.CV_32FC1)
    return Rectification(R1=R1, R2=R2, P1=P1, P2=P2, Q=Q, roi1=tuple(roi1), roi2=tuple(roi2),
                         maps1=maps1, maps2=maps2, image_size=size)


def rectify_pair(left: Any, right: Any, rect: Rectification, *,
                 interpolation: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Warp an unrectified pair into the rectified pair (``cv2.remap``, linear by default)."""
    import cv2

    a, b = np.asarray(left), np.asarray(right)
    if a.shape[:2] != rect.image_size[::-1] or b.shape[:2] != rect.image_size[::-1]:
        raise ValueError(f"left and right must be {rect.image_size[::-1]} images (H, W); got "
                         f"{a.shape} and {b.shape}")
    interp = cv2.INTER_LINEAR if interpolation is None else interpolation
    out = tuple(cv2.remap(img, m[0], m[1], interp, borderMode=cv2.BORDER_CONSTANT)
                for img, m in ((a, rect.maps1), (b, rect.maps2)))
    return out[0], out[1]


def to_lattice_convention(P: Any) -> np.ndarray:
    """OpenCV projection matrix (pixel centres at integers) -> mrfpe's (corners at integers)."""
    P = np.asarray(P, dtype=np.float64)
    if P.shape != (3, 4):
        raise ValueError(f"P must be a (3, 4) projection matrix; got shape {P.shape}")
    S = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
    return S @ P
