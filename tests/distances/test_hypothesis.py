"""Property-based tests (hypothesis) of every distance on random weighted sets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import mrfpe.distances as D
from mrfpe.posterior import build

FAST = settings(max_examples=25, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
FREE = [n for n in D.available() if not D.get(n).requires_grid]
GRID = [n for n in D.available() if D.get(n).requires_grid]


def _post(theta, lw):
    return build(theta, np.where(np.isfinite(lw), lw, -1e300), param_names=[f"p{i}" for i in
                 range(theta.shape[1])], log_weight=lw, sampler="hypothesis")


@st.composite
def weighted_sets(draw, d, n_min=2, points=None):
    """Samples from a coarse lattice (duplicates likely) or free floats; some zero weights."""
    if points is None:
        n = draw(st.integers(n_min, 10))
        coarse = draw(st.booleans())
        elem = (st.integers(0, 3).map(lambda k: 0.25 * k) if coarse
                else st.floats(-2.0, 2.0, allow_nan=False))
        theta = np.array(draw(st.lists(st.lists(elem, min_size=d, max_size=d), min_size=n,
                                       max_size=n)), dtype=np.float64)
        if draw(st.booleans()) and draw(st.booleans()):
            theta[:] = theta[0]  # collapsed: every sample at one point
    else:
        theta = points
        n = theta.shape[0]
    lw = np.array(draw(st.lists(st.one_of(st.floats(-8.0, 8.0), st.just(-np.inf)),
                                min_size=n, max_size=n)))
    assume(np.isfinite(lw).any())
    return _post(theta, lw)


def _value(dist, a, b):
    try:
        return dist(a, b)
    except ValueError:
        return None  # a named refusal (e.g. too few samples) is acceptable; NaN is not


@pytest.mark.parametrize("name", FREE)
@FAST
@given(data=st.data())
def test_free_distances(name, data):
    cls = D.get(name)
    dist = cls()
    d = data.draw(st.integers(1, 3))
    a = data.draw(weighted_sets(d, n_min=max(2, cls.min_samples)))
    b = data.draw(weighted_sets(d, n_min=max(2, cls.min_samples)))
    v = _value(dist, a, b)
    if v is None:
        return
    assert np.isfinite(v), v
    if cls.symmetric:
        w = dist(b, a)
        assert abs(v - w) <= 1e-7 * (1 + abs(v)), (v, w)
    if cls.nonnegative:
        assert v >= -1e-12
    if cls.kind == "distance":
        assert abs(dist(a, a)) <= 1e-6 * (1 + abs(v))
    else:
        assert np.isfinite(dist(a, a))


@pytest.mark.parametrize("name", GRID)
@FAST
@given(data=st.data())
def test_grid_measures(name, data):
    dist = D.get(name)()
    k = data.draw(st.integers(2, 5))
    g = np.stack(np.meshgrid(np.linspace(0, 1, k), np.linspace(0, 1, 3), indexing="ij"),
                 -1).reshape(-1, 2)
    a = data.draw(weighted_sets(2, points=g))
    b = data.draw(weighted_sets(2, points=g))
    v = dist(a, b)
    assert np.isfinite(v) and -1e-12 <= v <= 2 + 1e-12
    assert abs(v - dist(b, a)) <= 1e-12
    if name == "correlation":
        assert abs(dist(a, a)) <= 1e-9
