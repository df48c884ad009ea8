"""The MCMC samplers' ``ess`` trace is autocorrelation-based, at checkpoints, never a count."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mrfpe
from mrfpe.samplers.kit import ESS_CHECKPOINTS, KeptStates
from mrfpe.testing import CorrelatedGaussian

CASES = [("mh", {"n_steps": 600, "burn_in": 100}),
         ("emcee", {"n_steps": 300, "burn_in": 100}),
         ("dw_r", {"n_steps": 600, "burn_in": 100}),
         ("dw_q", {"n_steps": 600, "burn_in": 100})]


@pytest.mark.parametrize("name, cfg", CASES)
def test_ess_trace_is_chain_ess_at_checkpoints(name, cfg):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = mrfpe.sample(name, CorrelatedGaussian(), seed=0, **cfg)
    e = post["ess"].values
    finite = np.flatnonzero(np.isfinite(e))
    assert finite.size == ESS_CHECKPOINTS
    assert finite.min() >= cfg["burn_in"] and finite.max() == cfg["n_steps"] - 1
    n_draws = post.sizes["sample"]
    assert np.all(e[finite] < n_draws)  # never the number of draws
    if name in ("mh", "emcee"):  # equal weights: the last entry is diagnose's ESS
        assert e[finite[-1]] == pytest.approx(post.attrs["diag_ess"], rel=1e-9)


def test_kept_states_trace_ess_is_nan_off_checkpoints():
    kept = KeptStates(50, 10, 1, 4, 2)
    rng = np.random.default_rng(0)
    out = []
    for t in range(50):
        kept.record(t, rng.standard_normal((4, 2)), np.zeros(4))
        out.append(kept.trace_ess(t))
    out = np.array(out)
    assert np.isnan(out[:10]).all() and np.isfinite(out[-1])
    assert 50 < out[-1] < 400  # independent draws: about the 160 kept
