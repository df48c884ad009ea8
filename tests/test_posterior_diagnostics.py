"""mrfpe.posterior.diagnose against closed forms: AR(1) chains (ESS = S (1-ρ)/(1+ρ)),
shifted chains (R̂), Gaussian importance weights (Pareto k = 1 - σ_q²/σ_p²), Kish's ESS."""

import numpy as np
import pytest

from mrfpe import posterior as P
from mrfpe.posterior.diagnostics import ESS_MIN, RHAT_MAX, pareto_k_threshold


def _post(theta, log_weight=None, **kw):
    theta = np.asarray(theta, float).reshape(len(theta), -1)
    with pytest.warns(P.PosteriorWarning) if kw.pop("unreliable", False) else _nothing():
        return P.build(theta, np.zeros(len(theta)), param_names=[f"p{j}" for j in
                       range(theta.shape[1])], log_weight=log_weight, sampler="t", **kw)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _ar1(n_chains, n_draws, rho, rng, d=2):
    x = np.empty((n_draws, n_chains, d))
    x[0] = rng.standard_normal((n_chains, d))
    for t in range(1, n_draws):
        x[t] = rho * x[t - 1] + np.sqrt(1 - rho**2) * rng.standard_normal((n_chains, d))
    # stored as MCMC samplers store them: step-major, chains interleaved
    return x.reshape(-1, d), np.tile(np.arange(n_chains), n_draws)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_chain_ess_matches_ar1_closed_form(rho):
    rng = np.random.default_rng(0)
    theta, chain = _ar1(4, 2000, rho, rng)
    d = P.diagnose(_post(theta, chain=chain))
    expect = theta.shape[0] * (1 - rho) / (1 + rho)
    assert d["n_chains"] == 4
    assert 0.75 * expect < d["ess_chain"] < 1.25 * expect
    assert d["ess"] == d["ess_chain"]  # equal weights: the chain ESS is the ESS
    assert d["ess_kish"] == pytest.approx(theta.shape[0])
    assert d["rhat"] < RHAT_MAX and d["reliable"]
    # independent route: emcee's integrated autocorrelation time
    import emcee

    tau = emcee.autocorr.integrated_time(theta.reshape(2000, 4, 2), tol=0)
    assert 0.75 < d["ess_chain"] / (theta.shape[0] / tau.max()) < 1.33


def test_without_chain_the_ess_is_kish_and_autocorrelation_is_invisible():
    theta, _ = _ar1(1, 4000, 0.9, np.random.default_rng(1))
    d = P.diagnose(_post(theta))
    assert d["n_chains"] == 0 and np.isnan(d["ess_chain"]) and np.isnan(d["rhat"])
    assert d["ess"] == pytest.approx(4000)  # documented: pass chain= for MCMC


def test_rhat_flags_chains_that_disagree():
    rng = np.random.default_rng(2)
    theta, chain = _ar1(4, 1000, 0.5, rng)
    theta[chain == 3] += 1.0  # one chain in another place
    d = P.diagnose(_post(theta, chain=chain, unreliable=True))
    assert d["rhat"] > 1.1 and not d["reliable"]
    assert any("R̂" in m and "longer chains" in m for m in d["messages"])


def test_short_chains_ask_for_longer_chains():
    theta, chain = _ar1(2, 60, 0.9, np.random.default_rng(3))
    d = P.diagnose(_post(theta, chain=chain, unreliable=True))
    assert d["ess"] < ESS_MIN
    assert any("run longer chains" in m for m in d["messages"])


@pytest.mark.filterwarnings("ignore::mrfpe.posterior.PosteriorWarning")
@pytest.mark.parametrize("sd_q", [0.5, 0.8])
def test_pareto_k_of_gaussian_importance_weights(sd_q):
    # draws from N(0, sd_q²) weighted to N(0, 1): the weight tail has k = 1 - sd_q²
    rng = np.random.default_rng(4)
    x = rng.normal(0, sd_q, 20000)
    lw = -0.5 * x**2 + 0.5 * (x / sd_q) ** 2
    d = P.diagnose(_post(x, lw))
    assert d["pareto_k"] == pytest.approx(1 - sd_q**2, abs=0.1)
    assert d["ess"] == pytest.approx(P.ess(lw)) == d["ess_kish"]
    assert d["reliable"] == (d["pareto_k"] <= 0.7 and d["ess"] >= ESS_MIN)
    if not d["reliable"]:
        assert any("Pareto k̂" in m and "soften" in m for m in d["messages"])


