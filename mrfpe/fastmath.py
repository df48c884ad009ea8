"""Vectorisable math for numba kernels: the fast-math flags, exp, log and 2^x.

The one module the numerical kernels take their math from (the BRDF
pseudolikelihood engine, :mod:`mrfpe.mixture`, the declared models' simulators,
benchmarks). It imports only the leaf :mod:`mrfpe.threads`.

* :data:`FASTMATH` -- the value-safe fast-math flags every kernel compiles with;
* :func:`vexp`, :func:`vlog` (float64) and :func:`vexp32`, :func:`vlog32` (float32):
  ``exp`` and ``log`` written so that LLVM vectorises the loops around them
  (numba's libm calls do not); :func:`fexp` / :func:`flog` pick the precision
  from the argument, so a kernel compiles for either;
* :func:`exp2_32`, :func:`exp2_64` and :func:`fexp2`: ``2^x`` without the overflow
  clamp, for kernels that work in log2 units (the lean pseudolikelihood kernels);
* :func:`unary_intrinsic` and the bit casts (:func:`f64_as_i64`, ...) they are built from;
* :func:`compiled_features`: the CPU features numba compiles for, which decide
  :data:`SCALEF`.

Numba's vector width is a process setting chosen before the first compilation:
importing this module chooses it (:func:`mrfpe.threads.configure_vector_width`),
before :data:`SCALEF` is read from the features numba compiles for, so that every
importer sees the same kernels whichever module it imported first.
"""

from __future__ import annotations

import os
from typing import Any

import llvmlite.binding as ll
import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from mrfpe.threads import configure_vector_width

configure_vector_width()  # before SCALEF and any kernel below (mrfpe.threads explains why)

__all__ = ["FASTMATH", "HI32", "HI64", "LN2", "LOG2E", "SCALEF", "compiled_features", "exp2_32",
           "exp2_64", "f32_as_i32", "f64_as_i64", "fexp", "fexp2", "flog", "i32_as_f32",
           "i64_as_f64", "unary_intrinsic", "vexp", "vexp32", "vlog", "vlog32"]

LOG2E = 1.4426950408889634
LN2 = 0.6931471805599453
_F32 = np.float32


def compiled_features() -> frozenset[str]:
    """CPU features numba compiles for in this process (names without the ``+``).

    ``NUMBA_CPU_FEATURES`` if set (by the user, or by
    :func:`mrfpe.threads.configure_vector_width`); nothing for a CPU named by
    ``NUMBA_CPU_NAME`` other than ``host`` (e.g. ``generic`` for a portable cache: its
    features are not known here, so no feature is assumed); else the host's. Kernels
    that emit feature-specific code (AVX-512's ``vscalefps`` in :func:`exp2_32`)
    decide by this, so that code compiled for a portable target never relies on the host.
    """
    given = os.environ.get("NUMBA_CPU_FEATURES") or numba.config.CPU_FEATURES
    if given:
        return frozenset(f[1:] for f in given.split(",") if f.startswith("+"))
    name = os.environ.get("NUMBA_CPU_NAME") or numba.config.CPU_NAME
    if name and name != "host":
        return frozenset()
    return frozenset(k for k, on in ll.get_host_cpu_features().items() if on)


# Only value-safe fast-math flags: FMA contraction and ignoring the sign of
# zero. No 'nnan'/'ninf': +inf energies (forbidden labels) must survive.
FASTMATH = {"contract", "nsz"}


