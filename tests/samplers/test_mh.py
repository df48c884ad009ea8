"""Random-walk Metropolis–Hastings (thesis 5.41–5.46)."""

import numpy as np
import pytest
from scipy import stats

from mrfpe.posterior import validate
from mrfpe.samplers.mh import MetropolisHastings, metropolis_accept
from mrfpe.targets.base import Target


class BetaPair(Target):
    """Independent Beta(2, 5) × Beta(3, 3) on the unit square; counts its calls and rows."""

    param_names = ("p", "q")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])

    def __init__(self):
        self.calls = 0
        self.rows: list[np.ndarray] = []

    def log_prob(self, theta):
        self.calls += 1
        self.rows.append(np.array(theta, dtype=float, copy=True))
        return super().log_prob(theta)

    def _log_prob(self, theta):
        p, q = theta[:, 0], theta[:, 1]  # both normalisers are B(2,5) = B(3,3) = 1/30
        with np.errstate(divide="ignore"):
            return (np.log(p) + 4 * np.log1p(-p) + 2 * np.log(q) + 2 * np.log1p(-q)
                    + 2 * np.log(30.0))


def test_accept_rule():
    lp = np.array([0.0, 0.0, -np.inf, -1.0])
    lpy = np.array([1.0, -1.0, -5.0, -np.inf])
    log_u = np.log([0.999, 0.5, 0.999, 1e-300])
    # uphill: always; downhill by 1: iff u < e^-1 (0.5 >= 0.37: reject); from outside the
    # support: always; into a zero-density point: never.
    np.testing.assert_array_equal(metropolis_accept(log_u, lp, lpy), [True, False, True, False])
    assert metropolis_accept(np.log([0.3]), np.zeros(1), -np.ones(1))[0]  # 0.3 < e^-1


def test_samples_the_target():
    # Beta marginals have closed-form moments and CDFs (an independent route).
    post = MetropolisHastings(n_steps=3000, burn_in=500).run(BetaPair(), seed=0)
    validate(post)
    x = post["theta"].values
    assert x.shape == (2500 * 8, 2)
    for j, dist in enumerate((stats.beta(2, 5), stats.beta(3, 3))):
        assert abs(x[:, j].mean() - dist.mean()) < 0.1 * dist.std()
        assert abs(x[:, j].std() / dist.std() - 1) < 0.1
        # KS distance on a thinned subset (the chain is autocorrelated)
        assert stats.kstest(x[::40, j], dist.cdf).statistic < 0.06
    acc = post["acceptance"].values[500:].mean()  # per-step acceptance, an extra variable
    assert 0.1 < acc < 0.5  # adapted towards 0.234


def test_one_batched_call_per_step_and_counting():
    target = BetaPair()
    post = MetropolisHastings(n_steps=200, burn_in=50, n_chains=5).run(target, seed=1)
    rows = np.concatenate(target.rows)
    assert post.attrs["n_target_evals"] == rows.shape[0]
    assert target.calls <= 200 + 65  # one per step, plus the start-point batches
    # proposals outside the box are rejected without being evaluated
    assert np.all((rows >= 0) & (rows <= 1))


def test_adaptation_is_frozen_after_burn_in():
    post = MetropolisHastings(n_steps=600, burn_in=300).run(BetaPair(), seed=2)
    s = post["proposal_scale"].values
    assert np.all(s[300:] == s[300]) and np.ptp(s[:300]) > 0
    fixed = MetropolisHastings(n_steps=100, burn_in=10, adapt=False).run(BetaPair(), seed=2)
    assert np.all(fixed["proposal_scale"].values == 1.0)


def test_reproducible_and_trace():
    a = MetropolisHastings(n_steps=300, burn_in=100, thin=4).run(BetaPair(), seed=7)
    b = MetropolisHastings(n_steps=300, burn_in=100, thin=4).run(BetaPair(), seed=7)
    c = MetropolisHastings(n_steps=300, burn_in=100, thin=4).run(BetaPair(), seed=8)
    np.testing.assert_array_equal(a["theta"].values, b["theta"].values)
    assert not np.array_equal(a["theta"].values, c["theta"].values)
    assert a.sizes["sample"] == len(range(100, 300, 4)) * 8
    ml = a["map_log_target"].values
    assert a.sizes["step"] == 300 and np.all(np.diff(ml) >= 0)
    assert ml[-1] >= a["log_target"].values.max()
    np.testing.assert_allclose(BetaPair().log_prob(a["map_theta"].values[-1:])[0], ml[-1])


def test_callback_per_step():
    seen = []
    MetropolisHastings(n_steps=20, burn_in=5).run(BetaPair(), seed=0,
                                                 callback=lambda s, i: seen.append((s, i)))
    assert [s for s, _ in seen] == list(range(20))
    assert {"acceptance", "map_log_target", "ess"} <= set(seen[0][1])


@pytest.mark.parametrize(("kw", "match"), [
    ({"burn_in": 2500}, "burn_in"), ({"thin": 0}, "thin"), ({"proposal_sd": -0.1}, "proposal_sd"),
    ({"adapt": 1}, "adapt"), ({"target_acceptance": 1.0}, "target_acceptance"),
    ({"n_chains": 1.5}, "n_chains"),
])
def test_bad_config(kw, match):
    with pytest.raises(ValueError, match=match):
        MetropolisHastings(**kw)


def test_bad_seed_and_target():
    with pytest.raises(ValueError, match="seed"):
        MetropolisHastings().run(BetaPair(), seed=-1)
    with pytest.raises(ValueError, match="Target contract"):
        MetropolisHastings().run(object(), seed=0)
