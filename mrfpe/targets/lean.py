"""The lean pseudolikelihood kernel: one fused particle loop per (node, label), fixed template.

Same per-node terms as :mod:`mrfpe.targets.kernels` (``a * (-E_i(x_i)) + b *
log sum_s exp(-E_i(s))``), with the pixel data term's structure baked in:

* **Template.** Every node has four *positions* (slots): positions 0 and 1 hold
  two variable triangles each (the pixels whose TL-BR diagonal passes through
  the node), positions 2 and 3 one variable and one fixed triangle (the other two
  pixels). Boundary nodes get zero-weight positions, whose term is ``|0 - 0|``;
  a slot that does not fit (the triplet form's four single slots) goes to a
  free two-triangle position with its fixed triangle repeated for every label.
  The inner loop over a block of particles is then straight-line code: six
  exponentials, four absolute values, no per-triangle loops, no aliasing checks.
* **Precomputed, once per table.** Per (node, position, label) ``A = w * sum F0``
  of the position's triangles (variable and fixed), per triangle ``w * F1``
  (``w * F2``), so that a slot's prediction is ``c0 A + c1 S1 + c2 S2`` with
  ``S = sum w F exp(...)``: ``c0`` and ``c1`` are factored out of the triangle sums.
  ``1/sigma_b`` multiplies the sum of a label's four slot terms (one FMA, not
  four), so the tables do not depend on ``sigma_b`` or the unary energies and are
  cached on the :class:`~mrfpe.targets.energy.DataTables` they come from.
* **Ward form: weights in the exponent.** Where there is no second lobe term
  (Lambertian, Ward) the tables hold ``log2(w F1)`` in place of ``w F1``, so that
  ``w F1 2^(e1 G1) = 2^(e1 G1 + log2(w F1))``: the exponent's multiply becomes an
  FMA and a multiply per triangle goes (a zero weight is ``-inf``, whose ``exp2`` is
  the floor below; a negative one, which no built-in model has, sends the table to
  the classic kernel). :func:`exponent_bound` includes the largest of them.
* **exp.** :func:`exp2_32` / :func:`exp2_64`: ``2^x`` by rounding ``x`` with the
  1.5 * 2^23 (2^52) trick and a degree-5 (degree-10) polynomial for ``2^r``,
  ``|r| <= 1/2``, scaled by an integer add to its exponent bits (float32 with
  AVX-512: ``cvtps2dq`` and ``vscalefps``, the same bits; :data:`SCALEF`); the per-particle
  exponents are pre-multiplied by log2(e). Below ``2^-64`` (``2^-512``) the result
  is ``2^-64`` (``2^-512``): no denormals downstream, no clamp-and-select; there is
  no overflow clamp either, so :func:`~mrfpe.targets.dispatch.pl_terms` sends
  particles whose exponents could exceed 127 (1023) to the classic kernel.

Layout (:class:`LeanTables`): ``rec[i, k, s]`` -- field ``k`` of node ``i`` at label
``s``, labels contiguous so that the particles-as-SIMD kernel loads scalars that
stay in L1 (:class:`LeanTablesT`: the node-major copy, for a few particles) --
fields ``A_0..A_3``, then per template triangle ``t = 0..5``: ``wF1, G1`` (and
``wF2, G2`` for the full form; ``log2 wF1, G1`` for the Ward form); ``nrec[i, k]``:
``y_0..y_3``, then the two fixed triangles' ``wF1, G1 (, wF2, G2)`` (positions 2 and 3;
``log2 wF1`` likewise).

Numba compiles these kernels for the host's widest vectors (512-bit with
AVX-512; :func:`mrfpe.threads.configure_vector_width`, called by
:mod:`mrfpe.targets.kernels` before its first ``@njit``, explains the process-wide
setting and its opt-out ``MRFPE_AVX512=0``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from mrfpe.targets.energy import DataTables
from mrfpe.targets.kernels import (
    _FM,
    _f32_as_i32,
    _f64_as_i64,
    _i32_as_f32,
    _i64_as_f64,
    _unary_intrinsic,
    flog,
)
from mrfpe.threads import compiled_features

__all__ = ["BLOCK_BYTES", "BLOCK_MAX", "HI32", "HI64", "LOG2E", "NODE_BLOCK", "NODE_BLOCK_MAX",
           "SCALEF", "LeanTables", "LeanTablesT", "block_size", "exp2_32", "exp2_64",
           "exponent_bound", "fexp2", "lean_tables", "lean_tables_t", "lean_terms",
           "lean_terms_nodes", "node_block"]

LOG2E = 1.4426950408889634
_LN2 = 0.6931471805599453
_F32 = np.float32
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
#: AVX-512F and VL: :func:`mrfpe.threads.compiled_features`) or with integer bit arithmetic.
SCALEF = {"avx512f", "avx512vl"} <= compiled_features()


def _call_llvm(name: str, ret: ir.Type, *args: ir.Type):
    """An ``emit`` for :func:`~mrfpe.targets.kernels._unary_intrinsic`: call LLVM's ``name``."""
    fnty = ir.FunctionType(ret, list(args))
    return lambda builder, *xs: builder.call(
        cgutils.get_or_insert_function(builder.module, fnty, name), list(xs))


