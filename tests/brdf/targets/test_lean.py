"""The lean kernels against the classic ones (the ``kernel`` option) and the NumPy reference."""

from __future__ import annotations

import os

import numpy as np
import pytest
from numba import njit
from scipy.special import logsumexp

from mrfpe import brdf as B
from mrfpe.brdf.engine import kernel_family, lean_tables
from mrfpe.brdf.engine.lean import block_size
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.energy import energies_reference
from mrfpe.fastmath import fexp2
from mrfpe.targets import get

from ... import _processes as procs

CASES = [("ward", [0.7, 0.4, 0.45], "smooth"), ("phong", [0.5, 0.4, 0.3], "jagged"),
         ("ward_aniso", [0.7, 0.4, 0.45, 0.3], "smooth"),
         ("phong_aniso", [0.5, 0.4, 0.3, 0.5], "jagged"), ("lambertian", [0.7], "smooth")]


@njit(error_model="numpy")
def _map(x, out):
    for i in range(x.shape[0]):
        out[i] = fexp2(x[i])  # exp2_32 or exp2_64 by the argument's type


def test_exp2_accuracy_floor_and_unbiased_float32():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-512, 1023, 100_000), rng.uniform(-1, 1, 10_000), [0.0, -1.0]])
    o = np.empty_like(x)
    _map(x, o)
    np.testing.assert_allclose(o, np.exp2(x), rtol=1.5e-15, atol=0)
    x32 = np.concatenate([rng.uniform(-64, 127, 300_000), rng.uniform(-1, 1, 10_000),
                          [0.0, -1.0, 127.0, -64.0]]).astype(np.float32)
    o32 = np.empty_like(x32)
    _map(x32, o32)
    rel = o32 / np.exp2(x32.astype(np.float64)) - 1
    assert np.max(np.abs(rel)) < 2.2e-7
    # no persistent sign: a float32 bias adds up over a lattice's terms
    assert abs(rel.mean()) < 3e-9, rel.mean()
    # below the floor: the floor itself (normal, so no denormals downstream)
    low = np.array([-64.5, -100.0, -1e4, -np.inf], dtype=np.float32)
    ol = np.empty_like(low)
    _map(low, ol)
    np.testing.assert_array_equal(ol, np.float32(2.0 ** -64))
    low64 = np.array([-512.5, -1e4, -np.inf])
    o64 = np.empty_like(low64)
    _map(low64, o64)
    np.testing.assert_allclose(o64, 2.0 ** -512, rtol=1e-15)


_EXP2_BITS = """
import numpy as np, numba
from mrfpe.fastmath import SCALEF, fexp2
@numba.njit(error_model="numpy")
def m(x, out):
    for i in range(x.shape[0]):
        out[i] = fexp2(x[i])
x = np.concatenate([np.random.default_rng(0).uniform(-70, 127, 200_000),
                    [-64.0, -63.5, -0.5, 0.5, 126.5]]).astype(np.float32)
o = np.empty_like(x)
m(x, o)
print(SCALEF, o.view(np.int32).astype(np.int64).sum(), int(o.view(np.int32)[::997].sum()))
"""


def test_exp2_scalings_give_the_same_bits():
    """AVX-512's vscalefps and the integer exponent add: same k, r and p, so the same bits."""
    from mrfpe.fastmath import SCALEF, compiled_features

    assert SCALEF == ({"avx512f", "avx512vl"} <= compiled_features())
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CPU", "MRFPE_"))}
    here = procs.python(_EXP2_BITS, env=env).stdout.split()
    generic = procs.python(_EXP2_BITS, env={**env, "NUMBA_CPU_NAME": "generic"}).stdout.split()
    assert generic[0] == "False"  # a named CPU's features are not assumed
    assert here[1:] == generic[1:]


