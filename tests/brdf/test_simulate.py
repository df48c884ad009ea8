"""BRDF label-field simulator: energy against the pseudolikelihood, Gibbs against enumeration."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from mrfpe.brdf.simulate import (
    DEFAULT_SWEEPS,
    conditional_energies,
    label_energy,
    label_field,
    simulate_labels,
)
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.energy import build_tables, energies_reference
from mrfpe.brdf.targets.pseudolikelihood import PL, PL3, PLS, ImageFit
from mrfpe.models import get

SIGMA = 0.05


def _scene(brdf="ward", shape=(2, 3), n_labels=3, seed=1):
    theta = {"ward": [0.5, 0.3, 0.2], "phong": [0.5, 0.3, 20.0]}[brdf]
    sc = make_scene(brdf, theta=theta, shape=shape, n_labels=n_labels, seed=seed, noise=0.01,
                    surface="smooth" if brdf == "ward" else "jagged")
    rng = np.random.default_rng(seed)
    b = rng.uniform(0.1, 1.0, (*sc.lattice.node_shape, n_labels))
    return dataclasses.replace(sc, beliefs=b / b.sum(axis=2, keepdims=True))


def _theta(sc, scale=0.9):
    return sc.model.to_unit(sc.true_theta[None])[0] * scale


def _relabel(sc, x):
    return dataclasses.replace(sc, observed_labels=np.asarray(x).reshape(sc.lattice.node_shape))


def _single_flips(x, B):
    """Every labelling that differs from ``x`` at one node: (n_nodes, B, n_nodes)."""
    X = np.repeat(np.repeat(x[None, None], x.size, 0), B, 1)
    X[np.arange(x.size), :, np.arange(x.size)] = np.arange(B)
    return X


TARGETS = {"none": (PL, {}), "range": (PLS, {"prior_weight": 0.7}),
           "beliefs": (PL3, {"temperature": 1.5})}


@pytest.mark.parametrize("prior", ["none", "range", "beliefs"])
def test_joint_pl_is_the_pseudolikelihood_of_the_prior(prior):
    """``BRDFModel.joint_pl`` (the PL that pl_adjusted calibrates) is ``pl``/``pls``/``pl3``."""
    sc = _scene("ward")
    cls, opts = TARGETS[prior]
    got = get("brdf").joint_pl(sc, prior=prior, sigma_b=SIGMA, **opts)
    assert type(got) is cls
    th = np.random.default_rng(2).random((4, 3))
    np.testing.assert_array_equal(got.log_prob(th), cls(sc, sigma_b=SIGMA, **opts).log_prob(th))
    with pytest.raises(ValueError, match="valid options"):
        get("brdf").joint_pl(sc, n_sweeps=3)  # a chain option, not the joint's


@pytest.mark.parametrize("brdf", ["ward", "phong"])
@pytest.mark.parametrize("prior", ["none", "range", "beliefs"])
def test_energy_differences_are_the_pseudolikelihood_conditionals(brdf, prior):
    """Pixel form: U(x^s) - U(x^t) = E_i(s) - E_i(t), E_i from the PL target (consistency)."""
    sc = _scene(brdf)
    cls, opts = TARGETS[prior]
    th = _theta(sc)
    x = np.random.default_rng(5).integers(0, sc.n_labels, sc.lattice.n_nodes)
    flips = _single_flips(x, sc.n_labels)
    U = label_energy(sc, th, flips.reshape(-1, x.size), sigma_b=SIGMA, prior=prior,
                     **opts).reshape(x.size, -1)
    # log p_PL(x_i = s | x_-i) from the target's per-node terms at the labelling with x_i = s
    log_cond = np.empty_like(U)
    for i, s in itertools.product(range(x.size), range(sc.n_labels)):
        t = cls(_relabel(sc, flips[i, s]), sigma_b=SIGMA, **opts)
        log_cond[i, s] = t.node_terms(th)[0, i]
    np.testing.assert_allclose(U - U[:, :1], -(log_cond - log_cond[:, :1]), atol=1e-9)
    # and the normalised conditionals themselves
    lse = np.log(np.exp(-(U - U.min(1, keepdims=True))).sum(1)) - U.min(1)
    np.testing.assert_allclose(-U - lse[:, None], log_cond, atol=1e-9)


def test_pixel_energy_is_the_image_fit_once_per_pixel():
    """The pixel form's U counts each pixel once; ``fit`` counts it once per corner (4 times)."""
    sc = _scene(shape=(3, 3))
    th = _theta(sc, 0.8)
    for seed in range(3):
        x = np.random.default_rng(seed).integers(0, sc.n_labels, sc.lattice.node_shape)
        fit = ImageFit(_relabel(sc, x), sigma_b=SIGMA).log_prob(th)[0]
        assert label_energy(sc, th, x, sigma_b=SIGMA) == pytest.approx(-fit / 4, rel=1e-12)


