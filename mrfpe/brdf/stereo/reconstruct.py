"""From disparity labels to 3-D points and a BRDF scene (thesis 6.4-6.5, 6.42-6.53, 6.60).

Working frame. The thesis runs BP on the rectified pair and maps each node
``i`` of the *unrectified* first image to its nearest rectified node ``r(i)``
(6.42-6.46). Here the rectified left image itself is the scene's image: a
rectified view is an exact perspective image taken by the camera ``P_left``
(same centre as the original camera, rotated image plane), so working in the
rectified frame needs no nearest-node rounding and ``r(i) = i``. For the
shading (white-light) image pass it rectified with the same maps
(:func:`mrfpe.brdf.stereo.rectify_pair`).

Triangulation (6.47-6.53). Node ``(r, c)`` sits at ``(x, y) = (c, r)`` (pixel
corners, :mod:`mrfpe.brdf.lattice`); with disparity label ``d`` its match in the
right image is ``(c - d, r)`` (6.49: ``Y^R2 = Y_b^R2 + [d 0 0]^T`` with the
opposite sign convention -- the thesis's ``d`` ranges over -20..20, ours is
the usual non-negative left-minus-right disparity). Every (node, label) pair
is triangulated with the linear method 6.52-6.53
(:func:`mrfpe.brdf.geometry.triangulate_linear`); the label's range is the
distance of that point from the left camera centre (thesis 4.2.1, first
parameterisation), so ``ProjectiveCamera(P_left).points(node, range)`` gives
the point back. The probability of the point is the belief of its label
(6.50-6.51).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.brdf.stereo.disparity import DisparityResult, disparity

__all__ = ["check_rectified", "label_points", "label_ranges", "scene_from_stereo"]


def _projection(P: Any, name: str) -> np.ndarray:
    arr = np.asarray(P, dtype=np.float64)
    if arr.shape != (3, 4) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite (3, 4) projection matrix; got shape "
                         f"{np.shape(P)}")
    det = abs(np.linalg.det(arr[:, :3]))
    if det == 0.0 or det < 1e-12 * np.abs(arr[:, :3]).max() ** 3:
        raise ValueError(f"{name} must be a finite camera (invertible left 3x3 block)")
    return arr


def _depth(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Depth of points in front of camera P (HZ 6.15: > 0 in front); NaN-safe."""
    P = np.asarray(P, dtype=np.float64)
    M = P[:, :3]
    with np.errstate(invalid="ignore", over="ignore"):
        w = X @ P[2, :3] + P[2, 3]
        return np.sign(np.linalg.det(M)) * w / np.linalg.norm(M[2])


def check_rectified(P_left: Any, P_right: Any, shape: tuple[int, int], tol: float = 1e-6) -> None:
    """Raise ValueError unless ``(P_left, P_right)`` is a rectified pair with ``x_r < x_l``.

    Rectified: every 3-D point in front of the left camera projects to the
    same row in both images. The pair must also have the right camera to the
    right (positive disparities), which is what the matcher assumes.
    """
    from mrfpe.brdf.geometry import ProjectiveCamera

    P1, P2 = _projection(P_left, "P_left"), _projection(P_right, "P_right")
    H, W = shape
    cam = ProjectiveCamera(P1)
    xy = np.array([[0.0, 0.0], [W, 0.0], [0.0, H], [W, H], [W / 2, H / 2]])
    C2 = ProjectiveCamera(P2).center
    scale = max(float(np.linalg.norm(C2 - cam.center)), 1e-12)
    X = cam.points(xy[:, None, :], np.array([2.0, 10.0, 100.0])[None, :] * scale)
    x1, x2 = cam.project(X), ProjectiveCamera(P2).project(X)
    err = np.abs(x1[..., 1] - x2[..., 1]).max()
    if not err <= tol * max(H, W, 1.0):
        raise ValueError(f"P_left and P_right must be a rectified pair (equal rows); a test "
                         f"point lands {err:.3g} px apart vertically")
    # disparity must grow as points come closer: right camera to the right
    d = x1[..., 0] - x2[..., 0]
    if not np.all(np.diff(d, axis=1) < 0):
        raise ValueError("P_right must be the right camera of the pair (disparity x_left - "
                         "x_right must fall with distance); swap the images and cameras")


def label_points(P_left: Any, P_right: Any, disparities: Any, shape: tuple[int, int]) -> np.ndarray:
    """Triangulated 3-D point of every corner-vertex node and disparity label (6.49, 6.52-6.53).

    Parameters
    ----------
    P_left, P_right : (3, 4)
        Rectified projection matrices (mrfpe pixel-corner convention, same world frame).
    disparities : (L,)
        Disparity of each label, pixels.
    shape : (H, W)
        Image size; the lattice has (H+1) x (W+1) nodes.

    Returns
    -------
    ndarray (H+1, W+1, L, 3)
    """
    from mrfpe.brdf.geometry import triangulate_linear

    P1, P2 = _projection(P_left, "P_left"), _projection(P_right, "P_right")
    H, W = (int(s) for s in shape)
    d = np.asarray(disparities, dtype=np.float64).reshape(-1)
    r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
    x1 = np.broadcast_to(np.stack([c, r], -1)[:, :, None, :], (H + 1, W + 1, d.size, 2))
    x2 = np.stack(np.broadcast_arrays(c[:, :, None] - d, r[:, :, None]), -1)
    with np.errstate(divide="ignore", invalid="ignore"):  # points at infinity -> inf, checked later
        return triangulate_linear(P1, P2, x1, x2)


