"""Triangulation of (node, disparity label) pairs and the stereo scene."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from mrfpe.brdf.geometry import DirectionalLight, ProjectiveCamera  # noqa: E402
from mrfpe.brdf.stereo import (  # noqa: E402
    StereoCalibration,
    disparity,
    label_points,
    scene_from_stereo,
    stereo_rectify,
)
from mrfpe.brdf.stereo.reconstruct import check_rectified, label_ranges  # noqa: E402


def _rig(H=10, W=14, f=20.0, b=3.0, doffs=0.0):
    """Rectified pair in mrfpe's pixel-corner convention; world = left camera frame."""
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    K2 = K.copy()
    K2[0, 2] += doffs
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K2 @ np.hstack([np.eye(3), [[-b], [0.0], [0.0]]])
    return P1, P2


def test_label_points_reproject_and_match_opencv():
    H, W = 4, 5
    P1, P2 = _rig(H, W, doffs=-1.0)
    d = np.array([1.5, 2.0, 4.0, 7.25])
    X = label_points(P1, P2, d, (H, W))
    assert X.shape == (H + 1, W + 1, 4, 3)
    r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
    x1 = ProjectiveCamera(P1).project(X)
    x2 = ProjectiveCamera(P2).project(X)
    np.testing.assert_allclose(x1[..., 0], c[..., None] + 0 * d, atol=1e-9)
    np.testing.assert_allclose(x1[..., 1], r[..., None] + 0 * d, atol=1e-9)
    np.testing.assert_allclose(x2[..., 0], c[..., None] - d, atol=1e-9)
    # independent triangulation: OpenCV's DLT on the same correspondences
    a = np.stack(np.broadcast_arrays(c[..., None] + 0 * d, r[..., None] + 0 * d), -1)
    b = np.stack(np.broadcast_arrays(c[..., None] - d, r[..., None] + 0 * d), -1)
    Xh = cv2.triangulatePoints(P1, P2, a.reshape(-1, 2).T, b.reshape(-1, 2).T)
    np.testing.assert_allclose(X.reshape(-1, 3), (Xh[:3] / Xh[3]).T, rtol=1e-9, atol=1e-9)
    # ranges are distances from the left centre, and give the points back along the rays
    rg = label_ranges(P1, X)
    np.testing.assert_allclose(rg, np.linalg.norm(X, axis=-1))
    back = ProjectiveCamera(P1).points(np.stack([c, r], -1)[:, :, None, :], rg)
    np.testing.assert_allclose(back, X, atol=1e-9)
    # depth Z = f b / (d + doffs) for this rig: larger disparity, nearer point
    np.testing.assert_allclose(X[..., 2], 20.0 * 3.0 / (d - 1.0) + 0 * X[..., 2])


def test_calibrated_rig_rectified_frame_is_consistent():
    """stereo_rectify -> projection_matrices (lattice) -> label_points agree with the
    original cameras through the rectifying homography (6.42-6.43)."""
    K1 = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    K2 = np.array([[310.0, 0, 150], [0, 305, 125], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.02, -0.05, 0.01]))[0]
    T = np.array([-5.0, 0.2, 0.1])
    calib = StereoCalibration(K1=K1, D1=np.zeros(5), K2=K2, D2=np.zeros(5), R=R, T=T,
                              E=np.eye(3), F=np.eye(3), image_size=(320, 240), rms=0.0)
    rect = stereo_rectify(calib)
    Pl, Pr = rect.projection_matrices()
    check_rectified(Pl, Pr, (240, 320))
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-5, 5, 20), rng.uniform(-4, 4, 20), rng.uniform(30, 60, 20)])
    xl, xr = ProjectiveCamera(Pl).project(X), ProjectiveCamera(Pr).project(X)
    np.testing.assert_allclose(xl[:, 1], xr[:, 1], atol=1e-9)
    # original camera 1 (OpenCV convention) sees X where H1^-1 maps the rectified point
    orig = (K1 @ X.T).T
    orig = orig[:, :2] / orig[:, 2:]
    H1 = rect.P1[:, :3] @ rect.R1 @ np.linalg.inv(K1)       # rectifying homography
    y = np.column_stack([xl - 0.5, np.ones(20)]) @ np.linalg.inv(H1).T   # lattice -> OpenCV
    np.testing.assert_allclose(y[:, :2] / y[:, 2:], orig, atol=1e-8)
    # triangulating one node at its (exact) disparity returns the point
    node = np.array([[[xl[0, 0], xl[0, 1]]]])
    d = xl[0, 0] - xr[0, 0]
    P_node = _points_at(Pl, Pr, node, d)
    np.testing.assert_allclose(P_node, X[0], rtol=1e-9)


