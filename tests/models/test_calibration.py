"""Fisher information, MCMC-MLE and the adjusted pseudolikelihood, against exact routes
(variable elimination) on small lattices."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe import models
from mrfpe.models import calibration
from mrfpe.models.calibration import (
    AdjustedPL,
    _step,
    fisher_information,
    hessian,
    mcmc_mle,
    simulate_draws,
)
from mrfpe.posterior import PosteriorWarning, build, weighted_cov, weighted_mean
from mrfpe.targets import maximise
from mrfpe.targets.base import Target


@pytest.fixture(scope="module")
def ising():
    m = models.ising()
    x = m.simulate([0.3, 0.05], shape=(8, 8), seed=1, n_sweeps=300)
    return m, x, m.target("exact", x), m.target("likelihood", x), m.target("pl", x)


def test_fisher_information_is_the_hessian_of_log_z(ising):
    _m, _x, exact, lik, _ = ising
    th = np.array([0.3, 0.1])
    want = hessian(exact.log_partition, th, _step(exact))
    got = fisher_information(lik, simulate_draws(lik, th, 3000, seed=0))
    np.testing.assert_allclose(got, want, rtol=0.15, atol=0.05 * np.abs(want).max())


def test_mcmc_mle_finds_the_exact_mle(ising):
    _m, _x, exact, lik, pl = ising
    mle, _ = maximise(exact)
    res = mcmc_mle(lik, maximise(pl)[0], seed=0)
    assert res.converged
    assert np.all(np.abs(res.theta - mle) < 0.25 * res.se), (res.theta, mle, res.se)


def test_adjusted_pl_peaks_at_the_mle_with_the_fisher_curvature(ising):
    m, x, _exact, _lik, _pl = ising
    adj = m.target("pl_adjusted", x, seed=2, align="mode")
    assert isinstance(adj, AdjustedPL)
    top, _ = maximise(adj)
    np.testing.assert_allclose(top, adj.theta_ml, atol=2e-3)
    H = -hessian(adj._log_prob, adj.theta_ml, _step(adj))
    np.testing.assert_allclose(H, adj.fisher_information, rtol=0.02,
                               atol=0.02 * np.abs(H).max())
    assert adj.log_prob(adj.theta_ml)[0] == pytest.approx(0.0, abs=1e-9)


def test_adjustment_refuses_what_it_cannot_do():
    m = models.ising()
    with pytest.raises(ValueError, match="face"):
        m.target("pl_adjusted", np.zeros((6, 6), dtype=int))  # MPLE at the field's bound
    crf = models.autologistic(["z"])
    x = models.potts(2).simulate([0.4, 0.0], shape=(8, 8), seed=0)
    with pytest.raises(ValueError, match=r"singular|face|Hessian"):
        crf.target("pl_adjusted", x, covariates={"z": np.zeros((8, 8))})
    with pytest.raises(ValueError, match="mode"):
        m.target("pl_adjusted", x, mode="one_step")
    with pytest.raises(ValueError, match="pilot_sweeps"):
        m.target("pl_adjusted", x, pilot_sweeps=100)
    with pytest.raises(ValueError, match="max_rounds"):
        m.target("pl_adjusted", x, max_rounds=0)


class _Ridge(Target):
    """A pseudolikelihood that does not depend on its second parameter: no curvature there."""

    param_names = ("a", "b")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])

    def _log_prob(self, theta):
        return -1e3 * (theta[:, 0] - 0.4) ** 2


def test_a_ridge_is_named_as_a_ridge_not_as_a_face(ising):
    _m, _x, _exact, lik, _pl = ising
    with pytest.raises(ValueError, match=r"not negative definite.*saddle.*ridge"):
        AdjustedPL(_Ridge(), lik, align="mode")  # the mode alignment needs the curvature
    with pytest.raises(ValueError, match=r"face for \['b'\]"):  # the moments see b's spread
        AdjustedPL(_Ridge(), lik)


def test_rounds_and_pilot_reach_the_calibration(ising):
    """One round stops after one batch of draws; a short pilot still measures 50 tau."""
    m, x, _exact, lik, _pl = ising
    adj = m.target("pl_adjusted", x, seed=2, max_rounds=1, pilot_sweeps=250)
    assert adj.mle.n_iterations == 1
    d = simulate_draws(lik, adj.theta_pl, 20, seed=0, pilot_sweeps=250)
    assert d.burn_in >= 10 * d.tau


def test_moment_alignment_has_the_mean_and_covariance_it_promises(ising):
    m, x, exact, _, _ = ising
    adj = m.target("pl_adjusted", x, seed=2)  # align="moments"
    sd = np.sqrt(np.diag(np.linalg.inv(adj.fisher_information)))
    g = [np.linspace(c - 7 * s, c + 7 * s, 141) for c, s in zip(adj.theta_ml, sd, strict=True)]
    G = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 2)
    lp = adj.log_prob(G)
    w = np.exp(lp - lp.max())
    w /= w.sum()
    mean = w @ G
    cov = (G - mean).T @ ((G - mean) * w[:, None])
    np.testing.assert_allclose(mean, adj.theta_ml, atol=0.05 * sd.min())
    np.testing.assert_allclose(cov, np.linalg.inv(adj.fisher_information), rtol=0.1,
                               atol=0.1 * sd.min() ** 2)
    # and it sits closer to the exact posterior's mean than the mode alignment does
    e = exact.log_prob(G)
    we = np.exp(e - e.max())
    we /= we.sum()
    exact_mean = we @ G
    mode = m.target("pl_adjusted", x, seed=2, align="mode")
    lm = mode.log_prob(G)
    wm = np.exp(lm - lm.max())
    wm /= wm.sum()
    assert np.max(np.abs(mean - exact_mean) / sd) <= np.max(np.abs(wm @ G - exact_mean) / sd)


def test_mcmc_mle_does_not_jump_between_phases_near_the_critical_coupling():
    """A 10 x 10 Ising data set at the critical coupling whose MPLE (0.53, -0.08) lies in the
    ordered phase: undamped, the draws' phase flips each round and the iterate reaches the
    box's face (singular information); with the PL-metric step limit it reaches the exact MLE."""
    m = models.ising()
    x = m.simulate([0.44, 0.0], shape=(10, 10), seed=6537214486005296316, n_sweeps=1000)
    mle, _ = maximise(m.target("exact", x))
    pl = m.target("pl", x)
    mple, _ = maximise(pl)
    H = -hessian(pl._log_prob, mple, _step(pl, mple))
    seed = int(np.random.default_rng(1241352075385643944).integers(2**63))  # AdjustedPL's
    res = mcmc_mle(m.target("likelihood", x), mple, seed=seed, metric=H)
    assert res.converged
    assert np.all(np.abs(res.theta - mle) < 0.3 * res.se), (res.theta, mle, res.se)
    with pytest.raises(ValueError, match="singular"):  # the failure the limit prevents
        mcmc_mle(m.target("likelihood", x), mple, seed=seed)
    adj = m.target("pl_adjusted", x, seed=1241352075385643944)  # builds, on the MLE
    assert np.all(np.abs(adj.mle.theta - mle) < 0.3 * adj.mle.se)


