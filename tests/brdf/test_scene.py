"""Scene validation, 3-D label points and the exact netCDF round trip."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mrfpe.brdf.geometry import AffineCamera, DirectionalLight, PointLight, ProjectiveCamera
from mrfpe.brdf.scene import Scene

H, W, B = 3, 4, 5


def _kwargs(**over):
    rng = np.random.default_rng(0)
    base = dict(
        image=rng.random((H, W)),
        camera=AffineCamera(),
        light=DirectionalLight([0.1, 0.2, -1.0]),
        label_ranges=10 + np.cumsum(rng.random((H + 1, W + 1, B)), axis=2),
        observed_labels=rng.integers(0, B, (H + 1, W + 1)),
        brdf="ward",
    )
    base.update(over)
    return base


def _full_scene():
    rng = np.random.default_rng(1)
    beliefs = rng.random((H + 1, W + 1, B))
    beliefs /= beliefs.sum(axis=2, keepdims=True)
    K = np.array([[50.0, 0.0, 2.0], [0.0, 50.0, 1.5], [0.0, 0.0, 1.0]])
    return Scene(**_kwargs(
        camera=ProjectiveCamera(np.hstack([K, [[0.1], [0.2], [0.3]]]), image_shape=(H, W)),
        light=PointLight([1.0, 2.0, -3.0], 50.0),
        brdf="phong_aniso", true_theta=[0.3, 0.6, 10.0, 2.5],
        range_prior=rng.random((H + 1, W + 1, B)), beliefs=beliefs,
        tangent_ref=(0.0, 1.0, 0.5), noise_sigma=0.01,
        meta={"note": "test", "nested": {"a": [1, 2.5]}}))


def test_accessors():
    s = Scene(**_kwargs())
    assert s.n_labels == B and s.lattice.shape == (H, W)
    xy = s.node_xy()
    assert xy.shape == (H + 1, W + 1, 2)
    assert np.array_equal(xy[2, 3], [3.0, 2.0])  # node (r=2, c=3) at x=3, y=2
    lp = s.label_points()
    assert lp.shape == (H + 1, W + 1, B, 3)
    assert s.label_points() is lp  # cached
    np.testing.assert_array_equal(lp[..., 2], s.label_ranges)  # default camera: range = depth
    op = s.observed_points()
    r, c = 1, 2
    assert np.array_equal(op[r, c], lp[r, c, s.observed_labels[r, c]])


def test_label_points_projective_lie_on_rays():
    s = _full_scene()
    lp = s.label_points()
    dist = np.linalg.norm(lp - s.camera.center, axis=-1)
    np.testing.assert_allclose(dist, s.label_ranges)
    proj = s.camera.project(lp)
    np.testing.assert_allclose(proj, np.broadcast_to(s.node_xy()[:, :, None, :], proj.shape),
                               atol=1e-9)


@pytest.mark.parametrize("make", ["minimal", "full"])
def test_netcdf_round_trip_exact(tmp_path, make):
    s = Scene(**_kwargs()) if make == "minimal" else _full_scene()
    path = tmp_path / "scene.nc"
    s.save(path)
    t = Scene.load(path)
    for f in dataclasses.fields(Scene):
        if f.name in ("camera", "light", "_cache"):
            continue
        a, b = getattr(s, f.name), getattr(t, f.name)
        if isinstance(a, np.ndarray) or a is None:
            assert (a is None and b is None) or (np.array_equal(a, b) and a.dtype == b.dtype), \
                f.name
        else:
            assert a == b, f.name
    assert s.camera.to_dict() == t.camera.to_dict()
    assert s.light.to_dict() == t.light.to_dict()
    assert np.array_equal(s.label_points(), t.label_points())
    ds = t.to_dataset()
    assert Scene.from_dataset(ds).meta == s.meta


def test_from_dataset_rejects_other_datasets():
    import xarray as xr

    with pytest.raises(ValueError, match="ds is not a scene dataset"):
        Scene.from_dataset(xr.Dataset({"x": ("a", [1.0])}))


# ----------------------------------------------------------------------- bad input
def test_image_nan():
    img = np.ones((H, W))
    img[1, 1] = np.nan
    with pytest.raises(ValueError, match="image contains 1 NaN/inf"):
        Scene(**_kwargs(image=img))


def test_image_inf():
    img = np.ones((H, W))
    img[0, 0] = np.inf
    with pytest.raises(ValueError, match="image contains"):
        Scene(**_kwargs(image=img))


def test_image_wrong_ndim():
    with pytest.raises(ValueError, match=r"image must have shape \(H, W\)"):
        Scene(**_kwargs(image=np.ones((H, W, 3))))


def test_label_ranges_wrong_shape():
    with pytest.raises(ValueError, match="label_ranges must have shape"):
        Scene(**_kwargs(label_ranges=np.ones((H, W, B))))


def test_zero_labels():
    with pytest.raises(ValueError, match="B >= 1"):
        Scene(**_kwargs(label_ranges=np.ones((H + 1, W + 1, 0)),
                        observed_labels=np.zeros((H + 1, W + 1), int)))


def test_label_ranges_nan():
    lr = np.ones((H + 1, W + 1, B))
    lr[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="label_ranges must be finite"):
        Scene(**_kwargs(label_ranges=lr))


def test_observed_labels_out_of_range():
    obs = np.zeros((H + 1, W + 1), int)
    obs[2, 2] = B
    with pytest.raises(ValueError, match=r"observed_labels must lie in \[0, 4\]"):
        Scene(**_kwargs(observed_labels=obs))


def test_observed_labels_negative():
    obs = np.zeros((H + 1, W + 1), int)
    obs[0, 1] = -1
    with pytest.raises(ValueError, match="observed_labels must lie in"):
        Scene(**_kwargs(observed_labels=obs))


def test_observed_labels_wrong_shape():
    with pytest.raises(ValueError, match="observed_labels must have shape"):
        Scene(**_kwargs(observed_labels=np.zeros((H, W), int)))


def test_observed_labels_not_integer():
    with pytest.raises(ValueError, match="observed_labels must be integers"):
        Scene(**_kwargs(observed_labels=np.full((H + 1, W + 1), 0.5)))


def test_camera_image_size_mismatch():
    P = np.hstack([np.eye(3), np.ones((3, 1))])
    with pytest.raises(ValueError, match="camera image_shape"):
        Scene(**_kwargs(camera=ProjectiveCamera(P, image_shape=(H + 1, W))))


def test_projective_ranges_must_be_positive():
    P = np.hstack([np.eye(3), np.zeros((3, 1))])
    with pytest.raises(ValueError, match="label_ranges must be > 0"):
        Scene(**_kwargs(camera=ProjectiveCamera(P), label_ranges=-np.ones((H + 1, W + 1, B))))


def test_bad_camera_type():
    with pytest.raises(ValueError, match="camera must be"):
        Scene(**_kwargs(camera=np.eye(3)))


def test_bad_light_type():
    with pytest.raises(ValueError, match="light must be"):
        Scene(**_kwargs(light=[0, 0, -1]))


def test_bad_brdf():
    with pytest.raises(ValueError, match="brdf must be one of"):
        Scene(**_kwargs(brdf="blinn"))


def test_true_theta_wrong_length():
    with pytest.raises(ValueError, match=r"true_theta must have shape \(N, 3\)"):
        Scene(**_kwargs(true_theta=[0.1, 0.2]))


def test_true_theta_out_of_bounds():
    with pytest.raises(ValueError, match="true_theta outside the ward bounds"):
        Scene(**_kwargs(true_theta=[0.1, 0.2, 0.9]))


def test_range_prior_wrong_shape():
    with pytest.raises(ValueError, match="range_prior must have shape"):
        Scene(**_kwargs(range_prior=np.zeros((H + 1, W + 1, B + 1))))


def test_range_prior_nan():
    rp = np.zeros((H + 1, W + 1, B))
    rp[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="range_prior must not contain NaN"):
        Scene(**_kwargs(range_prior=rp))


def test_beliefs_not_normalised():
    with pytest.raises(ValueError, match="beliefs must be normalised"):
        Scene(**_kwargs(beliefs=np.ones((H + 1, W + 1, B))))


def test_beliefs_negative():
    bl = np.full((H + 1, W + 1, B), 1.0 / B)
    bl[0, 0, 0], bl[0, 0, 1] = -0.1, 0.2 + 0.1
    with pytest.raises(ValueError, match="beliefs must be finite and >= 0"):
        Scene(**_kwargs(beliefs=bl))


def test_bad_tangent_ref():
    with pytest.raises(ValueError, match="tangent_ref must be a finite non-zero"):
        Scene(**_kwargs(tangent_ref=(0, 0, 0)))


def test_bad_noise_sigma():
    with pytest.raises(ValueError, match="noise_sigma must be finite and >= 0"):
        Scene(**_kwargs(noise_sigma=-1.0))


def test_meta_not_json():
    with pytest.raises(ValueError, match="meta must be JSON-serialisable"):
        Scene(**_kwargs(meta={"a": object()}))
