"""The auto-normal model's data-driven precision box, its codings' identifiability, and the
parametric bootstrap's refits judged against their own boxes."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

import mrfpe
from mrfpe import models
from mrfpe.models import bootstrap
from mrfpe.models.gaussian.bounds import min_conditional_rss
from mrfpe.models.graph import from_networkx
from mrfpe.targets import maximise


@pytest.mark.parametrize("seed", range(4))
def test_a_default_box_scales_with_the_data(seed):
    """Property: fields a x + b (a != 0) get the box of x moved and scaled as the parameters
    are -- the mean's by a x + b, the couplings' unchanged, the precision's divided by a^2,
    a covariate's coefficient by a -- whatever the data's scale."""
    rng = np.random.default_rng(seed)
    m = models.autonormal(4, covariates=1)
    z = rng.normal(size=(9, 11))
    x = m.simulate([1.0, 0.15, 2.0, 0.5], shape=(9, 11), n=2, seed=seed, covariates=z)
    a, b = 10.0 ** rng.uniform(-4, 4), rng.normal() * 100
    one, two = m.default_bounds(x, z), m.default_bounds(a * x + b, z)
    np.testing.assert_allclose(two[0], a * one[0] + b, rtol=1e-9, atol=1e-9 * abs(b))
    np.testing.assert_allclose(two[1], one[1], rtol=1e-12)
    np.testing.assert_allclose(two[2], one[2] / a**2, rtol=1e-7)
    np.testing.assert_allclose(two[3], a * one[3], rtol=1e-9)


CASES = [((1.0, 0.2, 2.0), (16, 16), 1), ((0.0, 0.245, 1.0), (20, 20), 1),
         ((5.0, -0.2, 50.0), (8, 8), 3), ((0.0, 0.0, 1e-3), (12, 12), 1)]


@pytest.mark.parametrize(("theta", "shape", "M"), CASES)
def test_every_estimators_maximum_and_spread_lie_inside_the_box(theta, shape, M):
    """The box holds the PL's maximum, the exact MLE and each coding's maximum, each more
    than five of its curvature's sds below the precision's upper face -- also near the PD
    edge (coupling 0.245) and at precisions of 1e-3 and 50."""
    m = models.autonormal(4)
    y = m.simulate(list(theta), shape=shape, n=M, seed=3)
    box = m.default_bounds(y)
    targets = [m.target("pl", y), m.target("exact", y)] + [
        m.target("coding", y, coding=k) for k in range(m.n_codings(shape))]
    for t in targets:
        th, _ = maximise(t)
        tau = th[2]
        n = t.n_terms if hasattr(t, "n_terms") else y.size
        assert box[2, 1] - tau > 5 * tau * np.sqrt(2.0 / n), (t.name, tau, box[2])
    # the PL's maximum of the precision is n / min RSS, the bound's tau_PL
    pl = m.target("pl", y)
    th, _ = maximise(pl)
    st = m.structure(shape)
    np.testing.assert_allclose(th[2], y.size / min_conditional_rss(st, y.reshape(M, -1),
                                                                  np.zeros((st.n, 0))),
                               rtol=1e-4)


def test_pmc_on_the_calibrated_pl_is_right_with_the_default_box():
    """With the former box (0, 1e4 / var) PMC on pl_adjusted returned sd 1e-4 at the wrong
    mean; with the data's box it agrees with the exact posterior."""
    m = models.autonormal(4)
    y = m.simulate([1, 0.2, 2], shape=(16, 16), seed=0)
    exact = m.target("exact", y)
    mle, _ = maximise(exact)
    half = np.array([0.6, 0.12, 1.0])
    g = [np.linspace(c - h, c + h, 61) for c, h in zip(mle, half, strict=True)]
    G = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)
    lp = exact.log_prob(G)
    w = np.exp(lp - lp.max())
    w /= w.sum()
    mean = w @ G
    sd = np.sqrt(w @ (G - mean) ** 2)
    post = mrfpe.sample("pmc", m.target("pl_adjusted", y, seed=0, n_draws=2000), seed=0)
    got = mrfpe.posterior.weighted_mean(post)
    got_sd = np.sqrt(np.diag(mrfpe.posterior.weighted_cov(post)))
    assert post.attrs["diag_reliable"]
    assert np.all(np.abs(got - mean) < 0.2 * sd), (got, mean, sd)
    assert np.all(np.abs(got_sd / sd - 1) < 0.2), got_sd / sd


