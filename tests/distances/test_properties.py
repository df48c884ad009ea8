"""Property suite run over EVERY registered distance (built-ins and installed plugins).

d(a, a) ≈ 0 for distances, symmetry exactly where declared (and genuinely
absent where not), non-negativity where declared, invariance to the order of
the samples, weights honoured (duplicating a sample = doubling its weight),
the all-pairs matrix equal to the pair calls, and the bad-input contract.
"""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe
import mrfpe.distances as distances
from mrfpe.distances.base import Distance

from ._helpers import duplicated_vs_doubled, grid_post, permuted, post, random_post, with_var

NAMES = distances.available()


def measure(name):
    return distances.get(name)()


def three_sets(name, seed=0):
    """Three different posteriors suitable for ``name`` (on one grid if it needs one)."""
    rng = np.random.default_rng(seed)
    if getattr(distances.get(name), "requires_grid", False):
        return grid_post(rng), grid_post(rng), grid_post(rng)
    return (random_post(rng, loc=0.0, scale=0.3), random_post(rng, loc=0.4, scale=0.5),
            random_post(rng, S=31, loc=-0.2, scale=0.2))


def close(x, y):
    return np.isclose(x, y, rtol=1e-8, atol=1e-10)


def test_the_built_ins_are_all_registered():
    builtin = {"kl", "symmetric_kl", "chernoff", "bhattacharyya", "matusita",
               "patrick_fisher", "mahalanobis", "agmmp", "emd", "sliced_wasserstein",
               "correlation", "inner_product", "map_euclidean"}
    assert builtin <= set(NAMES)
    assert not builtin & set(distances.broken())


@pytest.mark.parametrize("name", NAMES)
def test_values_are_finite_floats(name):
    a, b, c = three_sets(name)
    for x, y in ((a, b), (b, c), (a, a)):
        v = mrfpe.distance(name, x, y)
        assert isinstance(v, float) and np.isfinite(v)


@pytest.mark.parametrize("name", NAMES)
def test_self_distance_is_zero_for_distances(name):
    m = measure(name)
    if m.kind != "distance":
        pytest.skip("a similarity's distance form need not vanish at a = a")
    for x in three_sets(name):
        assert abs(m(x, x)) <= 1e-6
    a, b, _ = three_sets(name)
    assert m(a, b) > 1e-6  # and it does not vanish everywhere


@pytest.mark.parametrize("name", NAMES)
def test_symmetry_exactly_as_declared(name):
    m = measure(name)
    a, b, c = three_sets(name)
    pairs = ((a, b), (b, c), (a, c))
    if m.symmetric:
        for x, y in pairs:
            assert close(m(x, y), m(y, x))
    else:  # the flag is honest: some pair really is asymmetric
        assert any(not close(m(x, y), m(y, x)) for x, y in pairs)


@pytest.mark.parametrize("name", NAMES)
def test_nonnegative_where_declared(name):
    m = measure(name)
    if not getattr(m, "nonnegative", True):
        pytest.skip("declared as possibly negative (see its own tests)")
    a, b, c = three_sets(name)
    for x in (a, b, c):
        for y in (a, b, c):
            assert m(x, y) >= 0.0


@pytest.mark.parametrize("name", NAMES)
def test_invariant_to_sample_order(name):
    m = measure(name)
    rng = np.random.default_rng(5)
    a, b, _ = three_sets(name)
    ref = m(a, b)
    for _ in range(2):
        assert close(m(permuted(a, rng), permuted(b, rng)), ref)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("k", [0, 7])
def test_duplicating_a_sample_equals_doubling_its_weight(name, k):
    m = measure(name)
    a, b, _ = three_sets(name)
    dup, dbl = duplicated_vs_doubled(a, k)
    assert close(m(dup, b), m(dbl, b))
    assert close(m(b, dup), m(b, dbl))
    # and the change is visible: doubling a weight is not a no-op for weight-based measures
    if name not in ("map_euclidean",):
        assert not close(m(dbl, b), m(a, b)) or not close(m(b, dbl), m(b, a))


@pytest.mark.parametrize("name", NAMES)
def test_param_order_is_aligned_by_name(name):
    m = measure(name)
    a, b, _ = three_sets(name)
    b_rev = b.isel(param=slice(None, None, -1))
    assert list(b_rev["param"].values) != list(b["param"].values)
    assert close(m(a, b_rev), m(a, b))


