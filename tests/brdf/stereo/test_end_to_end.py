"""Stereo path end to end (thesis 6.1 steps 6-7): textured stereo pair + shading image ->
disparity beliefs -> stereo scene -> pl3 -> PMC -> Ward parameters near the truth.

The scene is a textured plane facing the cameras, seen through a rectified pair of
wide-angle projective cameras (the view direction varies by about +-27 degrees over the
image, which is what makes the Ward lobe identifiable on a plane) under one directional
light. The stereo pair shows the texture (the thesis's structured-light images), the
shading image is the Ward rendering from the left camera (its white-light image).

Why a plane facing the cameras: window matching is exact only there. On slanted or
curved surfaces, window NCC is biased by foreshortening by ~0.05 px (measured on
noise-free renderings, see docs/stereo.md), while recovering Ward parameters within
0.15 from pixel-sized triangles needs the disparities to ~0.01-0.02 px.
"""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe.brdf.geometry import DirectionalLight, ProjectiveCamera
from mrfpe.brdf.stereo import scene_from_stereo
from mrfpe.brdf.synthetic import render

H = W = 16
F = W / 2.0          # wide-angle: focal length half the image width
BASELINE = 4.0
DOFFS = 5.6          # principal-point offset of the right camera (as Middlebury's doffs)
D_TRUE = 0.0         # plane disparity x_left - x_right (labels -1.6, -1.4, ..., 1.6)
THETA = np.array([0.5, 0.3, 0.15])  # Ward (rho_d, rho_s, alpha), natural units


def _rig():
    K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])
    K2 = K.copy()
    K2[0, 2] += DOFFS  # disparity = F * BASELINE / Z - DOFFS: every left pixel stays in view
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K2 @ np.hstack([np.eye(3), [[-BASELINE], [0.0], [0.0]]])
    return P1, P2


def _texture(rng, n=12):
    """Smooth random texture on the plane, wavelengths 2.5-6 pixel footprints."""
    k = rng.normal(0, 1, (n, 2))
    k *= rng.uniform(2 * np.pi / 6, 2 * np.pi / 2.5, (n, 1)) / np.linalg.norm(k, axis=1)[:, None]
    phase = rng.uniform(0, 2 * np.pi, n)

    def tex(u, v):
        s = np.sin(u[..., None] * k[:, 0] + v[..., None] * k[:, 1] + phase).sum(-1)
        return 0.5 + 0.4 * np.tanh(s / np.sqrt(n))

    return tex


def _rays(P, xy):
    M = P[:, :3]
    C = -np.linalg.solve(M, P[:, 3])
    d = np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], -1) @ np.linalg.inv(M).T
    return C, d


def _hit(P, xy, Z):
    """Points where the rays through ``xy`` meet the plane z = Z."""
    C, d = _rays(P, xy)
    return C + ((Z - C[2]) / d[..., 2])[..., None] * d


def _render_texture(P, Z, tex, ss=5):
    """Each pixel = mean of ss x ss samples of the texture where their rays meet the plane."""
    off = (np.arange(ss) + 0.5) / ss
    x = np.arange(W)[None, :, None, None] + off[None, None, None, :]
    y = np.arange(H)[:, None, None, None] + off[None, None, :, None]
    xy = np.stack(np.broadcast_arrays(x, y), -1)
    X = _hit(P, xy, Z)
    scale = F / Z  # world -> pixel footprints on the plane
    return tex(X[..., 0] * scale, X[..., 1] * scale).mean(axis=(2, 3))


@pytest.fixture(scope="module")
def stereo_scene():
    P1, P2 = _rig()
    Z = F * BASELINE / (D_TRUE + DOFFS)
    tex = _texture(np.random.default_rng(7))
    left, right = _render_texture(P1, Z, tex), _render_texture(P2, Z, tex)
    r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
    nodes = _hit(P1, np.stack([c, r], -1), Z)
    light = DirectionalLight([0.2, -0.3, -1.0])
    shading = render("ward", THETA, nodes, ProjectiveCamera(P1), light)
    scene = scene_from_stereo(left, right, P1, P2, light, max_disparity=1.6, min_disparity=-1.6,
                              step=0.2, brdf="ward", image=shading, true_theta=THETA)
    return scene, nodes


def test_stereo_recovers_the_plane(stereo_scene):
    scene, nodes = stereo_scene
    d = np.asarray(scene.meta["disparities"])[scene.observed_labels]
    assert np.all(np.abs(d - D_TRUE) < 1e-9)
    np.testing.assert_allclose(scene.observed_points(), nodes, atol=1e-9)
    np.testing.assert_allclose(scene.beliefs.sum(axis=2), 1.0)


def test_pl3_pmc_recovers_ward_parameters(stereo_scene):
    scene, _ = stereo_scene
    target = mrfpe.targets.get("pl3", scene)
    post = mrfpe.sample("pmc", target, seed=0, n_samples=300, n_iterations=8)
    est = post["map_theta"].isel(step=-1).values
    truth = target.to_unit(THETA[None])[0]
    assert np.linalg.norm(est - truth) < 0.15
