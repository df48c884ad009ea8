"""PMC's steps are pure: frozen parameters, unchanged input states, same stream → same output."""

import copy
import dataclasses

import numpy as np
import pytest

from mrfpe.samplers import ppf as ppf_module
from mrfpe.samplers.kit import grid, partition_or_none
from mrfpe.samplers.pmc import PMC
from mrfpe.samplers.pmc_steps import (
    ALGORITHMS,
    PMCParams,
    StepInfo,
    StepTarget,
    final_log_weight,
    importance_functions,
)
from mrfpe.samplers.ppf import PPF
from mrfpe.testing import CorrelatedGaussian

CONFIGS = {
    "mixture": {},
    "mixture_adaptive": {"kernel": "adaptive", "ess_threshold": 0.5},
    "thesis2": {"variant": "thesis2", "power": 0.3},
    "thesis2_literal": {"variant": "thesis2_literal", "power": 0.3},
    "thesis1": {"variant": "thesis1", "power": 0.3},
}


def _states(name, n_steps=3):
    """The algorithm, its parameters, a view of the target, and the states after 0..n steps."""
    pmc = PMC(n_samples=64, n_iterations=5, **CONFIGS[name])
    target = CorrelatedGaussian()
    G = importance_functions(target, 3, "strided",
                             None if pmc.variant == "mixture" else pmc.power)
    algorithm, params = ALGORITHMS[pmc.variant], pmc.params()

    def view(n):
        return StepTarget(G[n % len(G)].log_prob, target.log_prob, target.bounds)

    rng = np.random.default_rng(0)
    states = [algorithm.init(grid(target.bounds, 64))]
    for n in range(n_steps):
        states.append(algorithm.step(params, states[-1], rng, view(n))[0])
    return algorithm, params, view, states


def _equal(a, b):
    if isinstance(a, tuple):
        return len(a) == len(b) and all(_equal(u, v) for u, v in zip(a, b))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.tobytes() == b.tobytes() and a.shape == b.shape
    return a == b


@pytest.mark.parametrize("name", CONFIGS)
def test_step_leaves_its_input_state_unchanged(name):
    algorithm, params, view, states = _states(name)
    for n, state in enumerate(states):
        before = copy.deepcopy(state)
        algorithm.step(params, state, np.random.default_rng(7), view(n))
        assert _equal(state, before)


@pytest.mark.parametrize("name", CONFIGS)
def test_same_stream_same_step(name):
    algorithm, params, view, states = _states(name)
    for n, state in enumerate(states):
        a, b = np.random.default_rng(11), np.random.default_rng(0)
        b.bit_generator.state = a.bit_generator.state
        out_a = algorithm.step(params, state, a, view(n))
        out_b = algorithm.step(params, state, b, view(n))
        assert _equal(out_a, out_b)
        assert a.random() == b.random()  # and the streams advanced alike


@pytest.mark.parametrize("name", CONFIGS)
def test_states_count_iterations_and_infos_say_what_was_evaluated(name):
    algorithm, params, view, states = _states(name, n_steps=2)
    state, info = algorithm.step(params, states[-1], np.random.default_rng(1), view(2))
    assert state.iteration == 3 and isinstance(info, StepInfo)
    np.testing.assert_array_equal(info.log_g, view(2).log_g(state.x))
    if name == "thesis1":  # PMC (I) evaluates the full target; the driver offers it
        np.testing.assert_array_equal(info.log_target, CorrelatedGaussian().log_prob(state.x))
    else:
        assert info.log_target is None
    lt = CorrelatedGaussian().log_prob(state.x)
    assert final_log_weight(state, lt).shape == lt.shape


def test_parameters_are_frozen():
    params = PMC().params()
    assert isinstance(params, PMCParams)
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.n_samples = 3
    assert params.sigma(0) == 0.07 and params.sigma(20) == 0.0


def test_run_changes_nothing_on_the_sampler():
    s = PMC(n_samples=64, n_iterations=3)
    before = s.get_config()
    s.run(CorrelatedGaussian(), seed=0)
    assert s.get_config() == before and vars(s).keys() == before.keys()


@pytest.mark.parametrize("weights", ["mixture", "thesis"])
def test_ppf_builds_no_pmc(weights, monkeypatch):
    """PPF runs the shared steps with its own parameters; it does not configure a PMC."""
    assert not hasattr(ppf_module, "PMC")

    def refuse(*args, **kwargs):
        raise AssertionError("PPF constructed a PMC")

    monkeypatch.setattr(PMC, "__init__", refuse)
    post = PPF(n_samples=64, n_partitions=3, weights=weights, power=0.3).run(
        CorrelatedGaussian(), seed=0)
    assert post.sizes["sample"] == 64


def test_importance_functions_cycle_the_partition():
    target = CorrelatedGaussian()
    parts = partition_or_none(target, 3, "strided")
    G = importance_functions(target, 3, "strided")
    assert len(G) == 3 and [type(g) for g in G] == [type(p) for p in parts]
    soft = importance_functions(target, 3, "strided", 0.5)
    x = grid(target.bounds, 8)
    np.testing.assert_allclose(soft[0].log_prob(x), 0.5 * G[0].log_prob(x))