@pytest.mark.parametrize("name", NAMES)
def test_pairwise_matrix_equals_pair_calls(name):
    m = measure(name)
    if not isinstance(m, Distance):
        pytest.skip("plugin without the base class: no pairwise hook")
    sets = three_sets(name)
    mat = m.pairwise(list(sets))
    expect = np.array([[m(x, y) for y in sets] for x in sets])
    np.testing.assert_allclose(mat, expect, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("name", NAMES)
def test_similarities_are_decreasing_in_the_distance_form(name):
    m = measure(name)
    if m.kind != "similarity":
        pytest.skip("not a similarity")
    a, b, c = three_sets(name)
    pairs = [(a, b), (a, c), (b, c), (a, a)]
    d = np.array([m(x, y) for x, y in pairs])
    s = np.array([m.similarity(x, y) for x, y in pairs])
    order = np.argsort(d)
    assert np.all(np.diff(s[order]) <= 1e-12)
    for (x, y), sv in zip(pairs, s):
        if sv > 0 and np.isfinite(sv):
            assert np.isclose(m.log_similarity(x, y), np.log(sv), rtol=1e-10)


# -- the bad-input contract ---------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_different_param_coordinates_raise(name):
    a, b, _ = three_sets(name)
    other = b.assign_coords(param=["alpha", "beta"])
    with pytest.raises(ValueError, match="param"):
        mrfpe.distance(name, a, other)


@pytest.mark.parametrize("name", NAMES)
def test_zero_total_weight_raises(name):
    a, b, _ = three_sets(name)
    dead = with_var(a, "log_weight", np.full(a.sizes["sample"], -np.inf))
    with pytest.raises(ValueError, match="zero total weight"):
        mrfpe.distance(name, dead, b)
    with pytest.raises(ValueError, match="zero total weight"):
        mrfpe.distance(name, b, with_var(a, "log_weight", np.full(a.sizes["sample"], np.nan)))


@pytest.mark.parametrize("name", NAMES)
def test_nan_samples_raise(name):
    a, _, _ = three_sets(name)
    theta = a["theta"].values.copy()
    theta[3, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        mrfpe.distance(name, a, with_var(a, "theta", theta))


@pytest.mark.parametrize("name", NAMES)
def test_not_a_posterior_raises(name):
    a, _, _ = three_sets(name)
    with pytest.raises(ValueError, match=r"xarray\.Dataset"):
        mrfpe.distance(name, a, a["theta"].values)
    with pytest.raises(ValueError, match="log_weight"):
        mrfpe.distance(name, a.drop_vars("log_weight"), a)


@pytest.mark.parametrize("name", NAMES)
def test_unknown_parameter_raises(name):
    a, b, _ = three_sets(name)
    with pytest.raises(ValueError, match="unknown parameter"):
        mrfpe.distance(name, a, b, no_such_parameter=1)


@pytest.mark.parametrize("name", NAMES)
def test_single_sample_set_error_or_value(name):
    m = measure(name)
    rng = np.random.default_rng(3)
    one = post(rng.random((1, 2)), [0.0])
    other = post(rng.random((1, 2)) if m.requires_grid else rng.random((9, 2)),
                 None if m.requires_grid else rng.standard_normal(9))
    if getattr(m, "min_samples", 1) > 1:
        with pytest.raises(ValueError, match="at least"):
            m(one, other)
    elif m.requires_grid:
        with pytest.raises(ValueError, match="same grid"):
            m(one, other)
        assert np.isfinite(m(one, one))
    else:
        assert np.isfinite(m(one, other))


@pytest.mark.parametrize("name", NAMES)
def test_collapsed_or_spiked_sets_give_finite_values(name):
    """A collapsed PMC set (one point repeated, or one weight holding all the mass)."""
    m = measure(name)
    rng = np.random.default_rng(4)
    a, b, _ = three_sets(name)
    lw = np.full(a.sizes["sample"], -np.inf)
    lw[2] = 0.0
    spiked = with_var(a, "log_weight", lw)
    sets = [spiked]
    if not m.requires_grid:
        sets.append(post(np.repeat(rng.random((1, 2)), 12, axis=0), rng.standard_normal(12)))
    for s in sets:
        for x, y in ((s, b), (b, s), (s, s)):
            assert np.isfinite(m(x, y))
