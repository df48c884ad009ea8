"""Distances on extreme inputs: a number that means something, or one line saying why not."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

import mrfpe
from mrfpe.distances import registry
from mrfpe.distances.base import THETA_LIMIT

GAUSSIAN_ETC = [n for n in registry.names() if n not in ("correlation", "inner_product")]


def _post(theta, d=None):
    theta = np.asarray(theta, dtype=np.float64)
    S = theta.shape[0]
    names = [f"p{i}" for i in range(theta.shape[1])]
    return xr.Dataset({"theta": (("sample", "param"), theta),
                       "log_weight": (("sample",), np.full(S, -np.log(S)))},
                      coords={"param": names})


@pytest.mark.parametrize("name", registry.names())
@pytest.mark.parametrize("scale", [1e155, 1e300])
def test_huge_finite_theta_is_refused_not_zero_or_nan(name, scale):
    rng = np.random.default_rng(0)
    a, b = _post(rng.normal(size=(50, 3)) * scale), _post(rng.normal(size=(50, 3)) * scale)
    with pytest.raises(ValueError, match=r"^a\.theta has values up to .* in magnitude"):
        mrfpe.distance(name, a, b)


@pytest.mark.parametrize("name", registry.names())
def test_zero_parameters_is_refused(name):
    a = _post(np.zeros((5, 0)))
    with pytest.raises(ValueError, match="has no parameters"):
        mrfpe.distance(name, a, a)


@settings(max_examples=30, deadline=None)
@given(exponent=st.integers(-50, 100), seed=st.integers(0, 2**16),
       name=st.sampled_from(GAUSSIAN_ETC))
def test_property_values_within_the_limit_give_a_number_or_one_error(exponent, seed, name):
    rng = np.random.default_rng(seed)
    scale = min(10.0 ** exponent, THETA_LIMIT / 10)
    a, b = (_post(rng.normal(size=(20, 2)) * scale) for _ in range(2))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            v = mrfpe.distance(name, a, b)
        except ValueError:
            return
    assert not np.isnan(v)


def test_a_singular_linear_algebra_is_one_error(monkeypatch):
    from mrfpe.distances.gaussian import KL

    def singular(*a, **k):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(KL, "compare", singular)
    a = _post(np.random.default_rng(0).normal(size=(10, 2)))
    with pytest.raises(ValueError, match="kl: the linear algebra failed"):
        mrfpe.distance("kl", a, a)


def test_sliced_wasserstein_projections_beyond_the_budget_fail_at_once():
    a = _post(np.random.default_rng(0).normal(size=(10, 3)))
    with pytest.raises(ValueError, match="more than the memory budget"):
        mrfpe.distance("sliced_wasserstein", a, a, n_projections=1_000_000_000)
