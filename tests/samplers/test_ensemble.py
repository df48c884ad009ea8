"""emcee's affine-invariant ensemble on the batched target."""

import numpy as np
import pytest
from scipy import stats

from mrfpe.posterior import validate
from mrfpe.samplers.ensemble import EmceeEnsemble
from mrfpe.targets.base import Target
from mrfpe.testing import MostlyMinusInf


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
