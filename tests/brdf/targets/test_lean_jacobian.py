"""Analytic residual Jacobians (mrfpe.brdf.targets.jacobian) against central differences;
LM optima."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe import brdf as B
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import jacobian as J
from mrfpe.targets import get


@pytest.mark.parametrize("brdf,u,dtype", [("ward", [0.7, 0.4, 0.45], "float64"),
                                          ("phong", [0.5, 0.4, 0.3], "float64"),
                                          ("phong_aniso", [0.5, 0.4, 0.3, 0.5], "float64"),
                                          ("ward", [0.7, 0.4, 0.45], "float32")])
def test_jacobian_matches_central_differences(brdf, u, dtype):
    s = make_scene(brdf=brdf, theta=B.get(brdf).to_natural(np.array(u)), shape=(10, 12),
                   n_labels=6, surface="jagged", seed=1)
    t = get("pls", s, dtype=dtype)
    assert J.supports(t)
    x = np.clip(np.array(u) + 0.07, 0.05, 0.95)
    val, jac = J.node_terms_and_jacobian(t, x)
    # float32 node terms are differences of energies: accurate relative to the largest term
    # (the classic float32 kernel errs as much), not to a small term's own size
    scale = 1e-9 if dtype == "float64" else 2e-6 * np.max(np.abs(val))
    np.testing.assert_allclose(val, t.node_terms(x[None])[0],
                               rtol=1e-12 if dtype == "float64" else 2e-6, atol=scale)
    h = 1e-6
    fd = np.stack([(get("pls", s).node_terms((x + h * e)[None])[0]
                    - get("pls", s).node_terms((x - h * e)[None])[0]) / (2 * h)
                   for e in np.eye(x.size)], 1)
    assert np.linalg.norm(jac - fd) <= 1e-4 * np.linalg.norm(fd)
    for kind in ("inverse", "one_minus", "sqrt"):
        r, jr = J.residuals_and_jacobian(get("pls", s), x, kind)
        np.testing.assert_allclose(r, get("pls", s).residuals(x, kind), rtol=1e-12)
        fr = np.stack([(get("pls", s).residuals(x + h * e, kind)
                        - get("pls", s).residuals(x - h * e, kind)) / (2 * h)
                       for e in np.eye(x.size)], 1)
        assert np.linalg.norm(jr - fr) <= 1e-4 * np.linalg.norm(fr)


def test_lm_multiseed_same_optima_with_analytic_jacobian(monkeypatch):
    u = np.array([0.6, 0.4, 0.45])
    s = make_scene(brdf="ward", theta=B.get("ward").to_natural(u), shape=(16, 16), n_labels=10,
                   seed=0)
    t = get("pls", s)
    new = mrfpe.sample("lm_multiseed", t, seed=0, n_seeds=8)
    monkeypatch.setattr(J, "supports", lambda target: False)  # forward differences
    old = mrfpe.sample("lm_multiseed", t, seed=0, n_seeds=8)
    assert np.max(np.abs(new["map_theta"].values[-1] - old["map_theta"].values[-1])) < 5e-3
    # a noise-free scene's optimum sits where many L1 residuals are 0 (kinks): the two
    # Jacobians stop ~1e-5 apart in theta, up to ~2e-5 of the value apart, in either order
    # (1e-16 changes in the values move forward differences' path that much)
    assert abs(new["map_log_target"].values[-1] - old["map_log_target"].values[-1]) <= 5e-5 * abs(
        old["map_log_target"].values[-1])


@pytest.mark.parametrize("brdf,u", [("ward", [0.7, 0.4, 0.45]),
                                    ("phong_aniso", [0.5, 0.4, 0.3, 0.5])])
def test_batched_rows_are_the_single_point_calls_bit_for_bit(brdf, u):
    # more nodes than a block: the particles loop inside each node block
    s = make_scene(brdf=brdf, theta=B.get(brdf).to_natural(np.array(u)), shape=(25, 23),
                   n_labels=5, surface="jagged", seed=3)
    t = get("pls", s)
    x = np.random.default_rng(1).uniform(0.1, 0.9, (6, len(u)))
    r, jr = J.residuals_and_jacobians(t, x)
    assert r.shape == (6, t._tables.n_nodes) and jr.shape == (6, t._tables.n_nodes, len(u))
    for q in range(6):
        r1, j1 = J.residuals_and_jacobian(t, x[q])
        np.testing.assert_array_equal(r[q], r1)
        np.testing.assert_array_equal(jr[q], j1)