def test_growing_exponents_go_to_the_classic_kernel():
    from mrfpe.brdf.engine.template import exponent_bound
    from mrfpe.fastmath import HI32

    s = _scene("ward", [0.7, 0.4, 0.45], "smooth")
    t = get("pls", s, dtype="float32")
    lt = lean_tables(t._tables, False)
    assert lt.g_range[0, 0] >= 0 and lt.g_range[1].tolist() == [0.0, 0.0]
    decaying = np.array([[-30.0, 0.0]])
    assert exponent_bound(lt, decaying) <= 0 < HI32
    growing = np.array([[-30.0, 0.0], [1e6, 0.0]])  # not a Ward lobe: the bound says so
    assert exponent_bound(lt, growing) > HI32
    # the Ward tables hold log2 wF1, folded into the exponent: the bound includes it
    assert np.isfinite(lt.log_f_max) and exponent_bound(lt, np.zeros((1, 2))) == lt.log_f_max
    lam = lean_tables(get("pls", _scene("lambertian", [0.7], "smooth"))._tables, False)
    assert lam.log_f_max == -np.inf  # no lobe at all: every weight is 0
    # the per-call choice: growing exponents run the classic kernels, whatever the plan
    coef = np.zeros((2, 5))
    assert kernel_family(t._plan, t._engine_tables, coef) == "lean"
    coef[1, 3] = 1e6
    assert kernel_family(t._plan, t._engine_tables, coef) == "classic"
    assert kernel_family(get("pls", s, kernel="classic")._plan, t._engine_tables,
                         coef[:1]) == "classic"


def _scene(brdf, u, surface, shape=(9, 11), n_labels=7, seed=3):
    model = B.get(brdf)
    return make_scene(brdf=brdf, theta=model.to_natural(np.array(u)), shape=shape,
                      n_labels=n_labels, surface=surface, seed=seed)


def _points(d, n=70, seed=0):
    return np.random.default_rng(seed).random((n, d))


