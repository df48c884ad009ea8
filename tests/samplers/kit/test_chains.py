"""start_chains: the common opening of an MCMC run."""

import numpy as np
import pytest

from mrfpe.samplers.kit import ChainStart, KeptStates, Run, start_chains
from mrfpe.testing import CorrelatedGaussian, MostlyMinusInf

SETTINGS = {"n_steps": 50, "n_chains": 3, "burn_in": 10, "thin": 2, "desc": "test"}


def test_opens_the_run_with_starting_states_in_the_support():
    start = start_chains(MostlyMinusInf(), 0, **SETTINGS)
    assert isinstance(start, ChainStart)
    bounds, rng, run, x, lp, kept = start
    np.testing.assert_array_equal(bounds, MostlyMinusInf().bounds)
    assert isinstance(rng, np.random.Generator) and isinstance(run, Run)
    assert x.shape == (3, 3) and np.isfinite(lp).all()
    np.testing.assert_array_equal(lp, MostlyMinusInf().log_prob(x))
    assert isinstance(kept, KeptStates) and kept.steps.tolist() == list(range(10, 50, 2))
    assert kept.log_weight is None
    assert run.n_evals > 0  # the start's draws are counted


def test_same_seed_same_start_and_stream():
    a = start_chains(CorrelatedGaussian(), 4, **SETTINGS)
    b = start_chains(CorrelatedGaussian(), 4, **SETTINGS)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.rng.random() == b.rng.random()


def test_weighted_record():
    kept = start_chains(CorrelatedGaussian(), 0, weighted=True, **SETTINGS).kept
    assert kept.log_weight.shape == (20, 3)


@pytest.mark.parametrize(("target", "seed", "match"), [
    (object(), 0, "Target contract"),
    (CorrelatedGaussian(), -1, "seed"),
])
def test_validates_target_and_seed(target, seed, match):
    with pytest.raises(ValueError, match=match):
        start_chains(target, seed, **SETTINGS)


def test_memory_check_counts_the_kept_states():
    with pytest.raises(ValueError, match="sampler test"):
        start_chains(CorrelatedGaussian(), 0, **{**SETTINGS, "n_steps": 10**13, "burn_in": 0})


def test_short_antithetic_chains_never_report_more_ess_than_draws():
    import warnings

    import mrfpe
    from mrfpe import models

    m = models.ising()
    x = m.simulate([0.3, 0.0], shape=(16, 16), seed=0)
    for seed in range(20):  # 13 of these 20 failed the posterior's check before the cap
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
            post = mrfpe.sample("mh", m.target("pl", x), seed=seed, n_steps=20, burn_in=10)
        trace = post["ess"].values
        assert np.nanmax(trace) <= post.sizes["sample"]
