"""The engine's public face: a frozen plan, read-only tables, one evaluate call."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mrfpe import brdf as B
from mrfpe.brdf.engine import (
    KERNELS,
    evaluate,
    kernel_family,
    lean_tables,
    make_plan,
    make_tables,
)
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.energy import build_tables
from mrfpe.targets import get


@pytest.fixture(scope="module")
def parts():
    model = B.get("phong")
    scene = make_scene(brdf="phong", theta=model.to_natural(np.array([0.5, 0.4, 0.3])),
                       shape=(8, 9), n_labels=5, surface="jagged", seed=1)
    data = build_tables(scene)
    n = scene.lattice.n_nodes
    unary = np.zeros((n, scene.n_labels))
    obs = scene.observed_labels.reshape(n).astype(np.int64)
    theta = np.random.default_rng(0).random((40, 3))
    coef = reflectance.coefficients(model, model.to_natural(theta))
    return scene, data, unary, obs, coef


def _plan(tables, kernel, dtype="float64"):
    return make_plan(tables, kernel=kernel, dtype=dtype, full=True, sigma_b=0.05, a=1.0,
                     b=-1.0)


@pytest.mark.parametrize("n", [1, 3, 40])
def test_lean_and_classic_agree_to_rounding(parts, n):
    _, data, unary, obs, coef = parts
    tables = make_tables(data, lean_tables(data, True), unary, obs)
    lean, classic = _plan(tables, "lean"), _plan(tables, "classic")
    assert lean.lean and not classic.lean
    for per_node in (False, True):
        a = evaluate(lean, tables, coef[:n], per_node=per_node)
        b = evaluate(classic, tables, coef[:n], per_node=per_node)
        assert a.shape == ((n, data.n_nodes) if per_node else (n,))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.max(np.abs(b)))


def test_evaluate_is_what_the_target_returns(parts):
    scene, *_ = parts
    t = get("pl", scene, sigma_b=0.05)
    theta = np.random.default_rng(1).random((6, 3))
    coef = reflectance.coefficients(t.model, t.model.to_natural(theta))
    np.testing.assert_array_equal(evaluate(t._plan, t._engine_tables, coef) + t._const_sum,
                                  t.log_prob(theta))


def test_plan_is_frozen_and_carries_the_kernels_units(parts):
    _, data, unary, obs, _ = parts
    tables = make_tables(data, lean_tables(data, True), unary, obs)
    plan = _plan(tables, "lean", "float32")
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.kernel = "classic"  # type: ignore[misc]
    assert plan.inv_sigma.dtype == np.float32 and plan.a.dtype == np.float32
    assert plan.inv_sigma == np.float32(1 / 0.05)
    assert plan.inv_sigma_log2 == np.float32(1 / 0.05 * 1.4426950408889634)
    assert plan.exponent_limit == 127.0 and _plan(tables, "lean").exponent_limit == 1023.0


def test_tables_are_read_only(parts):
    _, data, unary, obs, _ = parts
    tables = make_tables(data, lean_tables(data, True), unary, obs)
    arrays = [tables.unary, tables.unary_log2, tables.unary_log2_t, tables.obs, tables.chunks,
              data.var_feat, data.slot_ptr, tables.lean.rec, tables.lean.recT,
              tables.lean.nrec, tables.lean.nrecT]
    assert not any(a.flags.writeable for a in arrays)
    with pytest.raises(ValueError):
        tables.lean.rec[0, 0, 0] = 1.0
    # the classic-only tables hold no log2 copies
    bare = make_tables(data, None, unary, obs)
    assert bare.unary_log2 is None and not _plan(bare, "lean").lean


def test_growing_exponents_fall_back_to_classic_per_call(parts):
    _, data, unary, obs, coef = parts
    tables = make_tables(data, lean_tables(data, True), unary, obs)
    plan = _plan(tables, "lean")
    assert kernel_family(plan, tables, coef) == "lean"
    grow = coef.copy()
    big = 1e5 / max(1e-3, float(np.max(np.abs(tables.lean.g_range))))
    grow[0, 3], grow[1, 3] = big, -big  # one of them grows, whatever the sign of G1
    assert kernel_family(plan, tables, grow) == "classic"
    assert kernel_family(plan, tables, coef) == "lean"  # nothing remembered between calls


@pytest.mark.parametrize("bad", ["fast", "LEAN", 1, None])
def test_the_kernel_option_is_checked_by_name(parts, bad):
    scene, *_ = parts
    with pytest.raises(ValueError, match=r"kernel must be one of 'lean', 'classic'"):
        get("pls", scene, kernel=bad)
    assert KERNELS == ("lean", "classic")
    from mrfpe.targets import options

    opt = {o.name: o for o in options("pls")}["kernel"]
    assert opt.default == "lean"
