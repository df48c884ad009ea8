"""The kernels' separable radiance form equals mrfpe.brdf.shading's radiance for every BRDF."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import brdf as B
from mrfpe.brdf import shading
from mrfpe.brdf.targets import reflectance


def _geometry(rng, m):
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:, 2] = np.abs(n[:, 2])  # mostly facing +z
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    l = rng.normal(size=(m, 3)) + np.array([0, 0, 1.5])
    l /= np.linalg.norm(l, axis=1, keepdims=True)
    v = rng.normal(size=(m, 3)) * 0.3 + np.array([0, 0, 1])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:3] = n[:3]  # mirror-like and degenerate cases
    l[:3] = n[:3]
    t = np.cross(n, [0.3, 1.0, 0.2])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    E = rng.uniform(0.5, 2.0, m)
    return shading.TriangleGeometry(n=n, l=l, v=v, t=t, irradiance=E)


@pytest.mark.parametrize("name", B.names())
def test_separable_equals_shading(name):
    rng = np.random.default_rng(0)
    model = B.get(name)
    g = _geometry(rng, 400)
    feats, weight = shading.shading_features(model, g)
    sep = reflectance.features(model, feats, weight)
    u = rng.random((25, model.d))
    u[0] = 0.0  # lower bounds: alpha = 0, n = 0
    u[1] = 1.0
    theta = model.to_natural(u)
    want = shading.radiance(model, theta, g)
    got = reflectance.radiance(reflectance.coefficients(model, theta), sep)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