def test_pareto_k_of_classic_pareto_weights():
    rng = np.random.default_rng(5)
    for a in (1.25, 2.5):  # classic Pareto(a) weights: k = 1/a
        w = rng.pareto(a, 10000) + 1.0
        post = _post(rng.random(10000), np.log(w), unreliable=a < 1.4)
        assert P.diagnose(post)["pareto_k"] == pytest.approx(1 / a, abs=0.1)


def test_equal_positive_weights_have_no_pareto_k():
    lw = np.where(np.arange(300) % 3 == 0, -np.inf, 0.0)  # zeros and equal positives
    d = P.diagnose(_post(np.random.default_rng(6).random(300), lw))
    assert np.isnan(d["pareto_k"]) and d["ess"] == pytest.approx(200)


def test_weighted_chains_multiply_the_efficiencies():
    rng = np.random.default_rng(7)
    theta, chain = _ar1(4, 1000, 0.5, rng)
    lw = rng.normal(0, 0.5, theta.shape[0])
    d = P.diagnose(_post(theta, lw, chain=chain))
    assert d["ess"] == pytest.approx(d["ess_chain"] * d["ess_kish"] / theta.shape[0])


def test_threshold_and_input_errors():
    assert pareto_k_threshold(100) == pytest.approx(0.5)
    assert pareto_k_threshold(10**4) == 0.7 and pareto_k_threshold(5) == 0.0
    with pytest.raises(ValueError, match="post must be a posterior"):
        P.diagnose({})
    post = _post(np.random.default_rng(8).random(200))
    with pytest.raises(ValueError, match="kind"):
        P.diagnose(post.assign_attrs(kind="other"))
    with pytest.raises(ValueError, match="zero total weight"):
        P.diagnose(post.assign(log_weight=post["log_weight"] * 0 - np.inf))


def test_diagnostics_round_trip_through_netcdf(tmp_path):
    import xarray as xr

    theta, chain = _ar1(3, 300, 0.3, np.random.default_rng(9))
    post = _post(theta, chain=chain, log_evidence=-1.25, log_evidence_se=0.5)
    P.save(post, tmp_path / "p.nc")
    back = P.load(tmp_path / "p.nc")
    xr.testing.assert_identical(back, post)
    assert back["chain"].dtype == np.int64
    assert back.attrs["diag_reliable"] == 1 and back.attrs["diag_messages"] == ""
    assert back.attrs["kind"] == "draws" and back.attrs["log_evidence"] == -1.25
    P.validate(back)


def test_posterior_warning_points_at_the_callers_line():
    """The warning names the user's call, not a line inside mrfpe (``_caller``)."""
    import warnings

    import mrfpe
    from mrfpe.testing import CorrelatedGaussian

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        mrfpe.sample("pmc", CorrelatedGaussian(), seed=0, n_samples=20, n_iterations=2)
    hits = [w for w in rec if issubclass(w.category, mrfpe.PosteriorWarning)]
    assert hits and all(w.filename == __file__ for w in hits)


def test_a_declared_bias_is_unreliable_whatever_the_ess():
    import warnings

    import mrfpe
    from mrfpe.posterior import PosteriorWarning, build
    from mrfpe.testing import box_gaussian

    rng = np.random.default_rng(0)
    theta = rng.random((500, 2))
    with pytest.raises(ValueError, match="bias must be a non-empty string"):
        build(theta, np.zeros(500), param_names=["a", "b"], sampler="x", bias="")
    with pytest.warns(PosteriorWarning, match="known bias: ignores the proposal"):
        post = build(theta, np.zeros(500), param_names=["a", "b"], sampler="x",
                     bias="ignores the proposal")
    assert post.attrs["diag_ess"] == pytest.approx(500) and not post.attrs["diag_reliable"]
    assert post.attrs["bias"] == "ignores the proposal"
    # SIR's thesis weights declare theirs; the default mixture weights do not
    t = box_gaussian(3)
    with pytest.warns(PosteriorWarning, match="known bias: weights='thesis'"):
        mrfpe.sample("sir", t, seed=0, n_samples=300, n_iterations=3, weights="thesis")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        assert "bias" not in mrfpe.sample("sir", t, seed=0, n_samples=300,
                                          n_iterations=3).attrs


