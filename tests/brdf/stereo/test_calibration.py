"""Calibration and rectification on a chessboard rendered through known cameras."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from mrfpe.brdf.stereo import calibration as cal  # noqa: E402

PATTERN = (9, 6)   # inner corners (columns, rows)
SIZE = (320, 240)  # (W, H)
K1 = np.array([[310.0, 0, 158.0], [0, 305.0, 121.0], [0, 0, 1]])
K2 = np.array([[300.0, 0, 163.0], [0, 298.0, 118.0], [0, 0, 1]])
D1 = np.array([-0.08, 0.02, 0.0, 0.0, 0.0])
D2 = np.array([-0.05, 0.0, 0.0, 0.0, 0.0])
R_TRUE = cv2.Rodrigues(np.array([0.01, -0.06, 0.02]))[0]   # X2 = R X1 + T
T_TRUE = np.array([-4.0, 0.15, 0.3])                       # baseline 4 squares


def _rays(K, D, ss=4):
    """Unit-depth ray directions (H, W, ss*ss, 3) of sub-pixel samples (camera frame)."""
    W, H = SIZE
    off = (np.arange(ss) + 0.5) / ss - 0.5
    u = np.arange(W)[None, :, None, None] + off[None, None, None, :]
    v = np.arange(H)[:, None, None, None] + off[None, None, :, None]
    uu, vv = np.broadcast_arrays(u, v)
    pts = np.stack([uu, vv], -1).reshape(-1, 1, 2).astype(np.float64)
    n = cv2.undistortPoints(pts, K, D).reshape(H, W, ss * ss, 2)
    return np.concatenate([n, np.ones((*n.shape[:-1], 1))], -1)


def _render(C, d, Rb, tb):
    """Chessboard seen along rays ``C + s d`` (world = camera-1 frame); board pose X = Rb b + tb."""
    n = Rb[:, 2]
    s = ((tb - C) @ n) / (d @ n)
    X = C + s[..., None] * d
    b = (X - tb) @ Rb            # board coordinates
    u, v = b[..., 0], b[..., 1]
    black = (np.floor(u).astype(int) + np.floor(v).astype(int)) % 2 == 0
    inside = (u >= -1) & (u < PATTERN[0]) & (v >= -1) & (v < PATTERN[1])
    margin = (u >= -2.0) & (u < PATTERN[0] + 1.0) & (v >= -2.0) & (v < PATTERN[1] + 1.0)
    val = np.where(inside & black, 0.05, np.where(margin, 0.95, 0.4))
    return np.clip(np.rint(val.mean(-1) * 255), 0, 255).astype(np.uint8)


def _poses():
    rng = np.random.default_rng(3)
    out = []
    for _ in range(9):
        Rb = cv2.Rodrigues(rng.uniform(-0.35, 0.35, 3))[0]
        centre = np.array([(PATTERN[0] - 1) / 2, (PATTERN[1] - 1) / 2, 0.0])
        tb = np.array([rng.uniform(0.5, 3.5), rng.uniform(-1.5, 1.5), rng.uniform(17, 22)]) \
            - Rb @ centre
        out.append((Rb, tb))
    return out


@pytest.fixture(scope="module")
def views():
    d1 = _rays(K1, D1)
    d2 = _rays(K2, D2) @ R_TRUE          # camera-2 rays in camera-1 frame: R^T d
    C2 = -R_TRUE.T @ T_TRUE
    poses = _poses()
    left = [_render(np.zeros(3), d1, *p) for p in poses]
    right = [_render(C2, d2, *p) for p in poses]
    return left, right, poses


@pytest.fixture(scope="module")
def calib(views):
    left, right, _ = views
    return cal.calibrate_from_images(left, right, PATTERN, square_size=1.0)


def test_corners_detected_in_canonical_order(views):
    left, _right, poses = views
    for img, (Rb, tb) in zip(left[:3], poses[:3], strict=True):
        pts = cal.find_chessboard(img, PATTERN)
        assert pts is not None and pts.shape == (PATTERN[0] * PATTERN[1], 2)
        X = cal.chessboard_points(PATTERN) @ Rb.T + tb
        proj = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K1, D1)[0].reshape(-1, 2)
        # same order as the board points (canonical order picks the right end)
        assert np.abs(pts - proj).max() < 0.3


def test_calibration_recovers_cameras(calib):
    assert calib.rms < 0.2
    np.testing.assert_allclose(calib.K1, K1, atol=2.0)
    np.testing.assert_allclose(calib.K2, K2, atol=2.0)
    np.testing.assert_allclose(calib.T, T_TRUE, atol=0.04 * np.linalg.norm(T_TRUE))
    dR = cv2.Rodrigues(calib.R @ R_TRUE.T)[0]
    assert np.degrees(np.linalg.norm(dR)) < 0.5  # correlates with the principal-point error
    # distortion is checked through its effect: rectified rows and triangulation below


def test_rectification_aligns_rows_and_triangulates(views, calib):
    left, right, poses = views
    rect = cal.stereo_rectify(calib)
    Pl, Pr = rect.projection_matrices(convention="opencv")
    errs, dys = [], []
    for k in range(len(poses)):
        a, b = cal.rectify_pair(left[k], right[k], rect)
        pa, pb = cal.find_chessboard(a, PATTERN), cal.find_chessboard(b, PATTERN)
        if pa is None or pb is None:  # the board may leave the rectified (cropped) view
            continue
        dys.append(np.abs(pa[:, 1] - pb[:, 1]))
        assert np.all(pa[:, 0] - pb[:, 0] > 0)          # positive disparities
        Xh = cv2.triangulatePoints(Pl, Pr, pa.T.astype(np.float64), pb.T.astype(np.float64))
        X = (Xh[:3] / Xh[3]).T
        Rb, tb = poses[k]
        truth = cal.chessboard_points(PATTERN) @ Rb.T + tb
        errs.append(np.linalg.norm(X - truth, axis=1) / np.linalg.norm(truth, axis=1))
    assert len(dys) >= 4
    assert np.mean(np.concatenate(dys)) < 0.15 and np.max(np.concatenate(dys)) < 0.5
    assert np.median(np.concatenate(errs)) < 0.01


def test_lattice_convention_shifts_half_pixel(calib):
    rect = cal.stereo_rectify(calib)
    P_cv = rect.projection_matrices("opencv")[0]
    P_lat = rect.projection_matrices("lattice")[0]
    X = np.array([[0.5, -1.0, 20.0, 1.0], [3.0, 2.0, 15.0, 1.0]]).T
    a, b = P_cv @ X, P_lat @ X
    np.testing.assert_allclose(b[:2] / b[2], a[:2] / a[2] + 0.5, atol=1e-9)


def test_bad_input():
    with pytest.raises(ValueError, match="pattern_size"):
        cal.chessboard_points((1, 5))
    with pytest.raises(ValueError, match="square_size"):
        cal.chessboard_points((3, 3), square_size=0)
    with pytest.raises(ValueError, match="object_points"):
        cal.calibrate_stereo([np.zeros((4, 3))], [np.zeros((4, 2))], [np.zeros((4, 2))], (10, 10))
    with pytest.raises(ValueError, match="left_images"):
        cal.calibrate_from_images([np.zeros((5, 5))], [], (3, 3))
    with pytest.raises(ValueError, match="P must"):
        cal.to_lattice_convention(np.eye(3))
    blank = np.full((60, 80), 200, np.uint8)
    assert cal.find_chessboard(blank, (4, 3)) is None
    with pytest.raises(ValueError, match="found in only 0"):
        cal.calibrate_from_images([blank] * 3, [blank] * 3, (4, 3))
