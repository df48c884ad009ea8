"""Dynamic weighting (thesis 5.5): the moves of 5.48/5.49, IWIW on a discrete target,
the stabiliser of 5.5.4, and the sampler as a whole."""

import numpy as np
import pytest
from scipy import integrate

from mrfpe import posterior as post_mod
from mrfpe.posterior import validate, weights
from mrfpe.samplers.dynamic_weighting import (
    QTypeDynamicWeighting,
    RTypeDynamicWeighting,
    dw_update,
)
from mrfpe.targets.base import Target
from mrfpe.testing import TwoModes

# -- the update rules, by hand from 5.48 / 5.49 ---------------------------------------------

PI, R, A = 2.0, 0.25, 3.0  # πr = 0.5


@pytest.mark.parametrize(("kind", "u", "accept", "weight"), [
    ("q", 0.49, True, 1.0),          # u <= min(1, πr/θ) = 0.5 -> (y, max(θ, πr)) = 1
    ("q", 0.51, False, A * PI),      # otherwise (x, aπ)
    ("r", 0.33, True, 1.5),          # u <= πr/(πr + θ) = 1/3 -> (y, πr + θ)
    ("r", 0.34, False, PI * 1.5),    # otherwise (x, π(πr + θ)/θ)
])
def test_update_matches_equations(kind, u, accept, weight):
    acc, lw = dw_update(kind, np.log([PI]), np.log([R]), np.log([u]), theta=1.0, a=A)
    assert acc[0] == accept
    assert np.exp(lw[0]) == pytest.approx(weight, rel=1e-12)


@pytest.mark.parametrize("kind", ["q", "r"])
def test_theta_zero_is_importance_weight_update(kind):
    # 5.53/5.54: θ = 0 accepts every move and sets Π' = Π r.
    log_pi, log_r = np.log([2.0, 0.5, 7.0]), np.log([0.1, 3.0, 1.0])
    acc, lw = dw_update(kind, log_pi, log_r, np.log([0.999, 0.5, 0.001]), theta=0.0, a=A)
    assert acc.all()
    np.testing.assert_allclose(lw, log_pi + log_r, rtol=1e-12)


def test_zero_density_proposal_is_rejected():
    for kind, theta, expected in [("r", 1.0, 2.0), ("q", 1.0, 2.0 * A), ("q", 0.0, 2.0),
                                  ("r", 0.0, 2.0)]:
        acc, lw = dw_update(kind, np.log([2.0]), np.array([-np.inf]), np.log([1e-12]),
                            theta=theta, a=A)
        assert not acc[0]
        assert np.exp(lw[0]) == pytest.approx(expected)


def test_stabiliser_multiplies_the_new_weight():
    _, plain = dw_update("r", np.log([2.0, 2.0]), np.log([R, R]), np.log([0.1, 0.9]), theta=1.0)
    _, stab = dw_update("r", np.log([2.0, 2.0]), np.log([R, R]), np.log([0.1, 0.9]), theta=1.0,
                        log_v=np.log([0.8, 1.2]))
    np.testing.assert_allclose(stab - plain, np.log([0.8, 1.2]))


def test_unknown_kind():
    with pytest.raises(ValueError, match="kind"):
        dw_update("x", np.zeros(1), np.zeros(1), np.zeros(1), theta=1.0)


# -- IWIW on a small discrete target ------------------------------------------------------

RHO = np.array([0.1, 0.2, 0.3, 0.4])  # target on 4 states of a cycle
P = RHO / RHO.sum()


def typo_r_update(kind, log_pi, log_r, log_u, *, theta, a=2.0, log_v=0.0):
    """The thesis's printed stabilised R-type rejection weight V(π(πr) + 1), for contrast."""
    acc, lw = dw_update("r", log_pi, log_r, log_u, theta=theta, log_v=log_v)
    pr = np.exp(log_pi + log_r)
    wrong = np.log(np.exp(log_pi) * pr + 1.0) + log_v
    return acc, np.where(acc, lw, wrong)


def weighted_occupancy(update, kind, theta, *, delta=0.0, steps=3, m=400_000, seed=0):
    """Start correctly weighted (x uniform, Π = ϱ(x)·E with E ~ Exp(1), so Σ π f ∝ ϱ),
    apply ``steps`` moves with the symmetric ±1 proposal on the cycle, and return the
    weighted state frequencies and their z-scores against ϱ (delta-method standard errors)."""
    rng = np.random.default_rng(seed)
    k = RHO.size
    x = rng.integers(0, k, m)
    lw = np.log(RHO[x]) + np.log(rng.exponential(size=m))
    for _ in range(steps):
        y = (x + rng.choice([-1, 1], m)) % k
        log_v = np.log(rng.uniform(1 - delta, 1 + delta, m)) if delta else 0.0
        acc, lw = update(kind, lw, np.log(RHO[y] / RHO[x]), np.log(rng.random(m)),
                         theta=theta, a=2.0, log_v=log_v)
        x = np.where(acc, y, x)
    w = np.exp(lw - lw.max())
    onehot = x[:, None] == np.arange(k)
    est = (w[:, None] * onehot).sum(0) / w.sum()
    infl = w[:, None] * (onehot - est) / w.mean()
    return est, (est - P) / (infl.std(0) / np.sqrt(m))