def test_triplet_joint_and_why_the_thesis_conditionals_are_not_its_own():
    """Triplet form: U = sum of every clique once (the centred node energies summed over the
    lattice), its conditionals sum every clique containing the node, and those differ from
    the thesis's centred conditionals (4.27)."""
    sc = _scene(shape=(3, 3))
    th = _theta(sc, 0.8)
    f = label_field(sc, data_term="triplet", sigma_b=SIGMA)
    x = np.random.default_rng(2).integers(0, sc.n_labels, sc.lattice.n_nodes)
    fit = ImageFit(_relabel(sc, x), sigma_b=SIGMA, data_term="triplet").log_prob(th)[0]
    assert label_energy(f, th, x) == pytest.approx(-fit, rel=1e-12)
    flips = _single_flips(x, sc.n_labels)
    U = label_energy(f, th, flips.reshape(-1, x.size)).reshape(x.size, -1)
    coef = reflectance.coefficients(sc.model, sc.model.to_natural(th[None]))
    E = energies_reference(build_tables(_relabel(sc, x), "triplet"), coef, SIGMA)[0]
    # the thesis's node energy (centred cliques) is not a full conditional of any joint ...
    assert np.abs((U - U[:, :1]) - (E - E[:, :1])).max() > 0.1
    # ... while the simulator's conditionals are the joint's
    for nodes in sc.lattice.codings():
        C = conditional_energies(f, coef, x, nodes).T
        np.testing.assert_allclose(C - C[:, :1], (U - U[:, :1])[nodes], atol=1e-9)


def _batch_z(f, th, draws, marg, mean_u):
    """Largest |estimate - exact| / batch-means SE over the per-node marginals and mean U."""
    stats = np.column_stack([draws, label_energy(f, th, draws)])
    batches = stats.reshape(20, -1, stats.shape[1]).mean(axis=1)
    se = batches.std(axis=0, ddof=1) / np.sqrt(20)
    return float(np.max(np.abs(stats.mean(axis=0) - np.append(marg, mean_u))
                        / np.maximum(se, 1e-3)))


def _wrong_sweeps(f, th, n, sets, seed):
    """Gibbs-like sweeps that update node sets sharing pixels at once (not codings)."""
    coef = reflectance.coefficients(f.scene.model, f.scene.model.to_natural(th[None]))
    rng = np.random.default_rng(seed)
    x, out = f.scene.observed_labels.reshape(-1).copy(), []
    for _ in range(n):
        for nodes in sets:
            logits = -conditional_energies(f, coef, x, nodes)
            x[nodes] = np.argmax(logits + rng.gumbel(size=logits.shape), axis=0)
        out.append(x.copy())
    return np.array(out)


@pytest.mark.parametrize("data_term", ["pixel", "triplet"])
def test_gibbs_matches_brute_force(data_term):
    """2 x 2 pixels, 9 nodes, 2 labels: 512 labellings enumerated.

    Per-node marginals and the mean energy of 2000 consecutive sweeps are compared
    with the exact values; standard errors from 20 batch means of 100 sweeps (the
    draws are correlated; a batch spans 15 to 100 autocorrelation times), threshold
    5 SE (a batch-means t with 19 d.o.f. exceeds 5 with probability 8e-5). The
    same bound rejects the field with the energy's sign flipped, and sweeps over
    node sets that share pixels (the strided sub-lattices of a 3-node-wide
    lattice), so the test has power against both errors.
    """
    sc = make_scene("ward", theta=[0.5, 0.3, 0.2], shape=(2, 2), n_labels=2, seed=3,
                    label_step=1.0)
    th = _theta(sc, 1.0)
    f = label_field(sc, sigma_b=0.03, data_term=data_term, prior="none")
    X = np.array(list(itertools.product(range(2), repeat=9)))
    U = label_energy(f, th, X)

    def exact(sign):
        logp = -sign * U
        p = np.exp(logp - logp.max())
        p /= p.sum()
        return p @ X, p @ U

    draws = simulate_labels(f, th, n=2000, n_sweeps=20, thin=1, seed=11).reshape(2000, 9)
    assert _batch_z(f, th, draws, *exact(1)) < 5
    assert _batch_z(f, th, draws, *exact(-1)) > 5
    wrong = _wrong_sweeps(f, th, 2000, sc.lattice.partition(4, "strided"), seed=11)
    assert _batch_z(f, th, wrong, *exact(1)) > 5


