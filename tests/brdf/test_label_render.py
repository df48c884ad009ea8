"""Rendering labellings: the radiance memo and kept draw renders equal the direct render."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf import label_render
from mrfpe.brdf.label_render import RadianceMemo, draw_features, memo_for, term_energies
from mrfpe.brdf.model import BRDFLikelihood
from mrfpe.brdf.simulate import _coefficients, label_field, simulate_labels
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import reflectance


def _field(brdf="ward", data_term="pixel", shape=(7, 9), n_labels=5):
    theta = {"ward": [0.5, 0.3, 0.2], "phong": [0.5, 0.3, 20.0]}[brdf]
    sc = make_scene(brdf, theta=theta, shape=shape, n_labels=n_labels, seed=3, noise=0.01)
    u = sc.model.to_unit(sc.true_theta[None])[0] * 0.9
    return label_field(sc, data_term=data_term, prior="range"), u


@pytest.mark.parametrize(("brdf", "data_term"), [("ward", "pixel"), ("phong", "triplet")])
def test_memo_gives_the_direct_render_bit_for_bit(brdf, data_term):
    f, u = _field(brdf, data_term)
    rng = np.random.default_rng(0)
    x = rng.integers(0, f.n_labels, (6, f.n_nodes))
    coef = _coefficients(f, u)
    direct = term_energies(f, coef, x)
    memo = RadianceMemo(f, coef)
    np.testing.assert_array_equal(term_energies(f, coef, x[:3], memo), direct[:, :3])
    filled = np.isfinite(memo.values).sum()
    np.testing.assert_array_equal(term_energies(f, coef, x, memo), direct)  # half from the memo
    assert filled < np.isfinite(memo.values).sum() < memo.values.size
    # a coding set to each label in turn: the same radiances as the B explicit labellings
    nodes = f.scene.lattice.codings()[1]
    X = np.repeat(x[:1], f.n_labels, axis=0)
    X[:, nodes] = np.arange(f.n_labels)[:, None]
    got = memo.coding_radiance(f, x[0], nodes)
    want = RadianceMemo(f, coef).radiance(f, X)
    np.testing.assert_array_equal(got, want)


def test_chain_with_and_without_the_memo_is_the_same_chain(monkeypatch):
    f, u = _field()
    with_memo = simulate_labels(f, u, 4, n_sweeps=6, thin=2, seed=9)
    assert "radiance" in f.memo
    g, _ = _field()
    without = simulate_labels(g, u, 4, n_sweeps=6, thin=2, seed=9, memoise=False)
    assert "radiance" not in g.memo
    np.testing.assert_array_equal(with_memo, without)
    monkeypatch.setattr(label_render, "MEMO_BUDGET_FRACTION", 0.0)  # no room for a memo
    assert memo_for(g, _coefficients(g, u)) is None


def test_memo_follows_the_parameters():
    f, u = _field()
    a, b = _coefficients(f, u), _coefficients(f, u * 0.5)
    m = memo_for(f, a)
    m.radiance(f, np.zeros((1, f.n_nodes), dtype=np.int64))
    assert memo_for(f, a) is m and np.isfinite(m.values).any()
    assert memo_for(f, b) is m and not np.isfinite(m.values).any()  # reset for new theta
    np.testing.assert_array_equal(m.coef, b)


def test_kept_draw_renders_give_the_likelihood_at_any_theta():
    f, u = _field("phong")
    lik = BRDFLikelihood(f.scene, prior="range")
    y = lik.simulate(u, n=3, seed=2, n_sweeps=4, thin=2)
    theta = np.array([u, 0.8 * u, [0.2, 0.6, 0.1], [1.2, 0.5, 0.5]])
    got = lik.log_f_of_draws(y)(theta)
    want = np.stack([lik.unnormalised(theta, yk[None]) for yk in y], axis=1)
    assert np.all(np.isinf(got[3])) and np.all(np.isinf(want[3]))  # outside the unit cube
    np.testing.assert_allclose(got[:3], want[:3], rtol=1e-13)
    feats = draw_features(f, y.reshape(3, -1))
    coef = _coefficients(f, u)
    rad = reflectance.radiance(coef, feats.reshape(-1, 5)).reshape(3, -1)
    np.testing.assert_array_equal(rad, RadianceMemo(f, coef).radiance(f, y.reshape(3, -1)))