# --- ensembles: judged by the integrated autocorrelation time, not by R̂ ---------------
# Goodman & Weare (2010); emcee's documentation (Foreman-Mackey et al. 2013) trusts τ from a
# chain of about 50 τ on. Any sampler opts in with chain_type="ensemble"; the expected τ
# comes from emcee.autocorr.integrated_time on the same draws.


def _ensemble(x, unreliable=False, **kw):
    """A posterior of walkers x (draw, walker, param), stored step-major as samplers do."""
    k, c, d = x.shape
    return _post(x.reshape(-1, d), chain=np.tile(np.arange(c), k), unreliable=unreliable,
                 extra_attrs={"chain_type": "ensemble"}, **kw)


def _ar1_walkers(n_walkers, n_draws, rho, seed, d=2):
    theta, _ = _ar1(n_walkers, n_draws, rho, np.random.default_rng(seed), d)
    return theta.reshape(n_draws, n_walkers, d)


def test_an_ensemble_of_50_tau_is_reliable_where_r_hat_across_walkers_is_not():
    import emcee

    x = _ar1_walkers(32, 1200, 0.9, seed=10)  # τ = (1 + ρ)/(1 − ρ) = 19 draws
    tau = emcee.autocorr.integrated_time(x, tol=0)
    assert 1200 >= 50 * tau.max()
    d = P.diagnose(_ensemble(x))
    assert d["reliable"] and d["messages"] == []
    assert d["tau"] == pytest.approx(tau.max(), rel=1e-12) and 15 < d["tau"] < 23
    assert d["ess"] == pytest.approx(32 * 1200 / tau.max(), rel=1e-12)
    assert np.isfinite(d["ess_chain"]) and np.isfinite(d["rhat"])  # reported for comparison
    # the same draws read as 32 independent chains: R̂ across them fails
    d_ind = P.diagnose(_post(x.reshape(-1, 2), chain=np.tile(np.arange(32), 1200),
                             unreliable=True))
    assert d_ind["rhat"] > RHAT_MAX and not d_ind["reliable"] and np.isnan(d_ind["tau"])


def test_an_ensemble_shorter_than_50_tau_says_so():
    import emcee

    x = _ar1_walkers(32, 300, 0.9, seed=11)
    tau = emcee.autocorr.integrated_time(x, tol=0).max()
    d = P.diagnose(_ensemble(x, unreliable=True, config={"n_steps": 400, "burn_in": 100}))
    assert not d["reliable"] and d["tau"] == pytest.approx(tau, rel=1e-12)
    (msg,) = d["messages"]
    assert msg.startswith(f"chain of 300 steps is shorter than 50 × τ = {50 * tau:.0f} "
                          f"(τ = {tau:.1f} steps"), msg
    assert "n_steps=400 →" in msg


def test_a_drifting_ensemble_is_too_short_for_its_tau():
    x = _ar1_walkers(32, 1200, 0.9, seed=10)  # reliable as it is (the test above)
    x = x + np.linspace(0.0, 1.0, 1200)[:, None, None]  # the whole ensemble moves 1 sd
    d = P.diagnose(_ensemble(x, unreliable=True))
    assert not d["reliable"] and d["tau"] > 24 and "shorter than 50 × τ" in d["messages"][0]


def test_an_ensemble_with_a_walker_that_never_moved_has_no_tau():
    x = _ar1_walkers(16, 2000, 0.5, seed=12)
    x[:, 3] = x[0, 3]  # walker 3 stuck where it started
    d = P.diagnose(_ensemble(x, unreliable=True))
    assert np.isnan(d["tau"]) and not d["reliable"]
    assert "cannot be estimated" in " ".join(d["messages"])
    assert d["ess"] == pytest.approx(d["ess_chain"])  # ArviZ's, where τ has no value


def test_ensemble_autocorr_time_is_emcees_with_its_own_tolerance():
    import emcee

    from mrfpe.posterior.diagnostics import ENSEMBLE_TAU_MULTIPLE, ensemble_autocorr_time

    x = _ar1_walkers(8, 400, 0.9, seed=13)  # τ ≈ 19: 50 τ > 400 draws
    tau, ok = ensemble_autocorr_time(x.transpose(1, 0, 2))
    np.testing.assert_array_equal(tau, emcee.autocorr.integrated_time(x, tol=0))
    with pytest.raises(emcee.autocorr.AutocorrError):
        emcee.autocorr.integrated_time(x, tol=ENSEMBLE_TAU_MULTIPLE)
    assert not ok
    assert ensemble_autocorr_time(x.transpose(1, 0, 2), tol=0.9 * 400 / tau.max())[1]
