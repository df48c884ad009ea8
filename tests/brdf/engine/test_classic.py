"""The classic kernels against plain numpy, and the vectorisable exp / log of fastmath."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from mrfpe.brdf.engine.classic import BLOCK, block_size, classic_terms, classic_terms_labels
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.energy import DataTables, chunk_bounds, energies_reference
from mrfpe.fastmath import vexp, vlog


@njit(error_model="numpy")
def _map_exp(x, out):
    for i in range(x.shape[0]):
        out[i] = vexp(x[i])


@njit(error_model="numpy")
def _map_log(x, out):
    for i in range(x.shape[0]):
        out[i] = vlog(x[i])


def test_vexp_accuracy():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-708, 709, 200_000), rng.uniform(-1, 1, 10_000),
                        [0.0, -708.0, 709.0, -1e-300, 1e-300, np.log(2), -np.log(2) / 2]])
    out = np.empty_like(x)
    _map_exp(x, out)
    np.testing.assert_allclose(out, np.exp(x), rtol=2e-15, atol=0)
    assert out[-7] == 1.0
    low = np.array([-708.5, -1e5, -np.inf])
    o = np.empty(3)
    _map_exp(low, o)
    np.testing.assert_array_equal(o, 0.0)


def test_vlog_accuracy():
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(1, 64, 100_000), np.exp(rng.uniform(-700, 700, 10_000)),
                        [1.0, np.sqrt(2), 2.0, 1e-300]])
    out = np.empty_like(x)
    _map_log(x, out)
    np.testing.assert_allclose(out, np.log(x), rtol=1e-15, atol=4.5e-16)
    assert out[-4] == 0.0


def test_block_size():
    for n in (1, 7, 8, 9, 63, 64, 65, 1000, 4097):
        bl = block_size(n)
        assert bl % 8 == 0 and 8 <= bl <= BLOCK
        assert -(-n // bl) == -(-n // BLOCK) or n <= BLOCK


def _random_tables(rng, n_nodes=23, B=5, full=True):
    ns = rng.integers(1, 5, n_nodes)
    slot_ptr = np.concatenate([[0], np.cumsum(ns)]).astype(np.int64)
    n_slots = slot_ptr[-1]
    nvar = rng.integers(1, 3, n_slots).astype(np.int64)
    nv_node = np.add.reduceat(nvar, slot_ptr[:-1])
    var_ptr = np.concatenate([[0], np.cumsum(nv_node * B)]).astype(np.int64)
    feat = np.vstack([rng.random((3, var_ptr[-1])), rng.random((2, var_ptr[-1])) * 3])
    fix = np.vstack([rng.random((3, n_slots)), rng.random((2, n_slots)) * 3])
    fix[:, nvar == 2] = 0.0
    if not full:
        feat[[2, 4]] = 0.0
        fix[[2, 4]] = 0.0
    return DataTables(nodes=np.arange(n_nodes), slot_ptr=slot_ptr, slot_y=rng.random(n_slots),
                      slot_w=np.where(rng.random(n_slots) < 0.5, 0.5, 1.0), slot_nvar=nvar,
                      fix_feat=fix, var_ptr=var_ptr, var_feat=feat, n_labels=B,
                      data_term="pixel")


def _run(tab, coef, unary, obs, sigma, a, b, per_node, full=True, labels=False,
         chunk_entries=17):
    N = coef.shape[0]
    bl = block_size(N)
    npad = N if labels else -(-N // bl) * bl
    ct = np.empty((5, npad))
    ct[:, :N] = coef.T
    ct[:, N:] = coef[:1].T
    chunks = chunk_bounds(tab.var_ptr, chunk_entries)
    oc = np.zeros((chunks.shape[0] - 1, npad))
    on = np.zeros((tab.n_nodes, npad)) if per_node else np.zeros((1, 1))
    args = (tab.slot_ptr, tab.slot_y, tab.slot_w, tab.slot_nvar, tab.fix_feat, tab.var_ptr,
            tab.var_feat, unary, obs, 1.0 / sigma, chunks, a, b, b != 0, oc, on, per_node)
    if labels:
        classic_terms_labels(ct, full, *args)
    else:
        classic_terms(ct, bl, full, *args)
    return on[:, :N].T if per_node else oc[:, :N].sum(axis=0)


@pytest.mark.parametrize("labels", [False, True])
@pytest.mark.parametrize("full", [True, False])
@pytest.mark.parametrize("N", [1, 13, 70])
def test_kernel_matches_numpy(full, N, labels):
    rng = np.random.default_rng(N)
    tab = _random_tables(rng, full=full)
    coef = np.column_stack([rng.random((N, 3)), -rng.random((N, 2)) * 4])
    if not full:
        coef[:, [2, 4]] = 0.0
    unary = rng.random((tab.n_nodes, tab.n_labels)) * 2
    unary[0, 1] = np.inf  # a forbidden label
    obs = rng.integers(0, tab.n_labels, tab.n_nodes)
    obs[0] = 0
    sigma = 0.07
    E = energies_reference(tab, coef, sigma) + unary[None]
    own = E[:, np.arange(tab.n_nodes), obs]
    m = E.min(axis=2)
    lse = -m + np.log(np.exp(-(E - m[..., None])).sum(axis=2))
    for a, b in ((1.0, -1.0), (1.0, 0.0), (0.0, 1.0), (0.5, 2.0)):
        want = a * (-own) + b * lse
        got_nodes = _run(tab, coef, unary, obs, sigma, a, b, True, full, labels)
        np.testing.assert_allclose(got_nodes, want, rtol=1e-13, atol=1e-12)
        got = _run(tab, coef, unary, obs, sigma, a, b, False, full, labels)
        np.testing.assert_allclose(got, want.sum(axis=1), rtol=1e-13, atol=1e-11)


def test_separable_reference_radiance():
    rng = np.random.default_rng(3)
    coef = rng.random((4, 5))
    feat = rng.random((6, 5))
    r = reflectance.radiance(coef, feat)
    want = np.array([[c[0] * f[0] + (c[1] * f[1] + c[2] * f[2]) * np.exp(c[3] * f[3] + c[4] * f[4])
                      for f in feat] for c in coef])
    np.testing.assert_allclose(r, want, rtol=1e-15)


def test_chunks_are_deterministic_and_cover():
    rng = np.random.default_rng(5)
    tab = _random_tables(rng, n_nodes=200)
    c = chunk_bounds(tab.var_ptr, 64)
    assert c[0] == 0 and c[-1] == 200 and np.all(np.diff(c) > 0)
    np.testing.assert_array_equal(c, chunk_bounds(tab.var_ptr, 64))


def test_float32_exp_log():
    from mrfpe.fastmath import vexp32, vlog32

    @njit(error_model="numpy")
    def both(x, y, ox, oy):
        for i in range(x.shape[0]):
            ox[i] = vexp32(x[i])
            oy[i] = vlog32(y[i])

    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-87, 88, 50_000), [0.0, -87.0, -88.0, -np.inf]]).astype(
        np.float32)
    y = np.concatenate([rng.uniform(1, 64, 50_000), [1.0, 2.0, 1.5, 3.0]]).astype(np.float32)
    ox, oy = np.empty_like(x), np.empty_like(y)
    both(x, y, ox, oy)
    assert ox.dtype == np.float32
    np.testing.assert_allclose(ox[:-2], np.exp(x[:-2].astype(float)), rtol=2e-7)
    assert ox[-2] == 0.0 and ox[-1] == 0.0
    np.testing.assert_allclose(oy, np.log(y.astype(float)), rtol=0, atol=5e-7)


@pytest.mark.parametrize("labels", [False, True])
def test_float32_kernel_close_to_numpy(labels):
    rng = np.random.default_rng(11)
    tab = _random_tables(rng)
    N = 3 if labels else 40
    coef = np.column_stack([rng.random((N, 3)), -rng.random((N, 2)) * 4])
    unary = rng.random((tab.n_nodes, tab.n_labels))
    obs = rng.integers(0, tab.n_labels, tab.n_nodes)
    E = energies_reference(tab, coef, 0.07) + unary[None]
    want = (-E[:, np.arange(tab.n_nodes), obs]
            - np.log(np.exp(-E).sum(axis=2))).sum(axis=1)
    t32 = tab.astype(np.float32)
    bl = block_size(N)
    npad = N if labels else -(-N // bl) * bl
    ct = np.zeros((5, npad), dtype=np.float32)
    ct[:, :N] = coef.T
    chunks = chunk_bounds(tab.var_ptr, 17)
    oc = np.zeros((chunks.shape[0] - 1, npad))
    args = (t32.slot_ptr, t32.slot_y, t32.slot_w, t32.slot_nvar, t32.fix_feat, t32.var_ptr,
            t32.var_feat, unary.astype(np.float32), obs, np.float32(1 / 0.07), chunks,
            np.float32(1), np.float32(-1), True, oc, np.zeros((1, 1)), False)
    if labels:
        classic_terms_labels(ct, True, *args)
    else:
        classic_terms(ct, bl, True, *args)
    np.testing.assert_allclose(oc[:, :N].sum(axis=0), want, rtol=2e-6)
