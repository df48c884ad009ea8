"""The thesis's BRDF MRF through the model door: the same targets, plus Besag's codings."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import models
from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import get


@pytest.fixture(scope="module")
def scene():
    return make_scene(brdf="phong", theta=[0.5, 0.4, 8.0], shape=(6, 7), n_labels=5, seed=3)


def test_model_targets_are_the_short_forms_bit_for_bit(scene):
    m = models.get("brdf")
    th = np.random.default_rng(0).random((9, 3))
    for est in ("pl", "pl2", "pls", "fit", "pml"):
        a = m.target(est, scene).log_prob(th)
        b = get(est, scene).log_prob(th)
        np.testing.assert_array_equal(a, b)


def test_codings_sum_to_pl_and_are_codings(scene):
    m = models.get("brdf")
    assert m.n_codings(scene.shape) == 4
    th = np.random.default_rng(1).random((5, 3))
    parts = [m.target("coding", scene, coding=k) for k in range(4)]
    np.testing.assert_allclose(sum(p.log_prob(th) for p in parts),
                               get("pl", scene).log_prob(th), rtol=1e-10)
    # no two nodes of one coding share a pixel (so they are conditionally independent)
    lat = scene.lattice
    for p in parts:
        mine = set(p.nodes.tolist())
        assert all(len(mine & set(px.tolist())) <= 1 for px in lat.pixel_nodes)
    with pytest.raises(ValueError, match="coding must be in"):
        m.target("coding", scene, coding=4)


def test_brdf_model_errors(scene):
    m = models.get("brdf")
    with pytest.raises(ValueError, match="estimator must be one of"):
        m.target("exact", scene)
    with pytest.raises(ValueError, match="valid options"):
        m.target("pl", scene, sigma=1.0)
    assert m.param_names("phong") == tuple(get("pl", scene).param_names)
