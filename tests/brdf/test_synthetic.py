"""Synthetic scenes (thesis 7.2, Appendix C)."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf import synthetic
from mrfpe.brdf.geometry import DirectionalLight, PointLight, ProjectiveCamera
from mrfpe.brdf.scene import Scene

SMALL = dict(shape=(6, 7), n_labels=8)


def _ward(**kw):
    args = dict(brdf="ward", theta=[0.7, 0.4, 0.45], **SMALL)
    args.update(kw)
    return synthetic.make_scene(**args)


def _equal_scenes(a: Scene, b: Scene) -> bool:
    return (np.array_equal(a.image, b.image) and np.array_equal(a.label_ranges, b.label_ranges)
            and np.array_equal(a.observed_labels, b.observed_labels)
            and np.array_equal(a.range_prior, b.range_prior)
            and a.light.to_dict() == b.light.to_dict())


def test_reproducible_by_seed():
    assert _equal_scenes(_ward(seed=5, noise=0.01), _ward(seed=5, noise=0.01))
    assert not _equal_scenes(_ward(seed=5), _ward(seed=6))


def test_true_labels_render_the_image_exactly():
    for s in (_ward(seed=1), synthetic.make_scene("phong", [0.4, 0.5, 15.0], surface="jagged",
                                                  seed=2, **SMALL)):
        img = synthetic.render(s.brdf, s.true_theta, s.observed_points(), s.camera, s.light,
                               s.tangent_ref)
        assert np.array_equal(img, s.image)
        assert np.all(np.isfinite(s.image)) and s.image.max() > 0


def test_render_batch_matches_single():
    s = _ward(seed=3)
    thetas = np.array([[0.7, 0.4, 0.45], [0.2, 0.8, 0.1]])
    batch = synthetic.render("ward", thetas, s.observed_points(), s.camera, s.light)
    assert batch.shape == (2, *s.shape)
    assert np.array_equal(batch[0], s.image)
    assert not np.allclose(batch[1], s.image)


def test_labels_and_range_prior_follow_7_2_to_7_4():
    B = 10
    s = _ward(seed=4, n_labels=B)
    lr, t = s.label_ranges, s.observed_labels
    np.testing.assert_allclose(np.diff(lr, axis=2), 0.3)  # 0.3 pixel widths per label
    z = np.take_along_axis(lr, t[..., None], axis=2)[..., 0]
    k = np.arange(B)
    np.testing.assert_allclose(lr, z[..., None] + (k - t[..., None]) * 0.3, atol=1e-12)
    # psi = |z - r(x)| / sigma with sigma = B/5 labels (7.4): |k - t| / (B/5) in label units.
    np.testing.assert_allclose(s.range_prior, np.abs(k - t[..., None]) / (B / 5), atol=1e-9)
    assert np.array_equal(np.argmin(s.range_prior, axis=2), t)
    # The true index varies from node to node by default.
    assert len(np.unique(t)) > 1
    assert s.true_theta.tolist() == [0.7, 0.4, 0.45]


def test_true_label_options():
    s = _ward(true_label="centre")
    assert np.all(s.observed_labels == SMALL["n_labels"] // 2)
    s = _ward(true_label=3)
    assert np.all(s.observed_labels == 3)
    tl = np.random.default_rng(0).integers(0, SMALL["n_labels"], (7, 8))
    assert np.array_equal(_ward(true_label=tl).observed_labels, tl)
    with pytest.raises(ValueError, match="true_label must lie in"):
        _ward(true_label=SMALL["n_labels"])
    with pytest.raises(ValueError, match="true_label must be"):
        _ward(true_label="middle")


def test_prior_sigma_option():
    s = _ward(prior_sigma=2.0, seed=1)
    t = s.observed_labels
    k = np.arange(SMALL["n_labels"])
    np.testing.assert_allclose(s.range_prior, np.abs(k - t[..., None]) / 2.0, atol=1e-9)


def test_smooth_surface_is_the_appendix_c_thin_plate_spline():
    """Compare with C.2-C.6 solved directly (E(r) = r^2 ln r^2)."""
    H, W = 6, 7
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    got = synthetic.surface_ranges((H, W), "smooth", rng_a, n_control_points=20)
    ctrl = rng_b.uniform(0.0, 1.0, (20, 3)) * np.array([W, H, W])
    xy, z = ctrl[:, :2], ctrl[:, 2]

    def E(r):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(r > 0, r**2 * np.log(r**2), 0.0)

    A = E(np.linalg.norm(xy[:, None] - xy[None], axis=-1))
    Bm = np.column_stack([np.ones(20), xy])
    Ai = np.linalg.inv(A)
    b = np.linalg.solve(Bm.T @ Ai @ Bm, Bm.T @ Ai @ z)  # C.6
    a = Ai @ (z - Bm @ b)
    r, c = np.meshgrid(np.arange(H + 1.0), np.arange(W + 1.0), indexing="ij")
    q = np.stack([c.ravel(), r.ravel()], 1)
    ref = E(np.linalg.norm(q[:, None] - xy[None], axis=-1)) @ a + b[0] + q @ b[1:]
    np.testing.assert_allclose(got.ravel(), ref, rtol=1e-6, atol=1e-6)
    # Heights of the control points span the cube (up to the image width).
    assert np.all((z >= 0) & (z <= W))


def test_jagged_surface_range():
    f = synthetic.surface_ranges((5, 5), "jagged", np.random.default_rng(0))
    assert f.shape == (6, 6) and f.min() >= 0 and f.max() <= 6
    s = synthetic.make_scene("phong", [0.4, 0.5, 15.0], surface="jagged", seed=0, **SMALL)
    z = np.take_along_axis(s.label_ranges, s.observed_labels[..., None], 2)[..., 0]
    assert np.ptp(z) <= 6


def test_default_light_within_cone_of_camera():
    for seed in range(5):
        s = _ward(seed=seed)
        assert isinstance(s.light, DirectionalLight)
        cos = np.dot(s.light.direction, [0.0, 0.0, -1.0])
        assert cos >= np.cos(np.deg2rad(synthetic.LIGHT_CONE_DEG)) - 1e-12


def test_noise_is_added():
    clean = _ward(seed=2, shape=(30, 30))
    noisy = _ward(seed=2, shape=(30, 30), noise=0.05)
    diff = noisy.image - clean.image
    assert 0.04 < diff.std() < 0.06 and noisy.noise_sigma == 0.05


def test_projective_camera_scene():
    K = np.array([[60.0, 0.0, 3.5], [0.0, 60.0, 3.0], [0.0, 0.0, 1.0]])
    cam = ProjectiveCamera(np.hstack([K, np.zeros((3, 1))]), image_shape=(6, 7))
    s = synthetic.make_scene("ward_aniso", [0.3, 0.6, 0.1, 0.3], camera=cam,
                             light=PointLight([0.0, -50.0, 0.0], 5000.0), seed=1, **SMALL)
    assert np.all(s.label_ranges > 0)
    img = synthetic.render(s.brdf, s.true_theta, s.observed_points(), cam, s.light,
                           s.tangent_ref)
    assert np.array_equal(img, s.image) and s.image.max() > 0
    # One world unit is about one pixel width at the surface (default depth = focal length).
    np.testing.assert_allclose(s.meta["pixel_size"], 1.0, rtol=1e-6)


def test_scene_saves_and_loads(tmp_path):
    s = _ward(seed=8, noise=0.01)
    s.save(tmp_path / "s.nc")
    t = Scene.load(tmp_path / "s.nc")
    assert _equal_scenes(s, t) and np.array_equal(s.true_theta, t.true_theta)
    assert t.meta == s.meta


# ------------------------------------------------------------------------ bad input
def test_theta_out_of_bounds():
    with pytest.raises(ValueError, match="theta outside the ward bounds"):
        _ward(theta=[0.7, 0.4, 0.8])


def test_theta_wrong_length():
    with pytest.raises(ValueError, match=r"theta must have shape \(3,\)"):
        _ward(theta=[0.7, 0.4])


def test_theta_missing():
    with pytest.raises(ValueError, match="theta is required"):
        synthetic.make_scene("ward", **SMALL)


def test_bad_shape():
    with pytest.raises(ValueError, match="shape must be"):
        _ward(shape=(0, 5))


def test_too_few_labels():
    with pytest.raises(ValueError, match="n_labels must be an integer >= 2"):
        _ward(n_labels=0)


def test_bad_surface():
    with pytest.raises(ValueError, match="surface must be 'smooth' or 'jagged'"):
        _ward(surface="rough")


def test_bad_label_step():
    with pytest.raises(ValueError, match="label_step must be finite and > 0"):
        _ward(label_step=0.0)


def test_bad_noise():
    with pytest.raises(ValueError, match="noise must be finite and >= 0"):
        _ward(noise=-0.1)


def test_bad_brdf():
    with pytest.raises(ValueError, match="brdf must be one of"):
        synthetic.make_scene("glossy", [0.1], **SMALL)


def test_bad_control_points():
    with pytest.raises(ValueError, match="n_control_points must be an integer >= 3"):
        _ward(n_control_points=2)


def test_render_bad_points():
    with pytest.raises(ValueError, match="points must have shape"):
        synthetic.render("ward", [0.5, 0.5, 0.2], np.zeros((4, 3)), None, None)


@pytest.mark.parametrize("kw, word", [
    ({"n_labels": 1}, "n_labels must be an integer >= 2"),
    ({"seed": "abc"}, "seed must be"),
    ({"seed": 1.5}, "seed must be"),
    ({"theta": "abc"}, "theta must be 3 numbers"),
    ({"label_step": True}, "label_step must be a number"),
    ({"depth": "x"}, "depth must be"),
    ({"noise": "x"}, "noise must be a number"),
])
def test_bad_arguments_are_named(kw, word):
    args = {"brdf": "ward", "theta": [0.5, 0.5, 0.1], "shape": (2, 2), "n_labels": 3, **kw}
    with pytest.raises(ValueError, match=word):
        synthetic.make_scene(**args)


def test_a_scene_beyond_the_memory_budget_fails_before_allocating():
    from mrfpe.brdf.synthetic import make_scene

    with pytest.raises(ValueError, match=r"a 100000x100000 scene with 20 labels needs about .* "
                                         "more than the memory budget"):
        make_scene(brdf="ward", theta=[0.3, 0.2, 0.1], shape=(100000, 100000))