#: ``round(x)`` to int32 in the current (nearest-even) mode: one ``cvtps2dq``.
_lrint_f32 = _unary_intrinsic(types.int32(types.float32),
                             _call_llvm("llvm.lrint.i32.f32", ir.IntType(32), ir.FloatType()))
#: ``float32(k)`` (``cvtdq2ps``; LLVM shares it with :func:`_ldexp_f32`'s own).
_i32_to_f32 = _unary_intrinsic(types.float32(types.int32),
                              lambda builder, k: builder.sitofp(k, ir.FloatType()))


@intrinsic
def _ldexp_f32(typingctx, x, k):
    """``x * 2^k`` (``llvm.ldexp``: ``vscalefps`` on AVX-512, a libm call elsewhere)."""
    emit = _call_llvm("llvm.ldexp.f32.i32", ir.FloatType(), ir.FloatType(), ir.IntType(32))

    def codegen(context, builder, signature, args):
        return emit(builder, *args)

    return types.float32(types.float32, types.int32), codegen


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
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
    ``x <= 127`` (:func:`exponent_bound`; the label log-sum-exp's arguments are ``<= 0``).
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
    return _i32_as_f32(_f32_as_i32(p) + (_f32_as_i32(t) << np.int32(23)))


@njit(inline="always", fastmath=_FM, error_model="numpy", cache=True)
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
    return _i64_as_f64(_f64_as_i64(p) + (_f64_as_i64(t) << 52))


def fexp2(x):  # pragma: no cover - replaced by the overload inside jitted code
    """``2^x`` for the argument's precision (:func:`exp2_32` or :func:`exp2_64`)."""
    return np.exp2(x)



@overload(fexp2, inline="always")
def _ol_fexp2(x):
    if x == types.float32:
        return lambda x: exp2_32(x)
    return lambda x: exp2_64(x)


# -- tables ---------------------------------------------------------------------------------

#: Positions (slots) per node and variable triangles of the template.
N_POS, N_TRI = 4, 6
_POS_TRI = ((0, 1), (2, 3), (4,), (5,))  # template triangles of each position


@dataclass(frozen=True)
class LeanTables:
    """Template tables of a set of nodes (module docstring). ``full``: F2/G2 fields present."""

    rec: np.ndarray   # (n, 4 + 6 * nf, B)
    nrec: np.ndarray  # (n, 4 + 2 * nf)
    full: bool
    g_range: np.ndarray  # (2, 2): min and max of G1 and G2 over every triangle (0 if absent)
    log_f_max: float = 0.0  # Ward form: the largest log2(wF1) in the tables (-inf if none)

    @property
    def nbytes(self) -> int:
        return int(self.rec.nbytes + self.nrec.nbytes)

    @property
    def isotropic(self) -> bool:
        """The full form with every ``G2 = 0`` (isotropic Phong): ``E1 G1 + E2 G2`` is
        ``E1 G1`` exactly, so the kernels leave the ``G2`` rows unread."""
        return bool(self.full and not np.any(self.g_range[1]))


def _pack(t: DataTables, full: bool) -> LeanTables | None:
    """Template tables of ``t``, or None if a node's slots do not fit the template."""
    n, B = t.n_nodes, t.n_labels
    nf = 4 if full else 2
    ft = t.var_feat.dtype
    rec = np.zeros((n, N_POS + N_TRI * nf, B))
    nrec = np.zeros((n, N_POS + 2 * nf))
    nslot = np.diff(t.slot_ptr)
    nvar = t.slot_nvar
    if nvar.size == 0:
        return LeanTables(rec.astype(ft), nrec.astype(ft), full, np.zeros((2, 2)))
    if nslot.max() > N_POS or nvar.min() < 1 or nvar.max() > 2:
        return None
    node = np.repeat(np.arange(n, dtype=np.int64), nslot)
    start = t.slot_ptr[node]
    dbl = nvar == 2
    cd = np.concatenate([[0], np.cumsum(dbl)])
    cs = np.concatenate([[0], np.cumsum(~dbl)])
    j = np.arange(nvar.size)
    rank_d = cd[j] - cd[start]
    rank_s = cs[j] - cs[start]
    n_d = cd[t.slot_ptr[1:]] - cd[t.slot_ptr[:-1]]
    pos = np.where(dbl, rank_d, np.where(rank_s < 2, 2 + rank_s, n_d[node] + rank_s - 2))
    if np.any(dbl & (rank_d >= 2)) or np.any(pos >= N_POS):
        return None
    cv = np.concatenate([[0], np.cumsum(nvar)])
    tstart = cv[j] - cv[start]
    w = t.slot_w.astype(np.float64)
    labels = np.arange(B)
    feat = t.var_feat.astype(np.float64)
    fix = t.fix_feat.astype(np.float64)
    nrec[node, pos] = t.slot_y
    fields = (1, 3, 2, 4)[:nf]  # wF1, G1, wF2, G2
    scaled = (True, False, True, False)[:nf]
    for k in range(2):
        sel = np.flatnonzero(nvar > k)
        e = t.var_ptr[node[sel]][:, None] + (tstart[sel] + k)[:, None] * B + labels  # (m, B)
        rec[node[sel], pos[sel]] += w[sel, None] * feat[0, e]
        tri = np.where(pos[sel] < 2, 2 * pos[sel] + k, pos[sel] + 2)
        for q, (fld, sc) in enumerate(zip(fields, scaled)):
            v = feat[fld, e]
            rec[node[sel], N_POS + nf * tri + q] = w[sel, None] * v if sc else v
    one = np.flatnonzero(nvar == 1)  # slots with a fixed triangle (zero features if none)
    rec[node[one], pos[one]] += (w[one] * fix[0, one])[:, None]
    in_fixed = one[pos[one] >= 2]
    in_double = one[pos[one] < 2]
    for q, (fld, sc) in enumerate(zip(fields, scaled)):
        v = w * fix[fld] if sc else fix[fld]
        nrec[node[in_fixed], N_POS + nf * (pos[in_fixed] - 2) + q] = v[in_fixed]
        # a single slot in a two-triangle position: its fixed triangle repeated per label
        rec[node[in_double], N_POS + nf * (2 * pos[in_double] + 1) + q] = v[in_double, None]
    log_f_max = 0.0
    if not full:  # fold wF1 into the exponent: wF1 2^(e1 G1) = 2^(e1 G1 + log2 wF1)
        f_rec = rec[:, N_POS:N_POS + N_TRI * nf:nf]  # views: written in place below
        f_nrec = nrec[:, N_POS:N_POS + 2 * nf:nf]
        if min(f_rec.min(initial=0.0), f_nrec.min(initial=0.0)) < 0:
            return None  # a negative lobe weight has no logarithm: the classic kernel
        with np.errstate(divide="ignore"):  # zero weights (padding, Lambertian): -inf
            log_f_max = float(np.log2(max(f_rec.max(initial=0.0), f_nrec.max(initial=0.0))))
            np.log2(f_rec, out=f_rec)
            np.log2(f_nrec, out=f_nrec)
    rec, nrec = rec.astype(ft), nrec.astype(ft)
    g_range = np.zeros((2, 2))
    for q in range(nf // 2):  # the G fields: N_POS + nf * triangle + 2 q + 1 in rec and nrec
        k = N_POS + 2 * q + 1
        g = np.concatenate([rec[:, k::nf].ravel(), nrec[:, k::nf].ravel()])
        g_range[q] = g.min(), g.max()
    return LeanTables(np.ascontiguousarray(rec), np.ascontiguousarray(nrec), full, g_range,
                      log_f_max)


def exponent_bound(lt: LeanTables, e: np.ndarray) -> float:
    """Largest exponent ``E1 G1 + E2 G2`` (plus ``log2 wF1`` in the Ward form) the kernels
    can meet for the particles' exponent coefficients ``e`` ((N, 2), log2 units):
    :func:`exp2_32` and :func:`exp2_64` need it below :data:`HI32` / :data:`HI64`."""
    e = np.asarray(e, dtype=np.float64)
    lo, hi = lt.g_range[:, 0], lt.g_range[:, 1]
    bound = np.max(np.maximum(e * lo, e * hi).sum(axis=1), initial=-np.inf)
    return float(bound if lt.full else bound + lt.log_f_max)


def lean_tables(t: DataTables, full: bool) -> LeanTables | None:
    """The template tables of ``t`` (built once and kept on ``t``), None if they do not fit."""
    key = "_lean_full" if full else "_lean"
    cache = t.__dict__
    if key not in cache:
        object.__setattr__(t, key, _pack(t, full))  # frozen dataclass: tables never change
    return cache[key]


#: Bytes of one block's (labels x particles) energy buffer, and the block's largest size.
BLOCK_BYTES, BLOCK_MAX = 131072, 1024


def block_size(n: int, n_labels: int, itemsize: int) -> int:
    """Particles per block of the lean kernel: a multiple of 16, blocks of near-equal size.

    Long blocks amortise each label's loop set-up (its table values broadcast to
    vectors, and spilled: the loop body keeps more constants than there are vector
    registers) over more particles. The block's (labels x particles) energies take up
    to :data:`BLOCK_BYTES` (L2, not L1: measured on Zen 4, 100 x 100, N = 1000, one
    process, alternated, medians of 7, float32 Ward 20 labels 0.91x and 40 labels
    0.83x, Phong 20 labels 0.85x the time of a 16 KiB buffer; float64 0.92x).
    The result does not depend on the block size (each particle's node sums run in
    node order whatever the block).
    """
    cap = max(64, min(BLOCK_MAX, (BLOCK_BYTES // max(1, n_labels * itemsize)) // 16 * 16))
    n_blocks = -(-max(int(n), 1) // cap)
    per = -(-max(int(n), 1) // n_blocks)
    return int(-(-per // 16) * 16)


# -- kernels --------------------------------------------------------------------------------


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def lean_terms(coef, bl, full, rec, nrec, unary, obs, inv_sigma, chunk_ptr, a, b,
               do_lse, out_chunk, out_node, per_node):  # pragma: no cover - compiled
    """Per-node terms with a block of ``bl`` particles as the SIMD lanes.

    Parameters
    ----------
    coef : (5, Npad) float32 or float64
        ``(c0, c1, c2, e1 log2e, e2 log2e)`` per particle; its dtype is the
        kernel's precision (``rec``, ``nrec``, ``unary``, ``inv_sigma``, ``a``,
        ``b`` share it). Node terms are accumulated in float64.
    bl : int
        Particles per block; ``Npad`` is a multiple of it.
    full : bool
        Whether the F2/G2 fields are present (not Lambertian or Ward).
    rec, nrec : template tables (:class:`LeanTables`).
    unary : (n, B)
        Theta-independent energies times log2(e): the kernel works in log2 units, so
        the label log-sum-exp needs no multiply and loses no accuracy to one.
    obs : (n,) int64
    inv_sigma : ``log2(e) / sigma_b``.
    chunk_ptr, a, b, do_lse, out_chunk, out_node, per_node
        As :func:`mrfpe.targets.kernels.pl_terms`.
    """
    n_chunks = chunk_ptr.shape[0] - 1
    npad = coef.shape[1]
    af = float(a)  # the node terms are combined in float64
    bf = float(b)
    nblk = npad // bl
    B = unary.shape[1]
    for c in prange(n_chunks):
        buf = np.empty((B, bl), dtype=coef.dtype)
        fa1 = np.empty(bl, dtype=coef.dtype)
        fa2 = np.empty(bl, dtype=coef.dtype)
        fb1 = np.empty(bl, dtype=coef.dtype)
        fb2 = np.empty(bl, dtype=coef.dtype)
        mn = np.empty(bl, dtype=coef.dtype)
        ssum = np.empty(bl, dtype=coef.dtype)
        acc = np.empty(bl)
        for blk in range(nblk):
            q0 = blk * bl
            c0 = coef[0, q0:q0 + bl]
            c1 = coef[1, q0:q0 + bl]
            c2 = coef[2, q0:q0 + bl]
            e1 = coef[3, q0:q0 + bl]
            e2 = coef[4, q0:q0 + bl]
            for p in range(bl):
                acc[p] = 0.0
            for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                y0 = nrec[i, 0]
                y1 = nrec[i, 1]
                y2 = nrec[i, 2]
                y3 = nrec[i, 3]
                r = rec[i]
                if full:
                    ha1 = nrec[i, 4]
                    ga1 = nrec[i, 5]
                    ha2 = nrec[i, 6]
                    ga2 = nrec[i, 7]
                    hb1 = nrec[i, 8]
                    gb1 = nrec[i, 9]
                    hb2 = nrec[i, 10]
                    gb2 = nrec[i, 11]
                    for p in range(bl):  # fixed triangles: once per node, not per label
                        xa = fexp2(e1[p] * ga1 + e2[p] * ga2)
                        xb = fexp2(e1[p] * gb1 + e2[p] * gb2)
                        fa1[p] = ha1 * xa
                        fa2[p] = ha2 * xa
                        fb1[p] = hb1 * xb
                        fb2[p] = hb2 * xb
                    for s in range(B):
                        u = unary[i, s]
                        a0 = r[0, s]
                        a1 = r[1, s]
                        a2 = r[2, s]
                        a3 = r[3, s]
                        f01, g01, f02, g02 = r[4, s], r[5, s], r[6, s], r[7, s]
                        f11, g11, f12, g12 = r[8, s], r[9, s], r[10, s], r[11, s]
                        f21, g21, f22, g22 = r[12, s], r[13, s], r[14, s], r[15, s]
                        f31, g31, f32, g32 = r[16, s], r[17, s], r[18, s], r[19, s]
                        f41, g41, f42, g42 = r[20, s], r[21, s], r[22, s], r[23, s]
                        f51, g51, f52, g52 = r[24, s], r[25, s], r[26, s], r[27, s]
                        bs = buf[s]
                        for p in range(bl):
                            E1 = e1[p]
                            E2 = e2[p]
                            x0 = fexp2(E1 * g01 + E2 * g02)
                            x1 = fexp2(E1 * g11 + E2 * g12)
                            x2 = fexp2(E1 * g21 + E2 * g22)
                            x3 = fexp2(E1 * g31 + E2 * g32)
                            x4 = fexp2(E1 * g41 + E2 * g42)
                            x5 = fexp2(E1 * g51 + E2 * g52)
                            C0 = c0[p]
                            C1 = c1[p]
                            C2 = c2[p]
                            d = abs(y0 - C0 * a0 - C1 * (f01 * x0 + f11 * x1)
                                    - C2 * (f02 * x0 + f12 * x1))
                            d += abs(y1 - C0 * a1 - C1 * (f21 * x2 + f31 * x3)
                                     - C2 * (f22 * x2 + f32 * x3))
                            d += abs(y2 - C0 * a2 - C1 * (fa1[p] + f41 * x4)
                                     - C2 * (fa2[p] + f42 * x4))
                            d += abs(y3 - C0 * a3 - C1 * (fb1[p] + f51 * x5)
                                     - C2 * (fb2[p] + f52 * x5))
                            bs[p] = u + inv_sigma * d
                else:
                    ha1 = nrec[i, 4]
                    ga1 = nrec[i, 5]
                    hb1 = nrec[i, 6]
                    gb1 = nrec[i, 7]
                    for p in range(bl):  # h, f: log2 of the weights (folded)
                        fa1[p] = fexp2(e1[p] * ga1 + ha1)
                        fb1[p] = fexp2(e1[p] * gb1 + hb1)
                    for s in range(B):
                        u = unary[i, s]
                        a0 = r[0, s]
                        a1 = r[1, s]
                        a2 = r[2, s]
                        a3 = r[3, s]
                        f0, g0, f1, g1 = r[4, s], r[5, s], r[6, s], r[7, s]
                        f2, g2, f3, g3 = r[8, s], r[9, s], r[10, s], r[11, s]
                        f4, g4, f5, g5 = r[12, s], r[13, s], r[14, s], r[15, s]
                        bs = buf[s]
                        for p in range(bl):
                            E1 = e1[p]
                            C0 = c0[p]
                            C1 = c1[p]
                            d = abs(y0 - C0 * a0 - C1 * (fexp2(E1 * g0 + f0) + fexp2(E1 * g1 + f1)))
                            d += abs(y1 - C0 * a1
                                     - C1 * (fexp2(E1 * g2 + f2) + fexp2(E1 * g3 + f3)))
                            d += abs(y2 - C0 * a2 - C1 * (fa1[p] + fexp2(E1 * g4 + f4)))
                            d += abs(y3 - C0 * a3 - C1 * (fb1[p] + fexp2(E1 * g5 + f5)))
                            bs[p] = u + inv_sigma * d
                bo = buf[obs[i]]
                if do_lse:
                    for p in range(bl):
                        mn[p] = buf[0, p]
                        ssum[p] = 0
                    for s in range(1, B):
                        bs = buf[s]
                        for p in range(bl):
                            mn[p] = min(mn[p], bs[p])
                    for s in range(B):
                        bs = buf[s]
                        for p in range(bl):
                            ssum[p] += fexp2(mn[p] - bs[p])  # energies in log2 units
                    if per_node:
                        for p in range(bl):
                            out_node[i, q0 + p] = _LN2 * (af * -float(bo[p]) - bf * float(
                                mn[p])) + bf * float(flog(ssum[p]))
                    else:
                        for p in range(bl):
                            acc[p] += _LN2 * (af * -float(bo[p]) - bf * float(mn[p])) + bf * float(
                                flog(ssum[p]))
                elif per_node:
                    for p in range(bl):
                        out_node[i, q0 + p] = _LN2 * (af * -float(bo[p]))
                else:
                    for p in range(bl):
                        acc[p] += _LN2 * (af * -float(bo[p]))
            if not per_node:
                for p in range(bl):
                    out_chunk[c, q0 + p] = acc[p]


# -- a few particles: the nodes are the SIMD lanes ------------------------------------------

#: Fewest nodes per block of :func:`lean_terms_nodes` (and the block of
#: :mod:`mrfpe.targets.jacobian`'s node-major loops).
NODE_BLOCK = 256
#: Most nodes per block of :func:`lean_terms_nodes` (:func:`node_block`).
NODE_BLOCK_MAX = 1024


def node_block(n_nodes: int, n_threads: int) -> int:
    """Nodes per block of :func:`lean_terms_nodes` for ``n_nodes`` nodes on ``n_threads``.

    Each (block, label) pair runs one vector loop over the block's nodes, whose
    set-up (29-45 row pointers, the alias checks) is paid once per pair: at
    100x100 nodes and 20 labels, blocks of 1024 take 0.80x the time of blocks of
    256 with one particle (Ward; 0.81x at 40 labels, 0.94x Phong at 20; medians
    of 15 alternations in one process, Zen 4). The block is the largest power of
    two from :data:`NODE_BLOCK` to :data:`NODE_BLOCK_MAX` that still leaves two
    blocks per thread, so threads stay balanced. Results do not depend on it
    (the per-node terms and their chunk sums are the same).
    """
    nb = NODE_BLOCK_MAX
    while nb > NODE_BLOCK and -(-int(n_nodes) // nb) < 2 * max(int(n_threads), 1):
        nb //= 2
    return nb


@dataclass(frozen=True)
class LeanTablesT:
    """:class:`LeanTables` with the nodes last (``recT[k, s, i]``, ``nrecT[k, i]``), so that a
    node block's field loads are contiguous vectors (:func:`lean_terms_nodes`)."""

    recT: np.ndarray   # (4 + 6 * nf, B, n)
    nrecT: np.ndarray  # (4 + 2 * nf, n)

    @property
    def nbytes(self) -> int:
        return int(self.recT.nbytes + self.nrecT.nbytes)


def lean_tables_t(lt: LeanTables) -> LeanTablesT:
    """The node-major copy of ``lt`` (built on the first small batch and kept on ``lt``)."""
    cache = lt.__dict__
    if "_t" not in cache:
        object.__setattr__(lt, "_t", LeanTablesT(np.ascontiguousarray(lt.rec.transpose(1, 2, 0)),
                                                 np.ascontiguousarray(lt.nrec.T)))
    return cache["_t"]


@njit(inline="always", cache=True)
def label_rows_full(recT, unaryT, s, sl):  # pragma: no cover - compiled
    """Label ``s``'s rows of node block ``sl`` in the node-major full-form tables.

    ``(u, a0..a3, f01, g01, f02, g02, ..., f51, g51, f52, g52)``: the unary energy,
    the four slots' albedo terms, and per variable triangle ``t = 0..5`` its two
    terms' feature ``f_tk`` and exponent ``g_tk`` (:class:`LeanTablesT`). Bound as 1-D
    views indexed from 0, so loops over them load vectors, not gathers.
    """
    return (unaryT[s, sl], recT[0, s, sl], recT[1, s, sl], recT[2, s, sl], recT[3, s, sl],
            recT[4, s, sl], recT[5, s, sl], recT[6, s, sl], recT[7, s, sl],
            recT[8, s, sl], recT[9, s, sl], recT[10, s, sl], recT[11, s, sl],
            recT[12, s, sl], recT[13, s, sl], recT[14, s, sl], recT[15, s, sl],
            recT[16, s, sl], recT[17, s, sl], recT[18, s, sl], recT[19, s, sl],
            recT[20, s, sl], recT[21, s, sl], recT[22, s, sl], recT[23, s, sl],
            recT[24, s, sl], recT[25, s, sl], recT[26, s, sl], recT[27, s, sl])


@njit(inline="always", cache=True)
def label_rows_ward(recT, unaryT, s, sl):  # pragma: no cover - compiled
    """As :func:`label_rows_full` for the Ward/Lambertian tables: ``(u, a0..a3, f0, g0, ...,
    f5, g5)``, one term per variable triangle."""
    return (unaryT[s, sl], recT[0, s, sl], recT[1, s, sl], recT[2, s, sl], recT[3, s, sl],
            recT[4, s, sl], recT[5, s, sl], recT[6, s, sl], recT[7, s, sl],
            recT[8, s, sl], recT[9, s, sl], recT[10, s, sl], recT[11, s, sl],
            recT[12, s, sl], recT[13, s, sl], recT[14, s, sl], recT[15, s, sl])


@njit(parallel=True, fastmath=_FM, error_model="numpy", cache=True)
def lean_terms_nodes(coef, nb, full, iso, recT, nrecT, unaryT, obs, inv_sigma, chunk_ptr, a,
                     b, do_lse, out_chunk, out_node, per_node):  # pragma: no cover - compiled
    """As :func:`lean_terms` for a few particles, with blocks of ``nb`` nodes
    (:func:`node_block`) as the SIMD lanes, whatever the label count; ``iso``:
    :attr:`LeanTables.isotropic`.

    ``coef`` is (5, N) without padding; ``recT``, ``nrecT``: :class:`LeanTablesT`;
    ``unaryT``: (B, n) in log2 units. Same formula and order of operations per
    (particle, node, label) as :func:`lean_terms`; the node terms are then summed per
    chunk in node order, as there, so the sums do not depend on the block size. The
    fields are bound to 1-D rows (``recT[k, s]``) so that numba's code knows their unit
    stride and loads vectors, not gathers, and indexed from 0 so that no
    negative-index wraparound is compiled in.

    The particles loop inside each (block, label), so a label's rows are read once
    for all N: at 100x100 nodes and 20 labels one particle's pass streams the whole
    table (13 MB for Ward, 23 MB for Phong) and runs at 1.6x (Ward) to 2.2x (Phong)
    its in-cache time per node. Two particles then cost 1.9x one (Ward) and
    1.2-1.5x (Phong), four 3.4x and 1.8x (one core, medians of 8). With the particles
    outside the label loop, as before, the same bits took 0.93-1.05x this time at
    N = 1 and 1.08-1.20x at N = 4.
    """
    N = coef.shape[1]
    af = float(a)  # the node terms are combined in float64
    bf = float(b)
    B = unaryT.shape[0]
    NB = nb
    lo, hi = chunk_ptr[0], chunk_ptr[-1]
    vals = out_node if per_node else np.empty((hi, N))
    for blk in prange(-(-(hi - lo) // NB)):
        i0 = lo + blk * NB
        i1 = min(i0 + NB, hi)
        en = np.empty((N, B, NB), dtype=coef.dtype)
        fa1 = np.empty((N, NB), dtype=coef.dtype)
        fa2 = np.empty((N, NB), dtype=coef.dtype)
        fb1 = np.empty((N, NB), dtype=coef.dtype)
        fb2 = np.empty((N, NB), dtype=coef.dtype)
        mn = np.empty(NB, dtype=coef.dtype)
        ssum = np.empty(NB, dtype=coef.dtype)
        m = i1 - i0
        sl = slice(i0, i1)
        y0, y1, y2, y3 = nrecT[0, sl], nrecT[1, sl], nrecT[2, sl], nrecT[3, sl]
        if full:
            ha1, ga1, ha2, ga2 = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
            hb1, gb1, hb2, gb2 = nrecT[8, sl], nrecT[9, sl], nrecT[10, sl], nrecT[11, sl]
            for q in range(N):  # fixed triangles: once per node, not per label
                E1 = coef[3, q]
                E2 = coef[4, q]
                qa1, qa2, qb1, qb2 = fa1[q], fa2[q], fb1[q], fb2[q]
                for j in range(m):
                    xa = fexp2(E1 * ga1[j] + E2 * ga2[j])
                    xb = fexp2(E1 * gb1[j] + E2 * gb2[j])
                    qa1[j] = ha1[j] * xa
                    qa2[j] = ha2[j] * xa
                    qb1[j] = hb1[j] * xb
                    qb2[j] = hb2[j] * xb
            for s in range(B):
                (u, a0, a1, a2, a3, f01, g01, f02, g02, f11, g11, f12, g12, f21, g21, f22,
                 g22, f31, g31, f32, g32, f41, g41, f42, g42, f51, g51, f52,
                 g52) = label_rows_full(recT, unaryT, s, sl)
                for q in range(N):
                    C0 = coef[0, q]
                    C1 = coef[1, q]
                    C2 = coef[2, q]
                    E1 = coef[3, q]
                    E2 = coef[4, q]
                    qa1, qa2, qb1, qb2 = fa1[q], fa2[q], fb1[q], fb2[q]
                    es = en[q, s]
                    # G2 = 0: E1 G1 + E2 0 is E1 G1 exactly, and the G2 rows stay unread. A loop
                    # of its own: one loop with the branch inside changed LLVM's FMAs (the bits)
                    if iso:
                        for j in range(m):
                            x0 = fexp2(E1 * g01[j])
                            x1 = fexp2(E1 * g11[j])
                            x2 = fexp2(E1 * g21[j])
                            x3 = fexp2(E1 * g31[j])
                            x4 = fexp2(E1 * g41[j])
                            x5 = fexp2(E1 * g51[j])
                            d = abs(y0[j] - C0 * a0[j] - C1 * (f01[j] * x0 + f11[j] * x1)
                                    - C2 * (f02[j] * x0 + f12[j] * x1))
                            d += abs(y1[j] - C0 * a1[j] - C1 * (f21[j] * x2 + f31[j] * x3)
                                     - C2 * (f22[j] * x2 + f32[j] * x3))
                            d += abs(y2[j] - C0 * a2[j] - C1 * (qa1[j] + f41[j] * x4)
                                     - C2 * (qa2[j] + f42[j] * x4))
                            d += abs(y3[j] - C0 * a3[j] - C1 * (qb1[j] + f51[j] * x5)
                                     - C2 * (qb2[j] + f52[j] * x5))
                            es[j] = u[j] + inv_sigma * d
                        continue
                    for j in range(m):
                        x0 = fexp2(E1 * g01[j] + E2 * g02[j])
                        x1 = fexp2(E1 * g11[j] + E2 * g12[j])
                        x2 = fexp2(E1 * g21[j] + E2 * g22[j])
                        x3 = fexp2(E1 * g31[j] + E2 * g32[j])
                        x4 = fexp2(E1 * g41[j] + E2 * g42[j])
                        x5 = fexp2(E1 * g51[j] + E2 * g52[j])
                        d = abs(y0[j] - C0 * a0[j] - C1 * (f01[j] * x0 + f11[j] * x1)
                                - C2 * (f02[j] * x0 + f12[j] * x1))
                        d += abs(y1[j] - C0 * a1[j] - C1 * (f21[j] * x2 + f31[j] * x3)
                                 - C2 * (f22[j] * x2 + f32[j] * x3))
                        d += abs(y2[j] - C0 * a2[j] - C1 * (qa1[j] + f41[j] * x4)
                                 - C2 * (qa2[j] + f42[j] * x4))
                        d += abs(y3[j] - C0 * a3[j] - C1 * (qb1[j] + f51[j] * x5)
                                 - C2 * (qb2[j] + f52[j] * x5))
                        es[j] = u[j] + inv_sigma * d
        else:
            ha1, ga1, hb1, gb1 = nrecT[4, sl], nrecT[5, sl], nrecT[6, sl], nrecT[7, sl]
            for q in range(N):  # h, f: log2 of the weights (folded)
                E1 = coef[3, q]
                qa1, qb1 = fa1[q], fb1[q]
                for j in range(m):
                    qa1[j] = fexp2(E1 * ga1[j] + ha1[j])
                    qb1[j] = fexp2(E1 * gb1[j] + hb1[j])
            for s in range(B):
                (u, a0, a1, a2, a3, f0, g0, f1, g1, f2, g2, f3, g3, f4, g4, f5,
                 g5) = label_rows_ward(recT, unaryT, s, sl)
                for q in range(N):
                    C0 = coef[0, q]
                    C1 = coef[1, q]
                    E1 = coef[3, q]
                    qa1, qb1 = fa1[q], fb1[q]
                    es = en[q, s]
                    for j in range(m):
                        d = abs(y0[j] - C0 * a0[j]
                                - C1 * (fexp2(E1 * g0[j] + f0[j]) + fexp2(E1 * g1[j] + f1[j])))
                        d += abs(y1[j] - C0 * a1[j]
                                 - C1 * (fexp2(E1 * g2[j] + f2[j]) + fexp2(E1 * g3[j] + f3[j])))
                        d += abs(y2[j] - C0 * a2[j] - C1 * (qa1[j] + fexp2(E1 * g4[j] + f4[j])))
                        d += abs(y3[j] - C0 * a3[j] - C1 * (qb1[j] + fexp2(E1 * g5[j] + f5[j])))
                        es[j] = u[j] + inv_sigma * d
        for q in range(N):
            enq = en[q]
            if do_lse:
                for j in range(m):
                    mn[j] = enq[0, j]
                    ssum[j] = 0
                for s in range(1, B):
                    es = enq[s]
                    for j in range(m):
                        mn[j] = min(mn[j], es[j])
                for s in range(B):
                    es = enq[s]
                    for j in range(m):
                        ssum[j] += fexp2(mn[j] - es[j])  # energies in log2 units
            for j in range(m):
                eo = enq[obs[i0 + j], j]
                if do_lse:
                    vals[i0 + j, q] = _LN2 * (af * -float(eo) - bf * float(mn[j])) + bf * float(
                        flog(ssum[j]))
                else:
                    vals[i0 + j, q] = _LN2 * (af * -float(eo))
    if not per_node:
        for c in prange(chunk_ptr.shape[0] - 1):
            for q in range(N):
                acc = 0.0
                for i in range(chunk_ptr[c], chunk_ptr[c + 1]):
                    acc += vals[i, q]
                out_chunk[c, q] = acc