@pytest.mark.parametrize(("kind", "theta", "delta"), [
    ("r", 1.0, 0.0), ("r", 0.3, 0.0), ("r", 1.0, 0.5), ("q", 0.0, 0.0),
])
def test_iwiw_on_discrete_target(kind, theta, delta):
    # 5.50 (R-type) and 5.53 (θ = 0): a correctly weighted start stays correctly weighted.
    est, z = weighted_occupancy(dw_update, kind, theta, delta=delta)
    assert np.all(np.abs(z) < 5), (est, P, z)
    np.testing.assert_allclose(est, P, atol=0.01)


def test_iwiw_test_has_power():
    # The same test rejects the thesis's misprinted stabilised rejection weight ...
    _, z = weighted_occupancy(typo_r_update, "r", 1.0)
    assert np.max(np.abs(z)) > 10
    # ... and the Q-type move with θ > 0, which is IWIW only approximately (5.51-5.52).
    _, z = weighted_occupancy(dw_update, "q", 1.0)
    assert np.max(np.abs(z)) > 10


# -- the stabiliser of 5.5.4 ----------------------------------------------------------------

def test_stabiliser_keeps_uniform_target_weights_finite():
    # 5.5.4: with ϱ uniform (r = 1) and θ = 1 the R-type weights climb without bound
    # (log Π grows like log t); V ~ U(1 - δ, 1 + δ), E log V < 0, makes them stationary.
    m = 1000
    rng = np.random.default_rng(3)
    for delta in (0.0, 0.5):
        lw, med = np.zeros(m), {}
        for t in range(1, 4001):
            log_v = np.log(rng.uniform(1 - delta, 1 + delta, m)) if delta else 0.0
            _, lw = dw_update("r", lw, np.zeros(m), np.log(rng.random(m)), theta=1.0,
                              log_v=log_v)
            if t in (1000, 4000):
                med[t] = np.median(lw)
        if delta == 0.0:
            assert med[4000] - med[1000] > 1.5  # two doublings of t: about +2
        else:
            assert abs(med[4000] - med[1000]) < 0.4 and med[4000] < 8.0


# -- the sampler ----------------------------------------------------------------------------

class Bump1D(Target):
    """A truncated Gaussian on [0, 1]; its moments come from quadrature."""

    param_names = ("u",)
    bounds = np.array([[0.0, 1.0]])

    def __init__(self, offset: float = 0.0):
        self.offset = offset

    def _log_prob(self, theta):
        return -0.5 * ((theta[:, 0] - 0.35) / 0.12) ** 2 + self.offset

    def moments(self):
        f = lambda u: np.exp(-0.5 * ((u - 0.35) / 0.12) ** 2)  # noqa: E731
        z = integrate.quad(f, 0, 1)[0]
        m1 = integrate.quad(lambda u: u * f(u), 0, 1)[0] / z
        m2 = integrate.quad(lambda u: u * u * f(u), 0, 1)[0] / z
        return m1, np.sqrt(m2 - m1 * m1)


@pytest.mark.parametrize(("cls", "cfg", "max_se"), [
    (RTypeDynamicWeighting, {}, 0.2),
    (RTypeDynamicWeighting, {"initial_weight": "relative", "delta": 0.5}, 0.2),
    (RTypeDynamicWeighting, {"theta": 0.1}, 0.2),
    (QTypeDynamicWeighting, {"theta": 0.0}, 0.02),
])
def test_ensemble_of_chains_stays_correctly_weighted(cls, cfg, max_se):
    # Many chains from a correctly weighted start (θ₀ uniform, Π₀ ∝ ϱ(θ₀), 7.13): after a
    # few steps the cross-chain weighted mean is the target's mean (IWIW through the whole
    # sampler: kernel, boundary rejections, Metropolis ratio and initial weights). R-type
    # weights are heavy-tailed (ESS ~ 50 of 20000 chains), hence the looser precision.
    target = Bump1D()
    mean, sd = target.moments()
    n_steps, chains = 5, 20000
    config = {"initial_weight": "absolute", "proposal_sd": 0.3, "weights": "raw",  # IWIW: raw
              **cfg}  # wide kernel: chains mix
    post = cls(n_steps=n_steps, n_chains=chains, burn_in=n_steps - 1, **config).run(target,
                                                                                    seed=5)
    assert post.sizes["sample"] == chains
    w, x = weights(post), post["theta"].values[:, 0]
    est = w @ x
    var = w @ (x - est) ** 2
    se = np.sqrt(np.sum((w * (x - est)) ** 2))  # delta-method standard errors
    se_var = np.sqrt(np.sum((w * ((x - est) ** 2 - var)) ** 2))
    assert abs(est - mean) < 5 * se, (est, mean, se)
    assert abs(var - sd**2) < 5 * se_var, (np.sqrt(var), sd, se_var)
    assert se < max_se * sd  # the test is sharp enough to mean something


