"""BRDF models against independent routes: angle forms, reciprocity, reductions."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import brdf

RNG_SEED = 1234


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _geometry(m, seed=RNG_SEED):
    """Random n, l, v above the tangent plane and a tangent t perpendicular to n."""
    rng = np.random.default_rng(seed)
    n = _unit(rng.normal(size=(m, 3)))

    def upper():
        d = _unit(rng.normal(size=(m, 3)))
        return np.where((np.sum(d * n, -1) < 0)[:, None], -d, d)

    l, v = upper(), upper()
    t = _unit(np.cross(n, rng.normal(size=(m, 3))))
    return n, l, v, t


def _random_theta(model, k, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.05, 1.0, (k, model.d))
    return model.to_natural(u)


def _angles(n, l, v, t):
    """Angles of Fig. 3.1 computed with trigonometry."""
    theta_i = np.arccos(np.clip(np.sum(n * l, -1), -1, 1))
    theta_r = np.arccos(np.clip(np.sum(n * v, -1), -1, 1))
    h = _unit(l + v)
    delta = np.arccos(np.clip(np.sum(n * h, -1), -1, 1))
    b = np.cross(n, t)
    phi = np.arctan2(np.sum(h * b, -1), np.sum(h * t, -1))
    return theta_i, theta_r, h, delta, phi


def test_names_and_get():
    assert set(brdf.names()) == {"lambertian", "ward", "ward_aniso", "phong", "phong_aniso"}
    for name in brdf.names():
        m = brdf.get(name)
        assert m.name == name
        assert m.bounds.shape == (m.d, 2)
        assert len(m.param_names) == m.d == len(m.unit_scale)
    with pytest.raises(ValueError, match="brdf must be one of"):
        brdf.get("cook_torrance")


def test_unit_cube_scales_match_thesis_7_1_7_2():
    assert np.array_equal(brdf.get("ward").unit_scale, [1.0, 1.0, 0.5])
    assert np.array_equal(brdf.get("phong").unit_scale, [1.0, 1.0, 25.0])
    assert np.array_equal(brdf.get("phong_aniso").bounds[:, 1], [1, 1, 25, 25])
    m = brdf.get("ward_aniso")
    u = np.random.default_rng(0).random((7, 4))
    assert np.allclose(m.to_unit(m.to_natural(u)), u)
    assert np.allclose(m.to_natural(u)[:, 2:], 0.5 * u[:, 2:])


def test_ward_matches_angle_form_3_1():
    n, l, v, t = _geometry(500)
    model = brdf.get("ward")
    theta = np.array([[0.7, 0.4, 0.45], [0.3, 0.6, 0.1], [0.05, 0.9, 0.2]])
    ti, tr, _, delta, _ = _angles(n, l, v, t)
    for rd, rs, a in theta:
        ref = rd / np.pi + rs / np.sqrt(np.cos(ti) * np.cos(tr)) * np.exp(
            -np.tan(delta) ** 2 / a**2) / (4 * np.pi * a**2)
        got = model.evaluate([[rd, rs, a]], n, l, v)[0]
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_ward_aniso_matches_angle_form_3_2():
    n, l, v, t = _geometry(500, seed=7)
    model = brdf.get("ward_aniso")
    ti, tr, _, delta, phi = _angles(n, l, v, t)
    for rd, rs, au, av in [(0.2, 0.5, 0.1, 0.3), (0.6, 0.3, 0.45, 0.05)]:
        expo = np.tan(delta) ** 2 * (np.cos(phi) ** 2 / au**2 + np.sin(phi) ** 2 / av**2)
        ref = rd / np.pi + rs / np.sqrt(np.cos(ti) * np.cos(tr)) * np.exp(-expo) / (
            4 * np.pi * au * av)
        got = model.evaluate([[rd, rs, au, av]], n, l, v, t)[0]
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def _as_reference(theta, n, l, v, t):
    """Ashikhmin & Shirley (2000), eqs. 3.12-3.14 and 3.16 with angles (phi form 3.13)."""
    rd, rs, nu, nv = theta
    h = _unit(l + v)
    b = np.cross(n, t)
    phi = np.arctan2(np.sum(h * b, -1), np.sum(h * t, -1))
    nh = np.sum(n * h, -1)
    nl = np.sum(n * l, -1)
    nvv = np.sum(n * v, -1)
    vh = np.sum(v * h, -1)  # k = k2 (camera) here, the test of "k can be either"
    fresnel = rs + (1 - rs) * (1 - vh) ** 5
    spec = (np.sqrt((nu + 1) * (nv + 1)) / (8 * np.pi) * nh ** (nu * np.cos(phi) ** 2
            + nv * np.sin(phi) ** 2) / (vh * np.maximum(nl, nvv)) * fresnel)
    diff = (28 * rd / (23 * np.pi) * (1 - rs) * (1 - (1 - nl / 2) ** 5)
            * (1 - (1 - nvv / 2) ** 5))
    return diff + spec


def test_ashikhmin_shirley_matches_independent_evaluation():
    n, l, v, t = _geometry(400, seed=3)
    model = brdf.get("phong_aniso")
    for th in [(0.3, 0.6, 10.0, 3.0), (0.8, 0.1, 0.5, 24.0), (0.5, 0.5, 25.0, 25.0)]:
        got = model.evaluate([th], n, l, v, t)[0]
        np.testing.assert_allclose(got, _as_reference(th, n, l, v, t), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", ["lambertian", "ward", "ward_aniso", "phong", "phong_aniso"])
def test_reciprocity(name):
    model = brdf.get(name)
    n, l, v, t = _geometry(300, seed=11)
    theta = _random_theta(model, 4)
    a = model.evaluate(theta, n, l, v, t)
    b = model.evaluate(theta, n, v, l, t)
    assert a.shape == (4, 300)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)


def test_equal_roughness_reduces_to_isotropic():
    n, l, v, t = _geometry(300, seed=5)
    th = _random_theta(brdf.get("ward"), 5, seed=2)
    iso = brdf.get("ward").evaluate(th, n, l, v)
    aniso = brdf.get("ward_aniso").evaluate(np.column_stack([th, th[:, 2]]), n, l, v, t)
    np.testing.assert_allclose(aniso, iso, rtol=1e-9)
    th = _random_theta(brdf.get("phong"), 5, seed=3)
    iso = brdf.get("phong").evaluate(th, n, l, v)
    aniso = brdf.get("phong_aniso").evaluate(np.column_stack([th, th[:, 2]]), n, l, v, t)
    np.testing.assert_allclose(aniso, iso, rtol=1e-9)


def test_anisotropic_models_depend_on_tangent():
    n, l, v, t = _geometry(200, seed=9)
    t2 = np.cross(n, t)  # rotate the tangent by 90 degrees
    for name, th in [("ward_aniso", [0.2, 0.7, 0.05, 0.4]), ("phong_aniso", [0.2, 0.7, 2, 20])]:
        m = brdf.get(name)
        a = m.evaluate([th], n, l, v, t)
        b = m.evaluate([th], n, l, v, t2)
        swapped = [th[0], th[1], th[3], th[2]]
        assert not np.allclose(a, b)
        np.testing.assert_allclose(m.evaluate([swapped], n, l, v, t2), a, rtol=1e-9)


def test_lambertian_value():
    n, l, v, _ = _geometry(50)
    out = brdf.get("lambertian").evaluate([[0.3], [1.0]], n, l, v)
    np.testing.assert_allclose(out, np.array([[0.3], [1.0]]) / np.pi * np.ones(50))


@pytest.mark.parametrize("name", ["lambertian", "ward", "ward_aniso", "phong", "phong_aniso"])
def test_zero_below_horizon(name):
    model = brdf.get(name)
    n, l, v, t = _geometry(100, seed=4)
    theta = _random_theta(model, 2)
    assert np.all(model.evaluate(theta, n, -l, v, t) == 0)
    assert np.all(model.evaluate(theta, n, l, -v, t) == 0)
    assert np.all(model.evaluate(theta, n, l, v, t) > 0)


def test_ward_specular_lobe_is_normalised():
    """Hemispherical integral of the Ward lobe times cos at normal incidence ~ rho_s.

    Independent check of the 1/(4 pi alpha^2) normalisation (Ward 1992: accurate
    for small alpha).
    """
    model = brdf.get("ward")
    th_o = np.linspace(0, np.pi / 2, 4001)[1:-1]
    ph = np.linspace(0, 2 * np.pi, 65)[:-1]
    T, P = np.meshgrid(th_o, ph, indexing="ij")
    v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    n = np.array([0.0, 0.0, 1.0])
    l = np.broadcast_to(n, v.shape)
    f = model.evaluate([[0.0, 1.0, 0.05]], n, l, v)[0]
    integral = np.sum(f * np.cos(T) * np.sin(T)) * (th_o[1] - th_o[0]) * (ph[1] - ph[0])
    assert abs(integral - 1.0) < 0.01


def test_output_shape_broadcasts_geometry():
    n, l, v, t = _geometry(24)
    geo = [a.reshape(2, 3, 4, 3) for a in (n, l, v, t)]
    model = brdf.get("phong_aniso")
    th = _random_theta(model, 5)
    out = model.evaluate(th, *geo)
    assert out.shape == (5, 2, 3, 4)
    np.testing.assert_array_equal(out.reshape(5, 24), model.evaluate(th, n, l, v, t))


def test_zero_roughness_is_finite():
    n, l, v, _ = _geometry(50)
    out = brdf.get("ward").evaluate([[0.4, 0.5, 0.0]], n, l, v)
    np.testing.assert_allclose(out, 0.4 / np.pi)
    assert np.all(np.isfinite(brdf.get("phong").evaluate([[0.4, 0.5, 0.0]], n, l, v)))


def test_h_along_normal_is_finite_for_phong_aniso():
    n = np.array([[0.0, 0.0, 1.0]])
    l = _unit(np.array([[0.3, 0.0, 1.0]]))
    v = l * np.array([-1, -1, 1])
    t = np.array([[1.0, 0.0, 0.0]])
    th = (0.3, 0.6, 5.0, 20.0)
    out = brdf.get("phong_aniso").evaluate([th], n, l, v, t)
    np.testing.assert_allclose(out[0], _as_reference(th, n, l, v, t))


def test_bad_theta_shape():
    n, l, v, _ = _geometry(5)
    with pytest.raises(ValueError, match=r"theta must have shape \(N, 3\)"):
        brdf.get("ward").evaluate([[0.1, 0.2]], n, l, v)


def test_missing_tangent():
    n, l, v, _ = _geometry(5)
    with pytest.raises(ValueError, match="t \\(surface tangent\\) is required"):
        brdf.get("ward_aniso").evaluate([[0.1, 0.2, 0.1, 0.1]], n, l, v)


def test_bad_geometry_shape():
    with pytest.raises(ValueError, match="n must have shape"):
        brdf.get("ward").evaluate([[0.1, 0.2, 0.1]], np.zeros((4, 2)), np.zeros(3), np.zeros(3))


def test_check_theta_bounds():
    m = brdf.get("ward")
    assert m.check_theta([0.7, 0.4, 0.45]).shape == (1, 3)
    with pytest.raises(ValueError, match="theta outside the ward bounds"):
        m.check_theta([0.7, 0.4, 0.6])
    with pytest.raises(ValueError, match="theta must be finite"):
        m.check_theta([0.7, np.nan, 0.1])
