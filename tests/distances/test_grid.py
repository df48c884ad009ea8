"""Correlation (8.9), inner product (8.10) on a shared grid, and the MAP distance."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
from mrfpe.distances import get

from ._helpers import grid_points, grid_post, post, with_var


def weights_on(ds, grid):
    """The normalised weight of each grid point, in ``grid`` order (test's own route)."""
    theta, w = ds["theta"].values, np.exp(ds["log_weight"].values)
    return np.array([w[np.all(theta == g, axis=1)].sum() for g in grid])


def test_correlation_and_inner_product_against_numpy():
    rng = np.random.default_rng(0)
    g = grid_points(4, 3)
    a, b = grid_post(rng, 4, 3), grid_post(rng, 4, 3)
    b = b.isel(sample=rng.permutation(b.sizes["sample"]))  # same grid, other order
    wa, wb = weights_on(a, g), weights_on(b, g)
    r = np.corrcoef(wa, wb)[0, 1]
    assert get("correlation")().similarity(a, b) == pytest.approx(r, rel=1e-12)
    assert mrfpe.distance("correlation", a, b) == pytest.approx(1 - r, rel=1e-12)
    assert get("inner_product")().similarity(a, b) == pytest.approx(wa @ wb, rel=1e-12)
    assert get("inner_product")().log_similarity(a, b) == pytest.approx(np.log(wa @ wb))
    assert mrfpe.distance("inner_product", a, b) == pytest.approx(1 - wa @ wb, rel=1e-12)


@pytest.mark.parametrize("name", ["correlation", "inner_product"])
def test_sets_off_the_shared_grid_are_refused(name):
    rng = np.random.default_rng(1)
    a = grid_post(rng)
    moved = a["theta"].values.copy()
    moved[4] += 0.01
    with pytest.raises(ValueError, match=r"same grid.*differ"):
        mrfpe.distance(name, a, with_var(a, "theta", moved))
    smaller = a.isel(sample=slice(0, 20))
    with pytest.raises(ValueError, match=r"same grid.*25 distinct points.*20"):
        mrfpe.distance(name, a, smaller)
    with pytest.raises(ValueError, match=r"posteriors\[0\] and posteriors\[2\]"):
        get(name)().pairwise([a, grid_post(rng), smaller])


def test_flat_weight_vectors_have_a_defined_correlation():
    rng = np.random.default_rng(2)
    g = grid_points()
    flat, flat2, peaked = post(g), post(g[::-1]), grid_post(rng)
    corr = get("correlation")()
    assert corr.similarity(flat, flat2) == 1.0
    assert corr.similarity(flat, peaked) == 0.0
    assert corr.similarity(peaked, flat) == 0.0
    assert mrfpe.distance("correlation", flat, flat2) == 0.0


def test_negative_correlation_has_no_logarithm():
    g = grid_points()
    w = np.linspace(0.0, 1.0, len(g))
    a, b = post(g, np.log(w + 0.01)), post(g, np.log(1.01 - w))
    corr = get("correlation")()
    assert corr.similarity(a, b) < 0
    assert mrfpe.distance("correlation", a, b) > 1
    with pytest.raises(ValueError, match="negative"):
        corr.log_similarity(a, b)


def test_inner_product_of_a_spike_with_itself_is_one():
    g = grid_points()
    lw = np.full(len(g), -np.inf)
    lw[7] = 0.0
    spike = post(g, lw)
    assert get("inner_product")().similarity(spike, spike) == 1.0
    assert mrfpe.distance("inner_product", spike, spike) == 0.0


def test_map_uses_the_trace_when_present():
    theta = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    # the heaviest sample is #0, the best log target #2, the trace says (3, 4)
    a = post(theta, [5.0, 0.0, 0.0], log_target=[0.0, 1.0, 2.0],
             map_theta=[[9.0, 9.0], [3.0, 4.0]], map_log_target=[1.0, 2.0])
    b = post(np.zeros((2, 2)))
    assert mrfpe.distance("map_euclidean", a, b) == pytest.approx(5.0)


def test_map_falls_back_to_the_heaviest_point():
    theta = np.array([[0.0, 3.0], [0.0, 3.0], [4.0, 0.0], [1.0, 1.0]])
    # (0, 3) is present twice with 0.3 each: 0.6 in total beats (4, 0)'s 0.4
    a = post(theta, np.log([0.3, 0.3, 0.4, 1e-9])).drop_vars(["map_theta", "map_log_target"])
    b = post(np.zeros((1, 2))).drop_vars(["map_theta"])
    assert mrfpe.distance("map_euclidean", a, b) == pytest.approx(3.0)
    # a non-finite trace is ignored too
    c = post(theta, np.log([0.3, 0.3, 0.4, 1e-9]), map_theta=[[np.nan, 0.0]],
             map_log_target=[np.nan])
    assert mrfpe.distance("map_euclidean", c, b) == pytest.approx(3.0)


def test_map_matrix_is_the_euclidean_matrix_of_the_maps():
    rng = np.random.default_rng(3)
    maps = rng.random((4, 3))
    sets = [post(rng.random((5, 3)), map_theta=m[None], map_log_target=[0.0]) for m in maps]
    expect = np.linalg.norm(maps[:, None] - maps[None], axis=-1)
    np.testing.assert_allclose(get("map_euclidean")().pairwise(sets), expect, rtol=1e-12)
