"""Property-based tests (hypothesis) of the targets: random small scenes, labels, batches."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrfpe.brdf.synthetic import make_scene
from mrfpe.models.short_forms import gibbs_sample
from mrfpe.targets import get, softened

THETA = {"lambertian": [0.6], "ward": [0.6, 0.5, 0.2], "ward_aniso": [0.6, 0.3, 0.2, 0.1],
         "phong": [0.5, 0.4, 10.0], "phong_aniso": [0.5, 0.4, 10.0, 5.0]}
FAST = settings(max_examples=20, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@st.composite
def scenes(draw, max_labels=6):
    brdf = draw(st.sampled_from(sorted(THETA)))
    H, W = draw(st.integers(1, 3)), draw(st.integers(1, 3))
    B = draw(st.integers(2, max_labels))
    seed = draw(st.integers(0, 2**16))
    noise = draw(st.sampled_from([0.0, 0.01]))
    return make_scene(brdf=brdf, theta=THETA[brdf], shape=(H, W), n_labels=B, noise=noise,
                      seed=seed)


def _batch(draw, d, n):
    vals = st.one_of(st.floats(0.0, 1.0), st.sampled_from([0.0, 1.0, -1e-9, 1 + 1e-9, -3.0,
                                                          4.0, 1e-300, 1 - 1e-16]))
    return np.array(draw(st.lists(st.lists(vals, min_size=d, max_size=d), min_size=n,
                                  max_size=n)), dtype=np.float64).reshape(n, d)


@FAST
@given(sc=scenes(), name=st.sampled_from(["pl", "pl2", "pls", "fit", "pml"]),
       dtype=st.sampled_from(["float64", "float32"]), data=st.data())
def test_brdf_target_properties(sc, name, dtype, data):
    t = get(name, sc, dtype=dtype)
    n = data.draw(st.integers(0, 7))
    x = _batch(data.draw, t.ndim, n)
    lp = t.log_prob(x)
    assert lp.shape == (n,) and lp.dtype == np.float64
    inside = np.all((x >= 0) & (x <= 1), axis=1)
    assert np.all(lp[~inside] == -np.inf)
    assert not np.isnan(lp).any() and not (lp == np.inf).any()
    if n:
        assert t.log_prob(x[0]).shape == (1,)
    kind = data.draw(st.sampled_from(["strided", "block"]))
    k = data.draw(st.integers(1, min(4, sc.lattice.n_nodes)))
    parts = t.partition(k, kind)
    assert sum(p.cost for p in parts) == pytest.approx(1.0)
    if n:
        total = np.sum([p.log_prob(x) for p in parts], axis=0)
        fin = np.isfinite(lp)
        rtol = 1e-9 if dtype == "float64" else 1e-5
        np.testing.assert_allclose(total[fin], lp[fin], rtol=rtol, atol=rtol)
        assert np.all(total[~fin] == -np.inf)


@FAST
@given(q=st.integers(2, 5), shape=st.tuples(st.integers(1, 5), st.integers(1, 5)),
       m=st.integers(1, 3), seed=st.integers(0, 1000), data=st.data())
def test_potts_properties(q, shape, m, seed, data):
    x = gibbs_sample(np.zeros(q), shape, q, n_samples=m, n_sweeps=2, seed=seed)
    t = get("potts", x, n_states=q)
    n = data.draw(st.integers(0, 6))
    b = t.bounds
    u = _batch(data.draw, q, n)
    theta = b[:, 0] + u * (b[:, 1] - b[:, 0])
    lp = t.log_prob(theta)
    assert lp.shape == (n,)
    assert not np.isnan(lp).any()
    inside = np.all((u >= 0) & (u <= 1), axis=1)
    assert np.all(lp[~inside] == -np.inf) and np.all(np.isfinite(lp[inside]))
    k = data.draw(st.integers(1, min(4, shape[0] * shape[1])))
    parts = t.partition(k, data.draw(st.sampled_from(["strided", "block"])))
    if n:
        np.testing.assert_allclose(np.sum([p.log_prob(theta) for p in parts], axis=0)[inside],
                                   lp[inside], rtol=1e-10, atol=1e-10)
    s = softened(t, 0.5)
    np.testing.assert_array_equal(s.log_prob(theta), 0.5 * lp)


# -- numerics at the edges: never NaN ----------------------------------------------------
EDGE = np.array([0.0, 1.0, 1e-300, 1e-16, 1 - 1e-16, 0.5])


def _edge_batch(d):
    grids = np.meshgrid(*([EDGE] * min(d, 3)), indexing="ij")
    pts = np.stack([g.reshape(-1) for g in grids], axis=1)
    if d > 3:
        pts = np.hstack([pts, np.full((pts.shape[0], d - 3), 0.0)])
        pts = np.vstack([pts, np.hstack([pts[:, :3], np.full((pts.shape[0], d - 3), 1.0)])])
    return pts


@pytest.mark.parametrize("brdf", sorted(THETA))
@pytest.mark.parametrize("sigma_b", [1e-12, 1e-3, 1e12])
@pytest.mark.parametrize("n_labels", [2, 200])
def test_edges_never_nan(brdf, sigma_b, n_labels):
    sc = make_scene(brdf=brdf, theta=THETA[brdf], shape=(1, 2), n_labels=n_labels, seed=4,
                    noise=0.01)
    for name in ("pl", "pls", "pml", "fit"):
        for dtype in ("float64", "float32"):
            t = get(name, sc, sigma_b=sigma_b, dtype=dtype)
            x = _edge_batch(t.ndim)
            lp = t.log_prob(x)
            assert not np.isnan(lp).any(), (name, dtype, x[np.isnan(lp)][:3])
            assert not (lp == np.inf).any()
            r = t.residuals(x[:4], "sqrt")
            assert not np.isnan(r).any()