def unary_intrinsic(sig: Any, emit: Any) -> Any:
    """A one-argument numba intrinsic of signature ``sig`` whose LLVM code is
    ``emit(builder, x)`` (bit casts, conversions, LLVM's math intrinsics)."""

    def typer(typingctx: Any, x: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            return emit(builder, args[0])

        return sig, codegen

    return intrinsic(typer)


def _bitcast(ty: Any) -> Any:
    return lambda builder, x: builder.bitcast(x, ty)


# the float bits as an integer and back: the exp/log kernels' exponent arithmetic
f64_as_i64 = unary_intrinsic(types.int64(types.float64), _bitcast(ir.IntType(64)))
i64_as_f64 = unary_intrinsic(types.float64(types.int64), _bitcast(ir.DoubleType()))
f32_as_i32 = unary_intrinsic(types.int32(types.float32), _bitcast(ir.IntType(32)))
i32_as_f32 = unary_intrinsic(types.float32(types.int32), _bitcast(ir.FloatType()))


_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_MAGIC = 6755399441055744.0  # 1.5 * 2**52: adding it rounds to an integer kept in the low bits
_EXP_LO = -708.0
_EXP_HI = 709.0
# exp(r) = 1 + r + r^2 q(r) on |r| <= ln2/2, q a degree-8 Chebyshev fit of
# (exp(r) - 1 - r) / r^2: relative error 1.3e-15, and exp(0) = 1 exactly.
_Q0 = 0.5000000000000006
_Q1 = 0.16666666666648275
_Q2 = 0.04166666666661234
_Q3 = 0.008333333353731515
_Q4 = 0.001388888892257133
_Q5 = 0.00019841208731181392
_Q6 = 2.4801513441820437e-05
_Q7 = 2.762511659244919e-06
_Q8 = 2.762366872962597e-07


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def vexp(x):
    """``exp(x)`` for float64, branch-free so that loops over it vectorise.

    Cody-Waite reduction ``x = k ln2 + r`` (|r| <= ln2/2) with ``k`` rounded by
    the 1.5*2^52 trick (which also leaves ``k`` in the low bits, from which
    ``2^k`` is assembled), and a degree-10 polynomial for ``exp(r)``. Relative
    error <= 1.5e-15; returns 0 for ``x < -708`` (including ``-inf``) and
    saturates at ``exp(709)``.
    """
    xc = min(max(x, _EXP_LO), _EXP_HI)
    t = xc * LOG2E + _MAGIC
    k = t - _MAGIC
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = _Q8
    p = p * r + _Q7
    p = p * r + _Q6
    p = p * r + _Q5
    p = p * r + _Q4
    p = p * r + _Q3
    p = p * r + _Q2
    p = p * r + _Q1
    p = p * r + _Q0
    p = p * r + 1.0
    p = p * r + 1.0
    y = p * i64_as_f64((f64_as_i64(t) + 1023) << 52)
    return y * np.float64(x >= _EXP_LO)  # arithmetic select: y is finite


_SQRT2 = 1.4142135623730951


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def vlog(x):
    """``log(x)`` for positive normal float64, branch-free (vectorises).

    ``x = m 2^e`` with ``m`` in [sqrt(1/2), sqrt(2)), ``log m = 2 atanh(s)``,
    ``s = (m-1)/(m+1)``, |s| <= 0.172, series to ``s^23`` (< 1e-17).
    Only called on sums of exponentials that are >= 1.
    """
    bits = f64_as_i64(x)
    e = (bits >> 52) - 1023
    m = i64_as_f64((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000)
    big = np.float64(m > _SQRT2)  # arithmetic, not a branch: keeps the loop vectorised
    m = m * (1.0 - 0.5 * big)
    ef = np.float64(e) + big
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    q = 1.0 / 23.0
    q = q * s2 + 1.0 / 21.0
    q = q * s2 + 1.0 / 19.0
    q = q * s2 + 1.0 / 17.0
    q = q * s2 + 1.0 / 15.0
    q = q * s2 + 1.0 / 13.0
    q = q * s2 + 1.0 / 11.0
    q = q * s2 + 1.0 / 9.0
    q = q * s2 + 1.0 / 7.0
    q = q * s2 + 1.0 / 5.0
    q = q * s2 + 1.0 / 3.0
    q = q * s2 + 1.0
    return ef * _LN2_HI + (2.0 * s * q + ef * _LN2_LO)


_LOG2E_32 = _F32(1.4426950408889634)
_LN2_HI_32 = _F32(0.693359375)  # ln 2 = HI + LO, HI with 8 significant bits (Cephes)
_LN2_LO_32 = _F32(-2.12194440e-4)
_MAGIC_32 = _F32(12582912.0)  # 1.5 * 2**23
_EXP_LO_32 = _F32(-87.0)
_EXP_HI_32 = _F32(88.0)
_P0_32, _P1_32, _P2_32 = _F32(1.9875691500e-4), _F32(1.3981999507e-3), _F32(8.3334519073e-3)
_P3_32, _P4_32, _P5_32 = _F32(4.1665795894e-2), _F32(1.6666665459e-1), _F32(5.0000001201e-1)
_ONE_32 = _F32(1.0)
_HALF_32 = _F32(0.5)
_ZERO_32 = _F32(0.0)
_SQRT2_32 = _F32(1.4142135623730951)
_LN2_32 = _F32(0.6931471805599453)


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def vexp32(x):
    """``exp(x)`` for float32 (Cephes ``expf`` polynomial), branch-free; 0 below -87."""
    xc = min(max(x, _EXP_LO_32), _EXP_HI_32)
    t = xc * _LOG2E_32 + _MAGIC_32
    k = t - _MAGIC_32
    r = (xc - k * _LN2_HI_32) - k * _LN2_LO_32
    p = _P0_32
    p = p * r + _P1_32
    p = p * r + _P2_32
    p = p * r + _P3_32
    p = p * r + _P4_32
    p = p * r + _P5_32
    p = p * (r * r) + r + _ONE_32
    y = p * i32_as_f32((f32_as_i32(t) + np.int32(127)) << np.int32(23))
    return y * _F32(x >= _EXP_LO_32)  # arithmetic select: y is finite


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def vlog32(x):
    """``log(x)`` for positive normal float32, branch-free (series of 2 atanh(s) to s^11)."""
    bits = f32_as_i32(x)
    e = (bits >> np.int32(23)) - np.int32(127)
    m = i32_as_f32((bits & np.int32(0x007FFFFF)) | np.int32(0x3F800000))
    big = _F32(m > _SQRT2_32)
    m = m * (_ONE_32 - _HALF_32 * big)
    ef = _F32(e) + big
    s = (m - _ONE_32) / (m + _ONE_32)
    s2 = s * s
    q = _F32(1.0 / 11.0)
    q = q * s2 + _F32(1.0 / 9.0)
    q = q * s2 + _F32(1.0 / 7.0)
    q = q * s2 + _F32(1.0 / 5.0)
    q = q * s2 + _F32(1.0 / 3.0)
    q = q * s2 + _ONE_32
    return ef * _LN2_32 + _F32(2.0) * s * q


def fexp(x):  # pragma: no cover - replaced by the overload inside jitted code
    """Vectorisable exp for the argument's precision (:func:`vexp` or :func:`vexp32`)."""
    return np.exp(x)


def flog(x):  # pragma: no cover - replaced by the overload inside jitted code
    """Vectorisable log for the argument's precision (:func:`vlog` or :func:`vlog32`)."""
    return np.log(x)


@overload(fexp, inline="always")
def _ol_fexp(x):
    if x == types.float32:
        return lambda x: vexp32(x)
    return lambda x: vexp(x)


@overload(flog, inline="always")
def _ol_flog(x):
    if x == types.float32:
        return lambda x: vlog32(x)
    return lambda x: vlog(x)



# 2^r on [-1/2, 1/2], degree 5, c0 = 1 exactly: near-minimax in relative error (Lawson's
# iteration), c2 then nudged so that the error *as evaluated in float32* has zero mean
# (-3e-10; max 2.1e-7). Degree 5 is as accurate as float32 rounding, but the minimax
# polynomial's c0 = 1.00000007 rounds up to 1 + 2^-23 in float32 and biases every value by
# +5e-8, which adds up over a lattice (2.4e-6 relative in log_prob at a noise-free maximum).
_A0, _A1, _A2 = _F32(1.0), _F32(0.6931470036506653), _F32(0.24022264778614044)
_A3, _A4, _A5 = _F32(0.05550733581185341), _F32(0.009671509265899658), _F32(0.0013264708686619997)
_MAGIC32 = _F32(12582912.0)  # 1.5 * 2^23
_LO32, HI32 = _F32(-64.0), 127.0
# 2^r on [-1/2, 1/2], degree 10: Chebyshev interpolation (near-minimax), relative error 1.1e-15.
_B0, _B1, _B2 = 1.0000000000000004, 0.6931471805599518, 0.24022650695907977
_B3 = 0.055504108664445426
_B4, _B5, _B6 = 0.00961812910829982, 0.0013333558228510879, 0.00015403529656437398
_B7, _B8, _B9, _B10 = (1.5252657855294864e-05, 1.3215796261250824e-06, 1.0208689179691987e-07,
                       7.0180311126213455e-09)
_MAGIC64 = 6755399441055744.0  # 1.5 * 2^52
_LO64, HI64 = -512.0, 1023.0


#: Whether :func:`exp2_32` scales with AVX-512's ``vscalefps`` (the code is compiled for
#: AVX-512F and VL: :func:`compiled_features`) or with integer bit arithmetic.
SCALEF = {"avx512f", "avx512vl"} <= compiled_features()


def _call_llvm(name: str, ret: ir.Type, *args: ir.Type):
    """An ``emit`` for :func:`unary_intrinsic`: call LLVM's ``name``."""
    fnty = ir.FunctionType(ret, list(args))
    return lambda builder, *xs: builder.call(
        cgutils.get_or_insert_function(builder.module, fnty, name), list(xs))


#: ``round(x)`` to int32 in the current (nearest-even) mode: one ``cvtps2dq``.
_lrint_f32 = unary_intrinsic(types.int32(types.float32),
                             _call_llvm("llvm.lrint.i32.f32", ir.IntType(32), ir.FloatType()))
#: ``float32(k)`` (``cvtdq2ps``; LLVM shares it with :func:`_ldexp_f32`'s own).
_i32_to_f32 = unary_intrinsic(types.float32(types.int32),
                              lambda builder, k: builder.sitofp(k, ir.FloatType()))


@intrinsic
def _ldexp_f32(typingctx, x, k):
    """``x * 2^k`` (``llvm.ldexp``: ``vscalefps`` on AVX-512, a libm call elsewhere)."""
    emit = _call_llvm("llvm.ldexp.f32.i32", ir.FloatType(), ir.FloatType(), ir.IntType(32))

    def codegen(context, builder, signature, args):
        return emit(builder, *args)

    return types.float32(types.float32, types.int32), codegen


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def exp2_32(x):
    """``2^x`` for float32 and ``x <= 127``, branch-free; ``2^-64`` below ``2^-64``.

    Relative error 2.1e-7 (mean 0) on ``[-64, 127]``. The floor stands for values
    that are zero to every sum the kernels form (a label's weight beside the
    minimum's ``1``, a lobe beside its slot's Lambertian part) and keeps products
    with the tables far from denormals. ``k = round(x)``, ``p = 2^(x - k)`` by the
    polynomial, and ``2^k p`` is exact either way:

    * with AVX-512 (:data:`SCALEF`): ``k`` by ``cvtps2dq``, ``r`` by ``cvtdq2ps`` and a
      subtraction, the scaling by ``vscalefps`` -- 4 ops besides the polynomial, off
      the integer pipes (0.94-0.97x the Ward float32 kernel's time on Zen 4);
    * elsewhere: adding ``1.5 * 2^23`` leaves ``k`` in the low mantissa bits (two
      float ops give ``r``), and ``k << 23`` added to the bits of ``p`` scales it --
      an integer add where a multiply would need an FMA port.

    The two give the same bits (same ``k``, ``r`` and ``p``). Callers guarantee
    ``x <= 127`` (:func:`mrfpe.brdf.engine.template.exponent_bound`; the label
    log-sum-exp's arguments are ``<= 0``).
    """
    xc = max(x, _LO32)
    if SCALEF:
        k = _lrint_f32(xc)
        r = xc - _i32_to_f32(k)
    else:
        t = xc + _MAGIC32
        r = xc - (t - _MAGIC32)  # t - MAGIC = round(xc); no 'reassoc' flag, LLVM keeps the trick
    p = _A5
    p = p * r + _A4
    p = p * r + _A3
    p = p * r + _A2
    p = p * r + _A1
    p = p * r + _A0
    if SCALEF:
        return _ldexp_f32(p, k)
    return i32_as_f32(f32_as_i32(p) + (f32_as_i32(t) << np.int32(23)))


@njit(inline="always", fastmath=FASTMATH, error_model="numpy", cache=True)
def exp2_64(x):
    """``2^x`` for float64 and ``x <= 1023``, branch-free; ``2^-512`` below ``2^-512``.

    Relative error 1.2e-15 on ``[-512, 1023]``; as :func:`exp2_32` with ``1.5 * 2^52``
    and a degree-10 polynomial.
    """
    xc = max(x, _LO64)
    t = xc + _MAGIC64
    r = xc - (t - _MAGIC64)
    p = _B10
    p = p * r + _B9
    p = p * r + _B8
    p = p * r + _B7
    p = p * r + _B6
    p = p * r + _B5
    p = p * r + _B4
    p = p * r + _B3
    p = p * r + _B2
    p = p * r + _B1
    p = p * r + _B0
    return i64_as_f64(f64_as_i64(p) + (f64_as_i64(t) << 52))


def fexp2(x):  # pragma: no cover - replaced by the overload inside jitted code
    """``2^x`` for the argument's precision (:func:`exp2_32` or :func:`exp2_64`)."""
    return np.exp2(x)


@overload(fexp2, inline="always")
def _ol_fexp2(x):
    if x == types.float32:
        return lambda x: exp2_32(x)
    return lambda x: exp2_64(x)


