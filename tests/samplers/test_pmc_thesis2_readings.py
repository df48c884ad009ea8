"""PMC (II) readings (issue 13): the literal 6.67 weight self-cancels with one sub-lattice.

The step functions live in ``docs/results/pmc_thesis2_readings/readings.py``
(a standalone experiment script, to be ported into ``mrfpe/samplers/pmc.py``);
they are imported from there by path.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import mrfpe

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "pmc_thesis2_readings" / \
    "readings.py"


@pytest.fixture(scope="module")
def readings():
    spec = importlib.util.spec_from_file_location("pmc_thesis2_readings", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop(spec.name, None)


@pytest.fixture(scope="module")
def target():
    theta = mrfpe.brdf.get("ward").to_natural(np.array([0.4, 0.6, 0.5]))
    scene = mrfpe.brdf.synthetic.make_scene(brdf="ward", theta=theta, shape=(10, 10), n_labels=5,
                                       seed=3)
    return mrfpe.targets.get("pls", scene)


def _trace(readings, target, reading, k, power=0.3, n=64, T=6, seed=0):
    """Resampling log weights of every iteration n >= 1 of one run."""
    s = readings.Settings(reading=reading, power=power, k=k, n=n, T=T)
    parts = target.partition(k, kind="strided") if k > 1 else [target]
    scale = np.ones(k)

    def evaluate_parts(x):
        return np.stack([np.asarray(p.log_prob(x), dtype=np.float64) for p in parts], axis=1)

    rng = np.random.default_rng(seed)
    bounds = np.asarray(target.bounds, dtype=np.float64)
    state, out = None, []
    for it in range(T):
        state, info = readings.thesis2_step(state, it, s, scale, evaluate_parts, rng, bounds)
        if it > 0:
            out.append(info["lw"])
    return out


def test_literal_weight_is_exactly_one_with_one_sublattice(readings, target):
    """k = 1: w = c^{n-1} G^n(a^{n-1}) = G(a)/G(a) = 1 for every particle (no selection)."""
    for lw in _trace(readings, target, "literal", k=1):
        assert np.all(lw == 0.0)


def test_literal_weight_is_a_ratio_of_different_sublattices(readings, target):
    """k = 3: the literal weight is G^n/G^{n-1} at the same points, not constant."""
    lws = _trace(readings, target, "literal", k=3)
    assert all(np.ptp(lw[np.isfinite(lw)]) > 0 for lw in lws)


def test_compound_weight_is_the_importance_function(readings, target):
    """k = 1: the compounding reading still selects (w = G^n(a^{n-1}), not constant)."""
    lws = _trace(readings, target, "compound", k=1)
    assert all(np.ptp(lw[np.isfinite(lw)]) > 0 for lw in lws)


def _resampling_weights(target, monkeypatch, **config):
    """The log weights every resampling of one PMC run sees."""
    pmc = pytest.importorskip("mrfpe.samplers.pmc_steps")
    seen = []
    real = pmc.resample

    def spy(lw, *args, **kwargs):
        seen.append(np.asarray(lw, dtype=np.float64).copy())
        return real(lw, *args, **kwargs)

    monkeypatch.setattr(pmc, "resample", spy)
    mrfpe.sample("pmc", target, seed=1, n_samples=64, n_iterations=5, power=0.3, **config)
    return seen


def test_library_thesis2_literal_k1_resamples_with_equal_weights(target, monkeypatch):
    """``PMC(variant="thesis2_literal", k=1)``: every resampling after the first sees
    exactly equal weights, ``log w = -log G(a) + log G(a) = 0`` (no selection)."""
    seen = _resampling_weights(target, monkeypatch, variant="thesis2_literal", k=1)
    assert len(seen) == 5
    assert np.ptp(seen[0]) > 0  # iteration 0 weights the grid by G^0
    for lw in seen[1:]:
        assert np.all(lw == 0.0)


def test_library_thesis2_compounds_with_one_sublattice(target, monkeypatch):
    """``PMC(variant="thesis2", k=1)`` (the compounding reading) keeps selecting: each
    resampling weight is ``G(a^{n-1})`` itself, so it is not constant."""
    seen = _resampling_weights(target, monkeypatch, variant="thesis2", k=1)
    assert len(seen) == 5
    for lw in seen:
        assert np.ptp(lw[np.isfinite(lw)]) > 0


def test_library_thesis2_matches_the_script(readings, target, monkeypatch):
    """The ported step and the experiment's ``weights_compound`` give the same weights:
    at every iteration n >= 1 the library resamples with ``log G^n`` at the current set."""
    seen = _resampling_weights(target, monkeypatch, variant="thesis2", k=3)
    lit = _resampling_weights(target, monkeypatch, variant="thesis2_literal", k=3)
    np.testing.assert_array_equal(seen[0], lit[0])  # iteration 0: the same grid, same G^0
    for lw in seen[1:]:
        np.testing.assert_array_equal(lw, readings.weights_compound(lw, None, None))
