"""PosteriorWarning says what to change, per sampler family; ensembles are judged by τ;
distances say when a posterior is a set of optima."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import mrfpe
from mrfpe import posterior as P
from mrfpe.posterior.diagnostics import nested_rhat
from mrfpe.testing import CorrelatedGaussian


def _post(theta, lw=None, config=None, chain=None, **attrs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = P.build(theta, np.zeros(len(theta)), param_names=["a"], log_weight=lw,
                       chain=chain, sampler="unit", config=config or {})
    post.attrs.update(attrs)
    return post


def test_nested_rhat_sees_a_shifted_superchain_not_short_walkers():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((32, 400, 1))
    for t in range(1, 400):  # AR(1), τ ≈ 19: plain split R̂ over 32 walkers is inflated
        x[:, t] = 0.9 * x[:, t - 1] + np.sqrt(1 - 0.81) * x[:, t]
    assert nested_rhat(x) < 1.01
    y = x.copy()
    y[::4] += 1.0  # one superchain of walkers elsewhere
    assert nested_rhat(y) > 1.05
    z = x.copy()
    z[:, 200:] += 0.5  # the whole ensemble drifts by half an sd: the split halves disagree
    assert nested_rhat(z) > 1.02
    assert np.isnan(nested_rhat(x[:6]))


def test_emcee_marks_its_walkers_as_an_ensemble():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = mrfpe.sample("emcee", CorrelatedGaussian(), seed=0, n_steps=200, burn_in=50)
    assert post.attrs["chain_type"] == "ensemble"
    x = post["theta"].values.reshape(-1, 32, 3).transpose(1, 0, 2)
    assert post.attrs["diag_rhat"] == pytest.approx(nested_rhat(x))
    P.validate(post)


@pytest.mark.parametrize("config, chain, words", [
    ({"n_samples": 50, "power": 0.1}, None, ["n_samples=50 →", "power=0.1 → 0.05"]),
    ({"n_samples": 50, "power": "auto", "n_iterations": 5}, None,
     ["n_samples=50 →", "n_iterations=5 → 10"]),
    ({"n_particles": 50}, None, ["n_particles=50 →"]),
    ({"n_steps": 25, "burn_in": 5, "n_chains": 2}, np.tile([0, 1], 25),
     ["n_steps=25 →", "n_chains=2 → 4"]),
])
def test_messages_name_the_samplers_own_options(config, chain, words):
    rng = np.random.default_rng(1)
    theta = rng.standard_normal((50, 1))
    lw = None if chain is not None else rng.standard_normal(50) * 3
    d = P.diagnose(_post(theta, lw, config, chain))
    assert not d["reliable"]
    text = " ".join(d["messages"])
    assert all(w in text for w in words), text


def test_ensemble_messages_say_more_walkers():
    rng = np.random.default_rng(2)
    post = _post(rng.standard_normal((80, 1)), config={"n_steps": 10, "n_walkers": 8},
                 chain=np.tile(np.arange(8), 10), chain_type="ensemble")
    text = " ".join(P.diagnose(post)["messages"])
    assert "more walkers (n_walkers=8 → 16)" in text and "n_steps=10 →" in text


SAMPLERS = ["pmc", "sir", "ppf", "mh", "emcee", "dw_q", "dw_r", "smc"]


@pytest.mark.parametrize("name", SAMPLERS)
def test_default_result_warns_once_exactly_when_unreliable(name):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        post = mrfpe.sample(name, CorrelatedGaussian(), seed=0)
    ours = [w for w in caught if issubclass(w.category, mrfpe.PosteriorWarning)]
    assert len(ours) == (0 if post.attrs["diag_reliable"] else 1)
    if ours:
        cfg = json.loads(post.attrs["config"])
        msg = str(ours[0].message)
        assert any(f"{k}=" in msg for k in cfg), msg  # names one of its own options


def test_a_distance_on_optima_computes_and_warns_once():
    rng = np.random.default_rng(3)
    a = _post(rng.standard_normal((30, 1)))
    b = _post(rng.standard_normal((30, 1)), kind="optima")
    dist = mrfpe.distances.get("bhattacharyya")()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = dist(a, b)
    ours = [w for w in caught if issubclass(w.category, mrfpe.PosteriorWarning)]
    assert np.isfinite(value) and len(ours) == 1
    assert str(ours[0].message).startswith("b is of kind='optima'")
    with warnings.catch_warnings():
        warnings.simplefilter("error", mrfpe.PosteriorWarning)
        dist(a, a)  # draws only: silent
