"""Lights, cameras, normals and triangulation."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.geometry import (
    AffineCamera,
    DirectionalLight,
    PointLight,
    ProjectiveCamera,
    camera_from_dict,
    light_from_dict,
    triangle_normals,
    triangulate_linear,
)


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _projective(seed=0):
    K = np.array([[80.0, 0.5, 16.0], [0.0, 75.0, 12.0], [0.0, 0.0, 1.0]])
    R = _rotation(seed)
    t = np.array([0.3, -0.2, 1.0])
    return K @ np.hstack([R, t[:, None]])


def test_directional_light():
    light = DirectionalLight([0, 0, -2], irradiance=3.0)
    X = np.random.default_rng(0).normal(size=(4, 5, 3))
    assert np.array_equal(light.to_light(X), np.broadcast_to([0.0, 0.0, -1.0], X.shape))
    assert np.array_equal(light.irradiance(X), np.full((4, 5), 3.0))


def test_point_light_inverse_square():
    light = PointLight([1.0, 2.0, -3.0], intensity=8.0)
    X = np.array([[1.0, 2.0, -1.0], [1.0, 2.0, 1.0], [4.0, 6.0, -3.0]])
    np.testing.assert_allclose(light.irradiance(X), [8 / 4, 8 / 16, 8 / 25])
    np.testing.assert_allclose(light.to_light(X)[2], [-0.6, -0.8, 0.0])


def test_light_bad_input():
    with pytest.raises(ValueError, match="direction must be a non-zero"):
        DirectionalLight([0, 0, 0])
    with pytest.raises(ValueError, match="irradiance must be finite"):
        DirectionalLight([0, 0, -1], irradiance=-1)
    with pytest.raises(ValueError, match="position must have shape"):
        PointLight([0, 0])
    with pytest.raises(ValueError, match="direction must be finite"):
        DirectionalLight([0, np.nan, -1])


def test_default_affine_camera_is_orthographic_at_origin():
    cam = AffineCamera()
    xy = np.array([[0.0, 0.0], [3.0, 2.0], [7.5, -1.0]])
    r = np.array([1.0, 10.0, -2.0])
    X = cam.points(xy, r)
    assert np.array_equal(X, np.column_stack([xy, r]))
    assert np.array_equal(cam.project(X), xy)
    assert np.array_equal(cam.to_camera(X), np.broadcast_to([0.0, 0.0, -1.0], X.shape))


def test_general_affine_camera_rays():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(2, 3))
    b = rng.normal(size=2)
    cam = AffineCamera(A, b)
    xy = rng.normal(size=(6, 2)) * 10
    r = rng.normal(size=6) * 5
    X = cam.points(xy, r)
    np.testing.assert_allclose(cam.project(X), xy, atol=1e-10)
    o, d = cam.ray(xy)
    np.testing.assert_allclose(A @ d[0], 0, atol=1e-12)  # d spans the null space
    np.testing.assert_allclose(np.sum(o * d, -1), 0, atol=1e-10)  # origins on the plane
    np.testing.assert_allclose(np.sum((X - o) * d, -1), r, atol=1e-10)


def test_projective_camera_rays_and_ranges():
    P = _projective(2)
    cam = ProjectiveCamera(P)
    C = cam.center
    np.testing.assert_allclose(P @ np.append(C, 1.0), 0, atol=1e-9)
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 30, size=(10, 2))
    r = rng.uniform(1, 50, size=10)
    X = cam.points(xy, r)
    np.testing.assert_allclose(cam.project(X), xy, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(X - C, axis=-1), r)
    # In front of the camera: positive depth (Hartley-Zisserman 6.2.3).
    M = P[:, :3]
    w = (P @ np.column_stack([X, np.ones(10)]).T)[2]
    depth = np.sign(np.linalg.det(M)) * w / np.linalg.norm(M[2])
    assert np.all(depth > 0)
    np.testing.assert_allclose(cam.to_camera(X), (C - X) / r[:, None])


def test_projective_camera_sign_of_P_does_not_matter():
    P = _projective(4)
    xy = np.array([[5.0, 7.0]])
    a = ProjectiveCamera(P).points(xy, np.array([9.0]))
    b = ProjectiveCamera(-P).points(xy, np.array([9.0]))
    np.testing.assert_allclose(a, b)


def test_camera_bad_input():
    with pytest.raises(ValueError, match="P must have shape"):
        ProjectiveCamera(np.eye(3))
    with pytest.raises(ValueError, match="M must be invertible"):
        ProjectiveCamera(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="A must have rank 2"):
        AffineCamera([[1, 0, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match="image_shape must be"):
        ProjectiveCamera(_projective(), image_shape=(3,))
    with pytest.raises(ValueError, match="xy must have shape"):
        AffineCamera().ray(np.zeros((3, 3)))


def test_dict_round_trip_exact():
    for cam in (AffineCamera(), AffineCamera(np.random.default_rng(0).normal(size=(2, 3))),
                ProjectiveCamera(_projective(5), image_shape=(24, 32))):
        back = camera_from_dict(cam.to_dict())
        assert type(back) is type(cam)
        xy = np.array([[1.5, 2.25]])
        assert np.array_equal(back.points(xy, np.array([7.0])), cam.points(xy, np.array([7.0])))
    for light in (DirectionalLight([0.3, -0.1, -1.0], 2.5), PointLight([1, 2, 3], 7.0)):
        back = light_from_dict(light.to_dict())
        X = np.array([[0.1, 0.2, 0.3]])
        assert np.array_equal(back.to_light(X), light.to_light(X))
        assert np.array_equal(back.irradiance(X), light.irradiance(X))


def test_triangle_normals_face_camera_and_match_4_15():
    rng = np.random.default_rng(0)
    cam = AffineCamera()
    p, q = rng.normal(size=2)
    # Plane r = p x + q y + 5 seen by the default camera, triangle with either winding.
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    X = cam.points(xy, p * xy[:, 0] + q * xy[:, 1] + 5)
    expected = np.array([p, q, -1.0]) / np.sqrt(p * p + q * q + 1)  # 4.15 with u = -r
    v = cam.to_camera(X[0])
    np.testing.assert_allclose(triangle_normals(X[0], X[1], X[2], v), expected)
    np.testing.assert_allclose(triangle_normals(X[0], X[2], X[1], v), expected)


def test_triangle_normals_projective_face_camera():
    cam = ProjectiveCamera(_projective(6))
    rng = np.random.default_rng(7)
    xy = rng.uniform(0, 30, size=(50, 3, 2))
    X = cam.points(xy, rng.uniform(5, 10, size=(50, 3)))
    centroid = X.mean(axis=1)
    v = cam.to_camera(centroid)
    n = triangle_normals(X[:, 0], X[:, 1], X[:, 2], v)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1)
    assert np.all(np.sum(n * v, -1) > 0)
    ref = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])  # 4.18 up to sign
    np.testing.assert_allclose(np.abs(np.sum(n * ref, -1)), np.linalg.norm(ref, axis=-1))


def test_triangulate_linear_against_cv2():
    cv2 = pytest.importorskip("cv2")
    P1 = _projective(0)
    P2 = _projective(1)
    rng = np.random.default_rng(5)
    Z = rng.uniform(-1, 1, size=(40, 3)) + np.array([0.0, 0.0, 6.0])
    cam1, cam2 = ProjectiveCamera(P1), ProjectiveCamera(P2)
    x1 = cam1.project(Z) + rng.normal(scale=0.2, size=(40, 2))  # noisy: not an exact fit
    x2 = cam2.project(Z) + rng.normal(scale=0.2, size=(40, 2))
    ours = triangulate_linear(P1, P2, x1, x2)
    Xh = cv2.triangulatePoints(P1, P2, x1.T.copy(), x2.T.copy())
    theirs = (Xh[:3] / Xh[3]).T
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6)
    # Exact correspondences give the points back.
    exact = triangulate_linear(P1, P2, cam1.project(Z), cam2.project(Z))
    np.testing.assert_allclose(exact, Z, atol=1e-9)


def test_triangulate_batched_shape_and_bad_input():
    P1, P2 = _projective(0), _projective(1)
    Z = np.random.default_rng(0).uniform(-1, 1, size=(2, 3, 3)) + np.array([0.0, 0.0, 6.0])
    x1, x2 = ProjectiveCamera(P1).project(Z), ProjectiveCamera(P2).project(Z)
    np.testing.assert_allclose(triangulate_linear(P1, P2, x1, x2), Z, atol=1e-9)
    with pytest.raises(ValueError, match="x1 and x2 must have the same shape"):
        triangulate_linear(P1, P2, x1, x2[:1])