def test_absolute_initial_weight_freezes_an_unnormalised_target():
    # Why the default is "relative": Π₀ = ϱ(θ₀) = e^-5000 makes πr ≪ θ = 1, so the R-type
    # chain never moves; the relative start is the same up to one constant and does move.
    target = Bump1D(offset=-5000.0)
    stuck = RTypeDynamicWeighting(n_steps=300, initial_weight="absolute").run(target, seed=0)
    moving = RTypeDynamicWeighting(n_steps=300).run(target, seed=0)
    assert stuck["acceptance"].values.sum() == 0
    assert moving["acceptance"].values.mean() > 0.3


@pytest.mark.parametrize("cls", [QTypeDynamicWeighting, RTypeDynamicWeighting])
def test_sampler_output(cls):
    post = cls(n_steps=3000).run(TwoModes(), seed=1)
    validate(post)
    assert post.sizes["sample"] == 3000 and post.sizes["step"] == 3000
    np.testing.assert_allclose(post["map_theta"].values[-1], TwoModes.high, atol=0.05)
    ml = post["map_log_target"].values
    assert np.all(np.diff(ml) >= 0)
    np.testing.assert_allclose(TwoModes().log_prob(post["map_theta"].values[-1:]), ml[-1])
    e = post["ess"].values  # chain ESS x Kish efficiency at checkpoints, NaN elsewhere
    ok = np.isfinite(e)
    assert ok.sum() == 20 and ok[-1]
    assert np.all((e[ok] >= 1) & (e[ok] <= np.arange(1, 3001)[ok] + 1e-9))
    assert post.attrs["n_target_evals"] <= 3000 + 2048 + 1
    again = cls(n_steps=3000).run(TwoModes(), seed=1)
    np.testing.assert_array_equal(post["log_weight"].values, again["log_weight"].values)


def test_burn_in_and_thin_select_the_kept_states():
    post = RTypeDynamicWeighting(n_steps=100, burn_in=40, thin=7, n_chains=3).run(Bump1D(),
                                                                                  seed=2)
    assert post.sizes["sample"] == len(range(40, 100, 7)) * 3


@pytest.mark.parametrize(("kw", "match"), [
    ({"theta": -1.0}, "theta"), ({"delta": 1.0}, "delta"), ({"burn_in": 20000}, "burn_in"),
    ({"proposal_sd": 0.0}, "proposal_sd"), ({"initial_weight": "x"}, "initial_weight"),
    ({"n_chains": 0}, "n_chains"),
])
def test_bad_config(kw, match):
    with pytest.raises(ValueError, match=match):
        RTypeDynamicWeighting(**kw)
    with pytest.raises(ValueError, match="a must"):
        QTypeDynamicWeighting(a=1.0)
    with pytest.raises(TypeError):
        RTypeDynamicWeighting(a=2.0)  # a is a Q-type setting only


def test_stratified_truncation_caps_each_stratum():
    from mrfpe.samplers.dynamic_weighting import stratified_truncation

    rng = np.random.default_rng(0)
    lt = rng.normal(size=1000)
    lw = rng.standard_cauchy(1000)
    lw[5] = -np.inf
    out = stratified_truncation(lw, lt, n_strata=4, quantile=0.9)
    assert np.isneginf(out[5]) and np.all(out <= lw)
    order = np.argsort(lt[np.isfinite(lw)])
    for block in np.array_split(np.flatnonzero(np.isfinite(lw))[order], 4):
        assert np.isclose(out[block].max(), np.quantile(lw[block], 0.9))
    assert np.array_equal(stratified_truncation(lw, lt, quantile=1.0), np.where(
        np.isfinite(lw), lw, -np.inf))


def test_default_weights_are_stratified_truncation_raw_kept():
    from mrfpe.samplers.dynamic_weighting import stratified_truncation
    from mrfpe.testing import CorrelatedGaussian

    t = CorrelatedGaussian()
    raw = RTypeDynamicWeighting(n_steps=3000, weights="raw").run(t, seed=1)
    post = RTypeDynamicWeighting(n_steps=3000).run(t, seed=1)
    assert np.array_equal(raw["theta"].values, post["theta"].values)
    expect = stratified_truncation(raw["log_weight"].values, raw["log_target"].values)
    assert np.allclose(np.exp(post["log_weight"]), np.exp(post_mod.normalise_log_weights(expect)))
    assert post_mod.ess(post) > post_mod.ess(raw)