def test_reproducible_shapes_and_start():
    sc = _scene(shape=(3, 4), n_labels=4)
    th = _theta(sc)
    a = simulate_labels(sc, th, n=3, n_sweeps=2, thin=1, seed=7)
    b = simulate_labels(sc, th, n=3, n_sweeps=2, thin=1, seed=7)
    c = simulate_labels(sc, th, n=3, n_sweeps=2, thin=1, seed=8)
    assert a.shape == (3, 4, 5) and a.dtype == np.int64
    assert a.min() >= 0 and a.max() < 4
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    first = simulate_labels(sc, th, n=2, n_sweeps=0, thin=1, seed=7)
    np.testing.assert_array_equal(first[0], sc.observed_labels)  # no sweep: the start
    np.testing.assert_array_equal(simulate_labels(sc, th, n=1, n_sweeps=1, seed=7)[0],
                                  first[1])  # draw k is the state after n_sweeps + k thin
    r = simulate_labels(sc, th, n=1, n_sweeps=0, seed=4, init="random")
    assert not np.array_equal(r[0], sc.observed_labels)
    # labels a prior forbids are never drawn
    beliefs = np.array(sc.beliefs)
    beliefs[..., 0] = 0.0
    sc0 = dataclasses.replace(sc, beliefs=beliefs / beliefs.sum(axis=2, keepdims=True))
    d = simulate_labels(sc0, th, n=4, n_sweeps=1, thin=1, seed=1, prior="beliefs")
    assert d.min() >= 1


def test_model_simulate_is_the_label_simulator():
    sc = _scene(shape=(2, 2))
    th = _theta(sc)
    m = get("brdf")
    np.testing.assert_array_equal(
        m.simulate(th, sc, n=2, seed=3, n_sweeps=3, thin=2, prior="range"),
        simulate_labels(sc, th, n=2, seed=3, n_sweeps=3, thin=2, prior="range"))
    assert DEFAULT_SWEEPS >= 10


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"n": 0}, "n must be an integer >= 1"),
    ({"n_sweeps": -1}, "n_sweeps must be an integer >= 0"),
    ({"thin": 0}, "thin must be an integer >= 1"),
    ({"init": "data"}, "init must be one of"),
    ({"init": np.zeros((2, 2), int)}, "init must have shape"),
    ({"data_term": "pixels"}, "data_term must be one of"),
    ({"prior": "flat"}, "prior must be one of"),
    ({"sigma_b": 0.0}, "sigma_b must lie in"),
    ({"temperature": -1.0}, "temperature must lie in"),
    ({"seed": "x"}, "seed"),
    ({"progress": 1}, "progress must be True or False"),
])
def test_validation(kwargs, match):
    sc = _scene(shape=(2, 2))
    with pytest.raises(ValueError, match=match):
        simulate_labels(sc, _theta(sc), **kwargs)


def test_validation_of_theta_labels_and_scene():
    sc = _scene(shape=(2, 2))
    with pytest.raises(ValueError, match="theta must be 3 finite numbers"):
        simulate_labels(sc, [0.5, 0.5])
    with pytest.raises(ValueError, match="theta must lie in the unit cube"):
        simulate_labels(sc, [0.5, 0.5, 1.5])
    with pytest.raises(ValueError, match="labels must lie in"):
        label_energy(sc, _theta(sc), np.full(9, 3))
    with pytest.raises(ValueError, match=r"scene must be an mrfpe\.brdf\.scene\.Scene"):
        label_energy(np.zeros((2, 2)), _theta(sc), np.zeros(9, int))
    with pytest.raises(ValueError, match="prior='range' needs"):
        simulate_labels(dataclasses.replace(sc, range_prior=None), _theta(sc), prior="range")


def test_likelihood_target_is_the_energy_with_the_simulator():
    sc = _scene(shape=(2, 3))
    th = _theta(sc)
    m = get("brdf")
    lik = m.target("likelihood", sc, sigma_b=SIGMA, prior="range", n_sweeps=3)
    assert lik.normalised is False and lik.n_observations == 1
    u = label_energy(sc, th, sc.observed_labels, sigma_b=SIGMA, prior="range")
    assert lik.log_prob(th)[0] == pytest.approx(-u, rel=1e-12)
    y = lik.simulate(th, seed=4)  # the exchange sampler's auxiliary draw: from the data
    np.testing.assert_array_equal(
        y, simulate_labels(sc, th, 1, n_sweeps=3, seed=4, sigma_b=SIGMA, prior="range"))
    two = np.stack([th, th * 0.5])
    want = [-label_energy(sc, t, y[0], sigma_b=SIGMA, prior="range") for t in two]
    np.testing.assert_allclose(lik.unnormalised(two, y), want, rtol=1e-12)
    assert lik.unnormalised(np.array([[0.5, 0.5, 1.2]]))[0] == -np.inf
    with pytest.raises(ValueError, match="valid options"):
        m.target("likelihood", sc, sigma=1.0)
    with pytest.raises(ValueError, match="scene must be given"):
        m.simulate(th)
    with pytest.raises(ValueError, match="shape must be the scene's image shape"):
        m.simulate(th, sc, shape=(3, 3))
