"""The fast-math leaf: what the code is compiled for, and that it stays a leaf."""

from __future__ import annotations

import numba
import numpy as np
from numba import njit

from mrfpe.fastmath import compiled_features, fexp, flog


def test_compiled_features_follow_numba_settings(monkeypatch):
    import llvmlite.binding as ll

    for var in ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(numba.config, "CPU_FEATURES", "")
    monkeypatch.setattr(numba.config, "CPU_NAME", None)
    host = {k for k, on in ll.get_host_cpu_features().items() if on}
    assert compiled_features() == host
    monkeypatch.setenv("NUMBA_CPU_FEATURES", "+avx2,-avx512f,+fma")
    assert compiled_features() == {"avx2", "fma"}  # a "-" feature is off, not on
    monkeypatch.delenv("NUMBA_CPU_FEATURES")
    monkeypatch.setenv("NUMBA_CPU_NAME", "generic")  # a portable target: nothing assumed
    assert compiled_features() == frozenset()
    monkeypatch.setenv("NUMBA_CPU_NAME", "host")
    assert compiled_features() == host


@njit(error_model="numpy")
def _exp_log(x, out_e, out_l):
    for i in range(x.shape[0]):
        out_e[i] = fexp(x[i])
        out_l[i] = flog(x[i])


def test_fexp_flog_follow_the_argument_precision():
    for dtype, rtol in ((np.float64, 2e-15), (np.float32, 3e-7)):
        x = np.linspace(1.0, 20.0, 101).astype(dtype)
        e, lg = np.empty_like(x), np.empty_like(x)
        _exp_log(x, e, lg)
        assert e.dtype == dtype
        np.testing.assert_allclose(e, np.exp(x.astype(np.float64)), rtol=rtol)
        np.testing.assert_allclose(lg, np.log(x.astype(np.float64)), rtol=rtol)


def test_fastmath_imports_only_the_threads_leaf():
    # it chooses numba's vector width (mrfpe.threads) before SCALEF and its kernels
    import ast
    import inspect

    import mrfpe.fastmath as fm

    tree = ast.parse(inspect.getsource(fm))
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert {m for m in mods if m and m.startswith("mrfpe")} == {"mrfpe.threads"}, mods
