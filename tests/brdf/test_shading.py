"""Triangle shading and the renderer / data-term agreement."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import brdf
from mrfpe.brdf import synthetic
from mrfpe.brdf.geometry import AffineCamera, DirectionalLight, PointLight, ProjectiveCamera
from mrfpe.brdf.shading import (
    pixel_intensity,
    radiance,
    radiance_from_features,
    shading_features,
    triangle_geometry,
)


def _plane_triangle(p, q, r0=10.0):
    cam = AffineCamera()
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    X = cam.points(xy, r0 + p * xy[:, 0] + q * xy[:, 1])
    return cam, X


def test_triangle_geometry_fields():
    cam, X = _plane_triangle(0.3, -0.5)
    light = DirectionalLight([0.2, 0.1, -1.0], irradiance=2.0)
    g = triangle_geometry(X[0], X[1], X[2], cam, light, tangent_ref=(1.0, 0.0, 0.0))
    n_ref = np.array([0.3, -0.5, -1.0]) / np.sqrt(0.09 + 0.25 + 1)
    np.testing.assert_allclose(g.n, n_ref)
    np.testing.assert_allclose(g.v, [0, 0, -1])
    np.testing.assert_allclose(g.l, light.direction)
    assert g.irradiance == 2.0
    assert abs(np.dot(g.t, g.n)) < 1e-14 and abs(np.linalg.norm(g.t) - 1) < 1e-14
    assert np.dot(g.t, [1.0, 0.0, 0.0]) > 0.9  # the projection of the reference


def test_tangent_fallback_when_reference_is_normal():
    cam, X = _plane_triangle(0.0, 0.0)
    g = triangle_geometry(X[0], X[1], X[2], cam, DirectionalLight([0, 0, -1]),
                          tangent_ref=(0.0, 0.0, 1.0))
    assert np.all(np.isfinite(g.t)) and abs(np.dot(g.t, g.n)) < 1e-14


def test_lambertian_plane_closed_form():
    # 4.17: L = rho_d / pi * I * (n . L)
    p, q = 0.4, 0.7
    cam, X = _plane_triangle(p, q)
    light = DirectionalLight([0.3, -0.2, -1.0], irradiance=1.7)
    g = triangle_geometry(X[0], X[1], X[2], cam, light)
    n = np.array([p, q, -1.0]) / np.sqrt(p * p + q * q + 1)
    expected = 0.6 / np.pi * 1.7 * np.dot(n, light.direction)
    np.testing.assert_allclose(radiance("lambertian", [0.6], g), [expected])


def test_radiance_is_brdf_times_irradiance_times_cosine():
    rng = np.random.default_rng(0)
    cam = ProjectiveCamera(np.hstack([np.diag([60.0, 60.0, 1.0]), np.zeros((3, 1))]))
    X = cam.points(rng.uniform(-5, 5, (20, 3, 2)), rng.uniform(40, 45, (20, 3)))
    light = PointLight([5.0, -30.0, 0.0], 900.0)
    g = triangle_geometry(X[:, 0], X[:, 1], X[:, 2], cam, light, (1.0, 1.0, 0.0))
    model = brdf.get("phong_aniso")
    theta = np.array([[0.3, 0.6, 10.0, 3.0], [0.9, 0.1, 1.0, 20.0]])
    expected = (model.evaluate(theta, g.n, g.l, g.v, g.t) * g.irradiance
                * np.maximum(np.sum(g.n * g.l, -1), 0))
    out = radiance(model, theta, g)
    np.testing.assert_allclose(out, expected, rtol=1e-14)
    feats, w = shading_features(model, g)
    np.testing.assert_array_equal(radiance_from_features("phong_aniso", theta, feats, w), out)
    centroid = X.mean(axis=1)
    np.testing.assert_allclose(g.irradiance, 900.0 / np.sum((light.position - centroid) ** 2, -1))


def test_shadowed_triangle_is_black():
    cam, X = _plane_triangle(0.0, 0.0)
    g = triangle_geometry(X[0], X[1], X[2], cam, DirectionalLight([0.0, 0.0, 1.0]))
    assert radiance("ward", [0.5, 0.5, 0.2], g)[0] == 0.0


def test_pixel_intensity_is_mean():
    a, b = np.array([1.0, 2.0]), np.array([3.0, 6.0])
    np.testing.assert_array_equal(pixel_intensity(a, b), [2.0, 4.0])


def test_bad_tangent_ref():
    cam, X = _plane_triangle(0.0, 0.0)
    with pytest.raises(ValueError, match="tangent_ref must be a finite non-zero"):
        triangle_geometry(X[0], X[1], X[2], cam, DirectionalLight([0, 0, -1]), (0, 0, 0))


def _data_term_at_labels(scene, theta, labels_override=None):
    """The recipe of docs/scene.md: per (node, label, triangle) geometry, as a target does.

    Returns the predicted intensity of every (node, label, pixel-touching-node) pair
    and the matching observed pixel ids.
    """
    L = scene.lattice
    n, B = L.n_nodes, scene.n_labels
    lp = scene.label_points().reshape(n, B, 3)
    obs = scene.observed_points().reshape(n, 3)
    indptr, tris = L.node_triangles
    node_of = np.repeat(np.arange(n), np.diff(indptr))  # (M,)
    V = L.triangles[tris]  # (M, 3) in lattice vertex order
    P = np.broadcast_to(obs[V][:, None], (len(V), B, 3, 3)).copy()
    is_i = V == node_of[:, None]
    mrow, mcol = np.nonzero(is_i)
    P[mrow, :, mcol, :] = lp[node_of[mrow]]
    g = triangle_geometry(P[..., 0, :], P[..., 1, :], P[..., 2, :], scene.camera,
                          scene.light, scene.tangent_ref)
    feats, w = shading_features(scene.brdf, g)
    rad = radiance_from_features(scene.brdf, theta, feats, w)[0]  # (M, B)
    # Label-independent radiance of every triangle at the observed labels.
    flat = obs
    tv = L.triangles
    g0 = triangle_geometry(flat[tv[:, 0]], flat[tv[:, 1]], flat[tv[:, 2]], scene.camera,
                           scene.light, scene.tangent_ref)
    rad_obs = radiance(scene.brdf, theta, g0)[0]
    # For each (node, pixel touching it): the two triangles' radiance under each label.
    pix_indptr, pix = L.node_pixels
    preds, pixels = [], []
    for i in range(n):
        mine = dict(zip(tris[indptr[i]:indptr[i + 1]], rad[indptr[i]:indptr[i + 1]]))
        for p in pix[pix_indptr[i]:pix_indptr[i + 1]]:
            a = mine.get(2 * p, np.full(B, rad_obs[2 * p]))
            b = mine.get(2 * p + 1, np.full(B, rad_obs[2 * p + 1]))
            preds.append(pixel_intensity(a, b))
            pixels.append(p)
    return np.array(preds), np.array(pixels), node_of


@pytest.mark.parametrize("case", ["ward_affine", "phong_jagged", "aniso_projective_point"])
def test_data_term_recipe_reproduces_renderer_bit_for_bit(case):
    if case == "ward_affine":
        scene = synthetic.make_scene("ward", [0.3, 0.6, 0.1], shape=(4, 5), n_labels=4, seed=1)
    elif case == "phong_jagged":
        scene = synthetic.make_scene("phong", [0.5, 0.4, 12.0], shape=(4, 5), n_labels=4,
                                     surface="jagged", seed=2)
    else:
        K = np.array([[40.0, 0.0, 2.5], [0.0, 40.0, 2.0], [0.0, 0.0, 1.0]])
        cam = ProjectiveCamera(np.hstack([K, np.zeros((3, 1))]), image_shape=(4, 5))
        scene = synthetic.make_scene("phong_aniso", [0.3, 0.6, 10.0, 3.0], shape=(4, 5),
                                     n_labels=4, seed=3, camera=cam,
                                     light=PointLight([10.0, -20.0, -5.0], 3000.0))
    theta = scene.true_theta[None]
    preds, pixels, _ = _data_term_at_labels(scene, theta)
    L = scene.lattice
    pix_indptr, _ = L.node_pixels
    node_for_pair = np.repeat(np.arange(L.n_nodes), np.diff(pix_indptr))
    true_lab = scene.observed_labels.reshape(-1)[node_for_pair]
    at_truth = preds[np.arange(len(preds)), true_lab]
    assert np.array_equal(at_truth, scene.image.reshape(-1)[pixels])
    # Other labels do predict something different (the data term is informative).
    other = (true_lab + 1) % scene.n_labels
    assert np.any(preds[np.arange(len(preds)), other] != at_truth)