# ------------------------------------------------------------------------------------------------
# codings on general graphs
# ------------------------------------------------------------------------------------------------
GRAPHS = {
    "gnp": lambda s: nx.gnp_random_graph(120, 0.08, seed=s),
    "barabasi_albert": lambda s: nx.barabasi_albert_graph(150, 4, seed=s),
    "geometric": lambda s: nx.random_geometric_graph(150, 0.15, seed=s),
    "watts_strogatz": lambda s: nx.watts_strogatz_graph(150, 8, 0.2, seed=s),
}


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_colourings_are_proper_and_have_no_class_that_could_be_merged(kind):
    """Property: on random graphs the colouring is proper, no class can be emptied into the
    others, and none is much smaller than the mean (greedy alone gave a Barabasi-Albert
    graph a class of a single node)."""
    for seed in range(3):
        g = from_networkx(GRAPHS[kind](seed))
        c = g.colouring()
        e = g.edges
        assert not np.any(c[e[:, 0]] == c[e[:, 1]])
        sizes = np.bincount(c)
        assert sizes.min() >= 0.8 * sizes.mean(), sizes
        A = g.adjacency().tocsr()
        for k in range(sizes.size):
            members = np.flatnonzero(c == k)
            taken = [set(c[A[v].indices].tolist()) | {k} for v in members]
            assert any(len(t) == sizes.size for t in taken), (kind, seed, k)


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_every_coding_that_builds_identifies_the_parameters(kind):
    """Property: a coding of the auto-normal model on a random graph either has its maximum
    inside the box (the precision well below the face) or is refused, naming the coding."""
    g = from_networkx(GRAPHS[kind](0))
    m = models.autonormal(g)
    y = m.simulate([1.0, 0.5 / max(g.degree().max(), 1), 2.0], n=1, seed=0)
    for k in range(m.n_codings()):
        t = m.target("coding", y, coding=k)
        th, _ = maximise(t)
        assert th[2] < t.bounds[2, 1] * 0.9, (kind, k, th, t.bounds[2])


def test_a_coding_that_cannot_identify_the_parameters_is_refused_naming_it():
    star = nx.star_graph(12)  # the hub alone in one colour, the leaves in the other
    m = models.autonormal(from_networkx(star))
    y = m.simulate([1.0, 0.1, 2.0], n=1, seed=0)
    with pytest.raises(ValueError, match=r"coding 0 \(1 node: \[0\]\) does not identify.*no "
                                         r"residual"):
        m.target("coding", y, coding=0)
    with pytest.raises(ValueError, match=r"coding 1 \(12 nodes.*neighbour sums are all alike"):
        m.target("coding", y, coding=1)
    lonely = models.autonormal(from_networkx(nx.empty_graph(6)))
    with pytest.raises(ValueError, match=r"no neighbours, so it carries no information on "
                                         r"coupling"):
        lonely.target("coding", np.random.default_rng(0).normal(size=(2, 6)), coding=0)
    m.target("pl", y)  # the PL itself is fine


def test_bootstrap_refits_are_judged_against_their_own_boxes(monkeypatch):
    """Each simulated data set of the auto-normal model has its own precision box: a refit on
    its face must be flagged even where the original data's face lies elsewhere."""
    m = models.autonormal(4)
    y = m.simulate([1, 0.1, 2], shape=(10, 10), seed=0)  # no refit near the PD edge
    real = bootstrap.maximise
    calls = []

    def at_the_face(target, **kw):
        theta, value = real(target, **kw)
        calls.append(np.asarray(target.bounds))
        if len(calls) > 1 and len(calls) % 2:  # every other refit: on its own face
            theta = theta.copy()
            theta[2] = target.bounds[2, 1]
            value = float(target.log_prob(theta)[0])
        return theta, value

    monkeypatch.setattr(bootstrap, "maximise", at_the_face)
    boot = bootstrap.parametric_bootstrap(m, y, n_boot=6, seed=0)
    want = np.array([k % 2 == 1 for k in range(2, 8)])
    np.testing.assert_array_equal(boot["on_face"].values, want)
    assert "precision" in boot.attrs["bias"]
    assert not all(np.array_equal(b, calls[0]) for b in calls[1:])  # boxes differ