def label_ranges(P_left: Any, points: np.ndarray) -> np.ndarray:
    """Distance of each point from the left camera centre (the scene's range labels)."""
    from mrfpe.brdf.geometry import ProjectiveCamera

    C = ProjectiveCamera(_projection(P_left, "P_left")).center
    return np.linalg.norm(np.asarray(points) - C, axis=-1)


def _shading_image(image: Any, name: str) -> np.ndarray:
    from mrfpe.brdf.stereo.match import as_image

    img = as_image(image, name)
    return img.mean(axis=2) if img.shape[2] > 1 else img[:, :, 0]


def _ranges_in_front(P_left: Any, P_right: Any, disp: np.ndarray,
                     shape: tuple[int, int]) -> np.ndarray:
    """Every (node, disparity label)'s range along the left camera's ray, (H+1, W+1, B);
    ValueError naming the labels whose points are not in front of both cameras at a
    finite range."""
    pts = label_points(P_left, P_right, disp, shape)
    with np.errstate(invalid="ignore", over="ignore"):
        ranges = label_ranges(P_left, pts)
    ok = np.isfinite(ranges) & (ranges > 0) & (_depth(P_left, pts) > 0) \
        & (_depth(P_right, pts) > 0)
    if not np.all(ok):
        bad = disp[~np.all(ok, axis=(0, 1))]
        raise ValueError(f"min_disparity must keep every label in front of the cameras; "
                         f"labels {bad[:5].tolist()} triangulate to infinity or behind them")
    return ranges


def scene_from_stereo(left: Any, right: Any, P_left: Any, P_right: Any, light: Any, *,
                      max_disparity: float, min_disparity: float = 1.0, step: float = 1.0,
                      brdf: str = "ward", image: Any = None, true_theta: Any = None,
                      noise_sigma: float = 0.0, tangent_ref: Any = (1.0, 0.0, 0.0),
                      result: DisparityResult | None = None, **disparity_options: Any):
    """A :class:`mrfpe.brdf.scene.Scene` from a rectified stereo pair (thesis 6.1 steps 6-7, 6.5).

    Runs :func:`mrfpe.brdf.stereo.disparity` on ``(left, right)`` (unless ``result``
    is given), triangulates every (node, disparity label) into a range along
    the left camera's ray, and returns a scene whose labels are the disparity
    labels, whose observed labelling is the MAP disparity (6.35) and whose
    ``beliefs`` are the BP beliefs, ready for ``mrfpe.targets.get("pl3", scene)``
    (``U^D = -T log b``, 6.60). The node match cost ``F = 1 - d`` (6.5) is
    attached as ``scene.match_cost`` for ``pl2``'s ``U^C`` (6.58); it is not
    part of the saved scene.

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3)
        Rectified stereo pair used for matching (e.g. under structured light,
        thesis 6.1 step 2).
    P_left, P_right : (3, 4)
        Rectified projection matrices in mrfpe's pixel-corner convention
        (:meth:`mrfpe.brdf.stereo.Rectification.projection_matrices`), in the
        world frame of ``light``.
    light : DirectionalLight or PointLight
    max_disparity, min_disparity, step : float
        Label set ``min, min + step, ..., max`` (pixels). ``min_disparity``
        must keep every label's point in front of both cameras at a finite
        range (disparity 0 is a point at infinity for a zero-disparity rig).
    brdf : str
        BRDF model of the scene.
    image : (H, W) or (H, W, 3), optional
        Shading image from the left camera (white light, 6.1 step 3); default
        ``left``. Colour is averaged to grey; uint8 is scaled to [0, 1].
    true_theta, noise_sigma, tangent_ref
        Passed to the Scene.
    result : DisparityResult, optional
        A precomputed :func:`disparity` result on this pair with these labels.
    **disparity_options
        Settings of :func:`mrfpe.brdf.stereo.disparity` (schedule, iterations, window, ...).

    Raises
    ------
    ValueError
        Mismatched shapes, cameras that are not a rectified pair, labels whose
        points are not in front of the cameras, or a bad disparity setting.
    """
    from mrfpe.brdf.geometry import ProjectiveCamera
    from mrfpe.brdf.scene import Scene
    from mrfpe.brdf.stereo.match import as_image

    L_img = as_image(left, "left")
    H, W = L_img.shape[:2]
    check_rectified(P_left, P_right, (H, W))
    shade = _shading_image(left if image is None else image, "image")
    if shade.shape != (H, W):
        raise ValueError(f"image must have the stereo pair's size {(H, W)}; got {shade.shape}")
    if result is None:
        result = disparity(left, right, max_disparity, min_disparity=min_disparity, step=step,
                           **disparity_options)
    elif not isinstance(result, DisparityResult) or result.map.shape != (H + 1, W + 1):
        raise ValueError(f"result must be a DisparityResult for a {(H, W)} image pair")
    disp = result.disparities
    cam = ProjectiveCamera(P_left, image_shape=(H, W))
    ranges = _ranges_in_front(P_left, P_right, disp, (H, W))
    settings = dict(result.settings)
    meta = {"generator": "mrfpe.brdf.stereo.scene_from_stereo", "stereo": settings,
            "disparities": disp.tolist(), "bp_energy": result.energy.tolist(),
            "P_right": np.asarray(P_right, dtype=float).tolist()}
    scene = Scene(image=shade, camera=cam, light=light, label_ranges=ranges,
                  observed_labels=result.labels, brdf=brdf, true_theta=true_theta,
                  beliefs=result.beliefs, tangent_ref=tangent_ref, noise_sigma=noise_sigma,
                  meta=meta)
    # pl2's match energy U^C (6.58) reads F = 1 - d (6.5) from this attribute (not saved
    # with the scene: pass match_cost=... to pl2 after a reload)
    scene.match_cost = 1.0 - result.measure
    return scene
