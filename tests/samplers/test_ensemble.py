"""emcee's affine-invariant ensemble on the batched target."""

import json

import numpy as np
import pytest
from scipy import stats

from mrfpe import posterior as P
from mrfpe.posterior import validate
from mrfpe.samplers.ensemble import EmceeEnsemble
from mrfpe.targets.base import Target
from mrfpe.testing import MostlyMinusInf, box_gaussian


class BetaPair(Target):
    """Independent Beta(2, 5) × Beta(3, 3); records the batch sizes it is called with."""

    param_names = ("p", "q")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])

    def __init__(self):
        self.batches: list[int] = []

    def log_prob(self, theta):
        self.batches.append(np.shape(theta)[0])
        return super().log_prob(theta)

    def _log_prob(self, theta):
        p, q = theta[:, 0], theta[:, 1]  # both normalisers are 1/30
        with np.errstate(divide="ignore"):
            return (np.log(p) + 4 * np.log1p(-p) + 2 * np.log(q) + 2 * np.log1p(-q)
                    + 2 * np.log(30.0))


def test_samples_the_target_vectorised():
    target = BetaPair()
    post = EmceeEnsemble(n_walkers=16, n_steps=800, burn_in=200).run(target, seed=0)
    validate(post)
    x = post["theta"].values
    assert x.shape == (600 * 16, 2)
    for j, dist in enumerate((stats.beta(2, 5), stats.beta(3, 3))):
        assert abs(x[:, j].mean() - dist.mean()) < 0.1 * dist.std()
        assert abs(x[:, j].std() / dist.std() - 1) < 0.1
    # vectorize=True: each stretch update evaluates a half-ensemble in one call
    assert set(target.batches[-10:]) == {8}
    assert post.attrs["n_target_evals"] == sum(target.batches)
    acc = post["acceptance"].values
    assert np.all((acc >= 0) & (acc <= 1)) and 0.2 < acc[200:].mean() < 0.9
    assert np.all(np.isfinite(post["autocorr_time"].values))


def test_reproducible_without_global_state():
    state = np.random.get_state()  # noqa: NPY002 - the legacy global state on purpose
    a = EmceeEnsemble(n_steps=60, burn_in=10).run(BetaPair(), seed=3)
    np.random.seed(123)  # noqa: NPY002 - emcee's generator must not depend on numpy's global one
    b = EmceeEnsemble(n_steps=60, burn_in=10).run(BetaPair(), seed=3)
    c = EmceeEnsemble(n_steps=60, burn_in=10).run(BetaPair(), seed=4)
    np.testing.assert_array_equal(a["theta"].values, b["theta"].values)
    assert not np.array_equal(a["theta"].values, c["theta"].values)
    np.random.set_state(state)  # noqa: NPY002


def test_bounds_and_support():
    post = EmceeEnsemble(n_steps=100, burn_in=20).run(MostlyMinusInf(), seed=0)
    x = post["theta"].values
    box = MostlyMinusInf.box
    # walkers start inside the support and never leave it
    assert np.all((x >= box[:, 0]) & (x <= box[:, 1]))
    assert np.all(np.isfinite(post["log_target"].values))


def test_trace_and_thinning():
    post = EmceeEnsemble(n_walkers=8, n_steps=50, burn_in=10, thin=5).run(BetaPair(), seed=1)
    assert post.sizes["sample"] == 8 * 8 and post.sizes["step"] == 50
    ml = post["map_log_target"].values
    assert np.all(np.diff(ml) >= 0) and ml[-1] >= post["log_target"].values.max()


@pytest.mark.parametrize(("kw", "match"), [
    ({"n_walkers": 7}, "even"), ({"n_walkers": 2}, "n_walkers"), ({"burn_in": 625}, "burn_in"),
    ({"stretch_scale": 1.0}, "stretch_scale"), ({"thin": 0}, "thin"),
])
def test_bad_config(kw, match):
    with pytest.raises(ValueError, match=match):
        EmceeEnsemble(**kw)


def test_too_few_walkers_for_dimension():
    class Wide(BetaPair):
        param_names = ("a", "b", "c", "d")
        bounds = np.array([[0.0, 1.0]] * 4)

        def _log_prob(self, theta):
            return -np.sum(theta**2, axis=1)

    with pytest.raises(ValueError, match="2\\*d"):
        EmceeEnsemble(n_walkers=8).run(Wide(), seed=0)


# --- reliability: an ensemble is judged by its integrated autocorrelation time ---------
# Goodman & Weare (2010) measure an affine-invariant ensemble by τ; emcee's documentation
# (Foreman-Mackey et al. 2013) trusts τ — and the ESS n_walkers × n_kept / τ — only from a
# chain of about 50 τ on. The expected values below come from emcee itself, on the same
# draws, not from mrfpe's diagnostics.


def _independent_tau(post):
    """τ per parameter from emcee.autocorr.integrated_time on the stored draws, arranged
    (kept step, walker, param) straight from their step-major order."""
    import emcee

    n_walkers = json.loads(post.attrs["config"])["n_walkers"]
    x = post["theta"].values.reshape(-1, n_walkers, post.sizes["param"])
    return emcee.autocorr.integrated_time(x, tol=0), x.shape[0], n_walkers