def test_the_adjusted_target_has_no_density_where_its_map_leaves_the_pl_box(ising):
    """exp(PL) lives on its box: a parameter mapped outside it is -inf, not the PL's
    formula extrapolated (which on a BRDF scene can exceed the PL's maximum)."""
    m, x, _exact, _lik, pl = ising
    adj = m.target("pl_adjusted", x, seed=2)
    b = pl.bounds
    G = np.stack(np.meshgrid(*[np.linspace(lo, hi, 41) for lo, hi in b], indexing="ij"),
                 -1).reshape(-1, 2)
    z = adj.to_pl(G)
    outside = ~pl.in_bounds(z)
    assert outside.any() and (~outside).any()
    lp = adj._log_prob(G)
    assert np.all(lp[outside] == -np.inf)
    np.testing.assert_array_equal(lp[~outside], pl._log_prob(z[~outside]) - adj._offset)
    # its bounds are the smallest box holding the rest: inside the PL's, and tight
    inner = G[~outside]
    assert np.all(adj.bounds[:, 0] >= b[:, 0]) and np.all(adj.bounds[:, 1] <= b[:, 1])
    assert np.all(adj.in_bounds(inner))
    # second route: the images of the PL box's corners span the bounding box
    corners = np.array([[b[0, i], b[1, j]] for i in (0, 1) for j in (0, 1)])
    images = adj.theta_ml + (corners - adj.centre) @ np.linalg.inv(adj.W).T
    want = np.stack([np.maximum(images.min(0), b[:, 0]), np.minimum(images.max(0), b[:, 1])], 1)
    np.testing.assert_allclose(adj.bounds, want, rtol=1e-12, atol=1e-12)


def test_a_restored_calibration_is_the_same_target(ising):
    m, x, _exact, _lik, pl = ising
    adj = m.target("pl_adjusted", x, seed=2)
    d = adj.describe()
    again = AdjustedPL.restore(pl, centre=d["centre"], W=d["W"], theta_ml=d["theta_mode"],
                               theta_pl=d["theta_mple"])
    G = adj.theta_ml + np.random.default_rng(0).normal(0.0, 0.2, (200, 2))
    np.testing.assert_array_equal(again.log_prob(G), adj.log_prob(G))
    assert again.fisher_information is None and again.param_names == adj.param_names