def _points_at(Pl, Pr, xy, d):
    from mrfpe.brdf.geometry import triangulate_linear

    return triangulate_linear(Pl, Pr, xy.reshape(-1, 2), xy.reshape(-1, 2) - [d, 0])[0]


def test_check_rectified_rejects_bad_pairs():
    P1, P2 = _rig()
    check_rectified(P1, P2, (10, 14))
    Rz = cv2.Rodrigues(np.array([0.0, 0.0, 0.05]))[0]
    bad = P2.copy()
    bad[:, :3] = P2[:, :3] @ Rz
    with pytest.raises(ValueError, match="rectified pair"):
        check_rectified(P1, bad, (10, 14))
    with pytest.raises(ValueError, match="right camera"):
        check_rectified(P2, P1, (10, 14))
    with pytest.raises(ValueError, match="P_left"):
        check_rectified(np.eye(3), P2, (10, 14))


def _dots(seed=0, H=10, W=14, d=4):
    rng = np.random.default_rng(seed)
    right = rng.random((H, W))
    left = np.concatenate([rng.random((H, d)), right[:, :-d]], axis=1)
    return left, right


def test_scene_from_stereo():
    P1, P2 = _rig()
    left, right = _dots()
    light = DirectionalLight([0.1, -0.2, -1.0])
    shade = np.random.default_rng(1).random((10, 14))
    sc = scene_from_stereo(left, right, P1, P2, light, max_disparity=6, min_disparity=2,
                           step=0.5, image=shade, brdf="ward", true_theta=[0.5, 0.3, 0.2])
    res = disparity(left, right, 6, min_disparity=2, step=0.5)
    assert sc.shape == (10, 14) and sc.n_labels == 9
    np.testing.assert_array_equal(sc.observed_labels, res.labels)
    np.testing.assert_allclose(sc.beliefs, res.beliefs)
    np.testing.assert_allclose(sc.beliefs.sum(axis=2), 1.0)
    np.testing.assert_allclose(sc.image, shade)
    assert isinstance(sc.camera, ProjectiveCamera)
    # ranges fall with disparity, and the scene's points are the triangulated ones
    assert np.all(np.diff(sc.label_ranges, axis=2) < 0)
    np.testing.assert_allclose(sc.label_points(),
                               label_points(P1, P2, res.disparities, (10, 14)), atol=1e-9)
    np.testing.assert_allclose(sc.observed_points()[5, 7, 2], 20 * 3 / 4.0, rtol=1e-9)
    assert sc.meta["stereo"]["step"] == 0.5
    np.testing.assert_allclose(sc.match_cost, 1.0 - res.measure)
    assert np.all((sc.match_cost >= 0) & (sc.match_cost <= 1))
    # a precomputed result gives the same scene; uint8 colour shading is averaged to grey
    rgb = np.dstack([np.full((10, 14), 51, np.uint8)] * 3)
    sc2 = scene_from_stereo(left, right, P1, P2, light, max_disparity=6, min_disparity=2,
                            step=0.5, result=res, image=rgb)
    np.testing.assert_array_equal(sc2.observed_labels, sc.observed_labels)
    np.testing.assert_allclose(sc2.image, 0.2)


def test_scene_from_stereo_bad_input():
    P1, P2 = _rig()
    left, right = _dots()
    light = DirectionalLight([0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match="min_disparity must keep"):
        scene_from_stereo(left, right, P1, P2, light, max_disparity=6, min_disparity=0)
    with pytest.raises(ValueError, match="image must have"):
        scene_from_stereo(left, right, P1, P2, light, max_disparity=6, image=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="P_right"):
        scene_from_stereo(left, right, P1, np.zeros((3, 4)), light, max_disparity=6)
    with pytest.raises(ValueError, match="result"):
        scene_from_stereo(left, right, P1, P2, light, max_disparity=6, result="x")
    with pytest.raises(ValueError, match="light"):
        scene_from_stereo(left, right, P1, P2, "sun", max_disparity=6, min_disparity=2)
