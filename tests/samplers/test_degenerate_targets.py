"""Targets that are NaN, +inf or -inf everywhere: every sampler refuses, early, naming why."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

import mrfpe

SAMPLERS = [("mh", {}), ("mh", {"n_steps": 3000}), ("emcee", {}), ("smc", {}),
            ("smc", {"n_particles": 400}), ("pmc", {}), ("sir", {}), ("ppf", {}), ("dw_q", {}),
            ("nlopt_multiseed", {})]


class Constant:
    param_names = ("a", "b", "c")
    bounds = np.array([[0.0, 1.0]] * 3)

    def __init__(self, value: float):
        self.value = value

    def log_prob(self, theta):
        return np.full(np.atleast_2d(theta).shape[0], self.value)


@pytest.mark.parametrize(("name", "config"), SAMPLERS,
                         ids=[f"{n}{'-' + str(c) if c else ''}" for n, c in SAMPLERS])
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_no_posterior_from_a_target_without_support(name, config, value):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        with pytest.raises(ValueError) as info:
            mrfpe.sample(name, Constant(value), seed=0, **config)
        elapsed = time.perf_counter() - t0
    msg = str(info.value)
    if value == np.inf:
        assert "+inf" in msg and "-inf or NaN" not in msg
    else:
        assert "-inf or NaN" in msg and "no support" in msg
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]  # no numpy noise
    assert elapsed < 5


class Returns:
    def __init__(self, value=None):
        self.value = value

    def run(self, target, *, seed=None, progress=False, callback=None):
        return self.value


@pytest.mark.parametrize("value", [None, 42, "posterior", {"theta": [1.0]}])
def test_sample_checks_what_a_plugin_returns(value):
    with pytest.raises(ValueError, match="sampler 'Returns' returned an invalid posterior"):
        mrfpe.sample(Returns(value), Constant(0.0), seed=0)


@pytest.mark.parametrize("seed", [2**64, 2**63, -1, True, 1.5])
def test_sample_refuses_a_seed_out_of_range_before_the_run(seed):
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*63 - 1\]"):
        mrfpe.sample(Returns(), Constant(0.0), seed=seed)