def test_a_sample_of_exp_pl_gives_the_moments_it_calibrates(ising, tmp_path):
    m, x, _exact, _lik, pl = ising
    post = mrfpe.sample("pmc", pl, seed=0, n_samples=2000)
    adj = m.target("pl_adjusted", x, seed=2, pl_sample=post)
    np.testing.assert_array_equal(adj.centre, weighted_mean(post))
    np.testing.assert_array_equal(adj.pl_covariance, weighted_cov(post))
    assert adj.describe()["pl_moments_from"] == "sample"
    path = tmp_path / "pl.nc"
    mrfpe.posterior.save(post, path)  # or the file a sampler's result was saved to
    again = m.target("pl_adjusted", x, seed=2, pl_sample=str(path))
    np.testing.assert_array_equal(again.centre, adj.centre)
    np.testing.assert_array_equal(again.W, adj.W)
    # on this unimodal exp(PL) the importance sampler from the MPLE agrees with it
    own = m.target("pl_adjusted", x, seed=2)
    assert own.describe()["pl_moments_from"] == "importance"
    sd = np.sqrt(np.diag(own.pl_covariance))
    assert np.all(np.abs(adj.centre - own.centre) < 0.1 * sd)
    np.testing.assert_allclose(np.sqrt(np.diag(adj.pl_covariance)), sd, rtol=0.1)


def test_a_sample_it_cannot_trust_is_refused_before_any_work(ising, monkeypatch):
    m, x, _exact, _lik, pl = ising
    post = mrfpe.sample("pmc", pl, seed=0, n_samples=2000)
    # sixty draws whose sampler called them reliable: too few for a covariance all the same
    with pytest.warns(PosteriorWarning):
        few = build(post["theta"].values[:60], post["log_target"].values[:60],
                    param_names=pl.param_names, sampler="test", target=pl)
    few = few.assign_attrs(diag_reliable=1, diag_messages="")

    def no_work(*args, **kwargs):
        raise AssertionError("the PL was maximised before the sample was checked")

    monkeypatch.setattr(calibration, "maximise", no_work)
    other = m.simulate([0.3, 0.05], shape=(8, 8), seed=2, n_sweeps=300)
    bad = {
        "not a sample of this PL": (other, post),
        "unreliable": (x, post.assign_attrs(diag_reliable=0, diag_messages="ESS 3 < 100")),
        "kind 'draws'": (x, post.assign_attrs(kind="optima")),
        r"Kish ESS of \d+, below the 100": (x, few),
        "must be over the PL's parameters": (x, post.assign_coords(param=["a", "b"])),
        "must be a posterior Dataset": (x, weighted_mean(post)),
        "no posterior file at": (x, "no/such/file.nc"),
    }
    for message, (data, sample) in bad.items():
        with pytest.raises(ValueError, match=f"pl_sample.*{message}|{message}.*"):
            m.target("pl_adjusted", data, pl_sample=sample, pilot_sweeps=250, n_draws=10)


def _spd(rng, d):
    a = rng.normal(size=(d, d))
    return a @ a.T + d * np.eye(d)


@pytest.mark.parametrize("d", [1, 2, 4])
def test_the_transport_map_is_the_symmetric_root(d):
    from scipy.linalg import sqrtm

    rng = np.random.default_rng(d)
    S, D = _spd(rng, d), _spd(rng, d)
    T = calibration.transport_map(S, D)
    np.testing.assert_allclose(T, T.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(T) > 0)
    np.testing.assert_allclose(T @ S @ T, D, rtol=1e-10, atol=1e-10)
    # a second route: scipy's general square root of the same formula
    Sh = np.real(sqrtm(S))
    Shi = np.linalg.inv(Sh)
    np.testing.assert_allclose(T, Shi @ np.real(sqrtm(Sh @ D @ Sh)) @ Shi, rtol=1e-8)
    # it is its own inverse's inverse, and it does not depend on the parameters' order
    np.testing.assert_allclose(calibration.transport_map(D, S), np.linalg.inv(T), rtol=1e-8)
    P = np.eye(d)[rng.permutation(d)]
    np.testing.assert_allclose(calibration.transport_map(P @ S @ P.T, P @ D @ P.T),
                               P @ T @ P.T, rtol=1e-8, atol=1e-12)


def test_diagonal_spreads_give_the_ratio_of_their_sds():
    T = calibration.transport_map(np.diag([4.0, 0.25]), np.diag([1.0, 1.0]))
    np.testing.assert_allclose(T, np.diag([0.5, 2.0]))


@pytest.mark.parametrize("align", ["moments", "mode"])
def test_both_affine_maps_meet_the_alignment(ising, align):
    m, x, *_ = ising
    chol = m.target("pl_adjusted", x, seed=2, align=align)
    sym = m.target("pl_adjusted", x, seed=2, align=align, affine="transport")
    assert sym.describe()["affine"] == "transport" and chol.describe()["affine"] == "cholesky"
    np.testing.assert_allclose(sym.W, sym.W.T, atol=1e-12)
    np.testing.assert_array_equal(sym.theta_ml, chol.theta_ml)  # same simulations
    info = chol.fisher_information
    for adj in (chol, sym):
        A = np.linalg.inv(adj.W)
        if align == "moments":  # the covariance the PL's maps onto is I⁻¹
            np.testing.assert_allclose(A @ adj.pl_covariance @ A.T, np.linalg.inv(info),
                                       rtol=1e-8)
        else:  # the Hessian at the mode is the Fisher information
            np.testing.assert_allclose(adj.W.T @ adj.pl_hessian @ adj.W, info, rtol=1e-8)
    with pytest.raises(ValueError, match="affine"):
        m.target("pl_adjusted", x, affine="qr")