@pytest.mark.parametrize("brdf,u,surface", CASES)
@pytest.mark.parametrize("data_term", ["pixel", "triplet"])
def test_float64_matches_classic_and_numpy_reference(brdf, u, surface, data_term):
    s = _scene(brdf, u, surface)
    x = np.vstack([_points(len(u)), np.array(u)])
    for name in ("pls", "pml", "fit"):
        t = get(name, s, data_term=data_term)
        assert t._plan.lean and t._plan.kernel == "lean"
        tc = get(name, s, data_term=data_term, kernel="classic")
        assert not tc._plan.lean
        ref = tc.node_terms(x)
        ref_lp = tc.log_prob(x)
        new = t.node_terms(x)
        # relative to the scale of the values (a noise-free fit at the truth is ~1e-13)
        tol = 1e-12 * np.max(np.abs(ref_lp))
        np.testing.assert_allclose(new, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
        np.testing.assert_allclose(t.log_prob(x), ref_lp, rtol=1e-12, atol=tol)
        np.testing.assert_allclose(t.log_prob(x[:3]), ref_lp[:3], rtol=1e-12, atol=tol)
    # independent route: plain-numpy energies of every (node, label)
    t = get("pl", s, data_term=data_term)
    coef = reflectance.coefficients(t.model, t.model.to_natural(x))
    e = energies_reference(t._tables, coef, t.sigma_b)  # (N, n, B)
    obs = t._obs
    ell = -e[:, np.arange(obs.size), obs] - logsumexp(-e, axis=2)
    np.testing.assert_allclose(t.node_terms(x), ell, rtol=1e-12, atol=1e-11)


@pytest.mark.parametrize("brdf,u,surface", CASES[:2])
def test_float32_within_2e6(brdf, u, surface):
    s = _scene(brdf, u, surface, shape=(30, 30), n_labels=20, seed=2)
    x = np.vstack([_points(3, 300), np.array(u)])
    a = get("pls", s).log_prob(x)
    t32 = get("pls", s, dtype="float32")
    b = t32.log_prob(x)
    np.testing.assert_allclose(b, a, rtol=2e-6)
    # differences that matter for sampling: between points, relative to their size
    d64, d32 = a[:, None] - a[None, :], b[:, None] - b[None, :]
    assert np.max(np.abs(d32 - d64)) <= 2e-6 * np.max(np.abs(a))
    c = get("pls", s, dtype="float32", kernel="classic").log_prob(x)
    np.testing.assert_allclose(b, c, rtol=2e-6)
    np.testing.assert_allclose(t32.log_prob(x[:2]), b[:2], rtol=1e-6)  # labels-SIMD kernel
    np.testing.assert_allclose(sum(p.log_prob(x[:20]) for p in t32.partition(3)), b[:20],
                               rtol=1e-12)


def test_partitions_forbidden_labels_and_threads():
    s = _scene("ward", [0.7, 0.4, 0.45], "smooth", shape=(12, 12), n_labels=6)
    bel = np.ones((*s.lattice.node_shape, 6))
    forbid = (s.observed_labels + 1) % 6  # one non-observed label per node: infinite energy
    np.put_along_axis(bel, forbid[..., None], 0.0, axis=2)
    t = get("pl3", s, beliefs=bel / bel.sum(axis=2, keepdims=True))
    x = _points(3, 40)
    ref = get("pl3", s, beliefs=bel / bel.sum(axis=2, keepdims=True),
              kernel="classic").log_prob(x)
    lp = t.log_prob(x)
    assert np.all(np.isfinite(lp))
    np.testing.assert_allclose(lp, ref, rtol=1e-12)
    parts = t.partition(4, "block")
    np.testing.assert_allclose(sum(p.log_prob(x) for p in parts), lp, rtol=1e-12)
    import numba

    from mrfpe.threads import limit_threads
    with limit_threads(1):
        one = t.log_prob(x)
    with limit_threads(numba.config.NUMBA_NUM_THREADS):
        assert np.array_equal(t.log_prob(x), one)  # fixed chunk order


def test_tables_shared_read_only_and_the_kernel_option_checked():
    s = _scene("ward", [0.7, 0.4, 0.45], "smooth")
    t = get("pls", s)
    assert get("pl", s)._engine_tables.lean is t._engine_tables.lean  # one per scene
    assert not t._engine_tables.lean.rec.flags.writeable
    with pytest.raises(ValueError, match="kernel must be one of 'lean', 'classic'"):
        get("pls", s, kernel="fast")
    assert block_size(1000, 20, 4) % 16 == 0 and block_size(1, 40, 8) == 16


@pytest.mark.parametrize("brdf,n", [("phong", 40), ("phong", 1000), ("ward", 300)])
def test_values_do_not_depend_on_the_block(monkeypatch, brdf, n):
    import mrfpe.brdf.engine.lean as lean

    t = get("pls", _scene(brdf, [0.5, 0.4, 0.3], "jagged"), dtype="float32")
    x = np.random.default_rng(3).random((n, 3))
    want = t.log_prob(x)
    for bl in (16, 48, 1024):
        monkeypatch.setattr(lean, "block_size", lambda n, b, i, bl=bl: bl)
        assert np.array_equal(t.log_prob(x), want)
    sizes = [block_size(k, b, i) for k in (1, 100, 1000, 5000) for b in (10, 40) for i in (4, 8)]
    assert all(s % 16 == 0 and s <= lean.BLOCK_MAX for s in sizes)
    assert block_size(1000, 20, 4) * 20 * 4 <= lean.BLOCK_BYTES


def test_vector_width_opt_out_and_user_setting():
    code = ("import mrfpe.brdf.engine, mrfpe.threads as t, numba; "
            "print(t.configure_vector_width(), numba.config.CPU_FEATURES is None)")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU")}
    out = procs.python(code, env={**env, "MRFPE_AVX512": "0"}).stdout.split()
    assert out == ["opt-out", "True"]
    out = procs.python(code, env={**env, "NUMBA_CPU_NAME": "generic"}).stdout.split()
    assert out[0] == "user"
    code2 = ("import numba; numba.njit(lambda x: x)(1); import mrfpe.brdf.engine, "
             "mrfpe.threads as t; print(t.configure_vector_width())")
    out = procs.python(code2, env=env).stdout.split()
    assert out == ["late"]  # numba already built its target machine: left alone


def test_node_block_is_the_largest_that_keeps_two_blocks_per_thread():
    from mrfpe.brdf.engine.lean_nodes import NODE_BLOCK, NODE_BLOCK_MAX, node_block

    assert node_block(10201, 1) == NODE_BLOCK_MAX == 1024  # 100x100: 10 blocks
    assert node_block(10201, 2) == 1024
    assert node_block(2601, 2) == 512  # 50x50 on two threads: 6 blocks, not 3
    assert node_block(900, 1) == 512
    assert node_block(100, 4) == NODE_BLOCK  # never below the smallest block
    assert node_block(0, 0) == NODE_BLOCK


@pytest.mark.parametrize("brdf,u,surface", [CASES[0], CASES[3]])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_nodes_kernel_gives_the_same_bits_for_every_block_size(brdf, u, surface, dtype,
                                                               monkeypatch):
    import mrfpe.brdf.engine.lean_nodes as lean

    s = _scene(brdf, u, surface, shape=(40, 37), n_labels=6)
    t = get("pls", s, dtype=dtype)
    assert t._tables.n_nodes > 1024  # blocks of 1024 and of 256 cut it differently
    x = _points(len(u), n=3)
    got, asked = {}, []
    for nb in (256, 512, 1024):
        monkeypatch.setattr(lean, "node_block", lambda n, k, nb=nb: asked.append(nb) or nb)
        got[nb] = (t.log_prob(x), t.node_terms(x[:2]))
    assert asked == [256, 256, 512, 512, 1024, 1024]  # every call took the patched block
    for nb in (512, 1024):
        np.testing.assert_array_equal(got[nb][0], got[256][0])
        np.testing.assert_array_equal(got[nb][1], got[256][1])


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_nodes_kernel_isotropic_path_gives_the_same_bits_as_the_general_one(dtype, monkeypatch):
    import mrfpe.brdf.engine.lean_nodes as lean

    brdf, u, surface = CASES[1]  # isotropic Phong: every G2 = 0
    t = get("pls", _scene(brdf, u, surface, shape=(20, 23)), dtype=dtype)
    assert lean_tables(t._tables, True).isotropic
    aniso = get("pls", _scene(*CASES[3], shape=(20, 23)), dtype=dtype)
    assert not lean_tables(aniso._tables, True).isotropic

    x = _points(len(u), n=2)
    iso = [(t.log_prob(x[:k]), t.node_terms(x[:k])) for k in (1, 2)]
    kernel, taken = lean.lean_terms_nodes, []

    def general(coef, nb, full, iso, *rest):  # the same call down the general path
        taken.append(iso)
        return kernel(coef, nb, full, False, *rest)

    monkeypatch.setattr(lean, "lean_terms_nodes", general)
    for k, (lp, nt) in zip((1, 2), iso):
        np.testing.assert_array_equal(t.log_prob(x[:k]), lp)
        np.testing.assert_array_equal(t.node_terms(x[:k]), nt)
    assert taken == [True] * 4  # every call would have taken the isotropic path


@pytest.mark.parametrize("brdf,u,surface", [CASES[0], CASES[3]])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_small_batches_run_the_nodes_kernel_and_agree_with_large_ones(brdf, u, surface, dtype):
    from mrfpe.brdf.engine.lean_nodes import NODE_BLOCK

    # more nodes than a block, not a multiple of it: blocks cross the chunks
    s = _scene(brdf, u, surface, shape=(29, 31), n_labels=9)
    t = get("pls", s, dtype=dtype)
    assert t._tables.n_nodes > NODE_BLOCK and t._tables.n_nodes % NODE_BLOCK
    x = np.vstack([_points(len(u), n=40), np.array(u)])
    big = t.node_terms(x)
    lp = t.log_prob(x)
    rtol = 1e-12 if dtype == "float64" else 2e-6
    for k in (1, 2, 4):
        small = t.node_terms(x[:k])
        np.testing.assert_allclose(small, big[:k], rtol=rtol,
                                   atol=rtol * np.max(np.abs(big)))
        np.testing.assert_allclose(t.log_prob(x[:k]), lp[:k], rtol=rtol,
                                   atol=rtol * np.max(np.abs(lp)))
    ref = get("pls", s, dtype=dtype, kernel="classic").log_prob(x[:1])
    np.testing.assert_allclose(t.log_prob(x[:1]), ref, rtol=rtol, atol=rtol * abs(ref[0]))