def _moments(post, target):
    err = np.abs(P.weighted_mean(post) - target.mean) / target.sd
    ratio = np.sqrt(np.diag(P.weighted_cov(post))) / target.sd
    return err.max(), ratio.min(), ratio.max()


@pytest.mark.slow
def test_a_10d_gaussian_run_of_50_tau_reads_reliable_and_is_accurate(caplog):
    t = box_gaussian(10)  # AR(1) correlation 0.7: the stretch move's τ is ~125 steps
    with caplog.at_level("WARNING", logger="emcee"):
        post = EmceeEnsemble(n_steps=10000, burn_in=1500).run(t, seed=0)
    assert not [r for r in caplog.records if r.name.startswith("emcee")]  # quiet handled
    tau, k, w = _independent_tau(post)
    d = P.diagnose(post)
    assert k == 8500 and k >= 50 * tau.max()
    assert d["tau"] == pytest.approx(tau.max(), rel=1e-12)
    np.testing.assert_allclose(post["autocorr_time"].values, tau, rtol=1e-12)
    assert d["ess"] == pytest.approx(w * k / tau.max(), rel=1e-12) == post.attrs["diag_ess"]
    assert d["reliable"] and post.attrs["diag_reliable"] == 1 and d["messages"] == []
    assert np.isfinite(post.attrs["diag_rhat"])  # R̂ across walkers: reported, not decisive
    err, lo, hi = _moments(post, t)
    assert err < 4 / np.sqrt(d["ess"]) + 0.05 and 0.9 < lo and hi < 1.1, (err, lo, hi)


def test_the_default_run_in_10d_is_too_short_for_its_tau_and_says_so():
    post = EmceeEnsemble().run(box_gaussian(10), seed=0)  # 32 × 625, burn-in 125
    tau, k, w = _independent_tau(post)
    assert k == 500 and k < 50 * tau.max()
    d = P.diagnose(post)
    assert not d["reliable"] and d["tau"] == pytest.approx(tau.max(), rel=1e-12)
    assert d["ess"] == pytest.approx(w * k / tau.max(), rel=1e-12)
    text = post.attrs["diag_messages"]
    assert f"chain of 500 steps is shorter than 50 × τ = {50 * tau.max():.0f}" in text, text
    assert "n_steps=625 →" in text and "R̂" not in text, text


def test_a_100_step_run_reads_unreliable_with_the_tau_reason():
    with pytest.warns(P.PosteriorWarning, match="chain of 80 steps is shorter than 50 × τ"):
        post = EmceeEnsemble(n_steps=100, burn_in=20).run(box_gaussian(10), seed=0)
    tau, k, _ = _independent_tau(post)
    assert k == 80 and not post.attrs["diag_reliable"]
    assert f"50 × τ = {50 * tau.max():.0f} (τ = {tau.max():.1f} steps" in \
        post.attrs["diag_messages"]
    assert "n_steps=100 →" in post.attrs["diag_messages"]


def test_the_ess_trace_ends_at_the_ensemble_ess():
    post = EmceeEnsemble(n_walkers=16, n_steps=400, burn_in=100, thin=2).run(BetaPair(),
                                                                              seed=2)
    tau, k, w = _independent_tau(post)  # τ in kept (thinned) steps
    e = post["ess"].values
    last = e[np.isfinite(e)][-1]
    assert last == pytest.approx(w * k / max(tau.max(), 1.0), rel=1e-9)
    assert last == pytest.approx(post.attrs["diag_ess"], rel=1e-9)
    assert post.attrs["chain_type"] == "ensemble"


def test_any_sampler_opts_in_through_kept_states():
    """Not only emcee: KeptStates(..., ensemble=True) marks a sampler's walkers as one
    ensemble; its ESS trace and the posterior's diagnostics then follow τ."""
    from mrfpe.posterior import build
    from mrfpe.samplers.kit import KeptStates

    rng = np.random.default_rng(5)
    kept = KeptStates(700, 100, 1, 12, 2, ensemble=True)
    plain = KeptStates(700, 100, 1, 12, 2)
    x = rng.standard_normal((12, 2))
    for t in range(700):  # AR(1) walkers, τ = 9
        x = 0.8 * x + 0.6 * rng.standard_normal((12, 2))
        kept.record(t, x, np.zeros(12))
        plain.record(t, x, np.zeros(12))
        e = kept.trace_ess(t)
    kw = kept.build_kwargs({"note": "x"})
    assert kw["extra_attrs"] == {"note": "x", "chain_type": "ensemble"}
    assert set(plain.build_kwargs()) == {"chain"}
    np.testing.assert_array_equal(kw["chain"], plain.chain())
    theta, lp, _ = kept.flat()
    post = build(theta, lp, param_names=["a", "b"], sampler="toy", **kw)
    d = P.diagnose(post)
    assert post.attrs["chain_type"] == "ensemble" and np.isfinite(d["tau"])
    assert e == pytest.approx(d["ess"], rel=1e-9)  # the trace's last entry is diagnose's ESS
