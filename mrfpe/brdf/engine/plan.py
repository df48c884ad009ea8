"""What the engine is asked to compute: a frozen :class:`Plan` and the target's :class:`Tables`.

Both are made once, when a target is built, and never change:

* :class:`Tables` -- every array a kernel reads: the classic CSR tables
  (:class:`~mrfpe.brdf.engine.tables.DataTables`), the lean template tables
  (:class:`~mrfpe.brdf.engine.template.LeanTables`, None when the template does not
  fit), the theta-independent unary
  energies in the kernels' dtype and, for the lean kernels, in log2 units
  (and transposed for the node-major kernel), the observed labels and the
  parallel chunks. All read-only.
* :class:`Plan` -- the choices: kernel family, dtype, the model's form (full or
  Ward), isotropy, the weights ``a``, ``b`` and ``1/sigma_b`` already in the units
  and precision each family wants.

The only choice left to each call is :func:`kernel_family`: the lean kernels'
``2^x`` has no overflow clamp, so a batch whose exponents could exceed it runs the
classic kernels -- a pure function of the plan, the tables and the batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrfpe.brdf.engine.tables import DataTables, chunk_bounds, read_only
from mrfpe.brdf.engine.template import LeanTables, exponent_bound
from mrfpe.fastmath import HI32, HI64, LOG2E

__all__ = ["DTYPES", "KERNELS", "LABEL_KERNEL_BELOW", "Plan", "Tables", "kernel_family",
           "log2_units", "make_plan", "make_tables"]

#: Kernel families: ``"lean"`` (the fixed-template kernels, default) and ``"classic"``
#: (general CSR loops); the same terms up to rounding.
KERNELS = ("lean", "classic")
#: Precisions of the tables and kernels.
DTYPES = ("float64", "float32")
#: Batches smaller than this run the small-batch kernels (no padding of particles).
LABEL_KERNEL_BELOW = 5


@dataclass(frozen=True, eq=False)
class Tables:
    """Every array :func:`mrfpe.brdf.engine.evaluate` reads for one target (module docstring).

    Attributes
    ----------
    data : DataTables
        The classic CSR tables (:mod:`mrfpe.brdf.engine.classic`).
    lean : LeanTables or None
        The template tables (:mod:`mrfpe.brdf.engine.template`).
    unary : (n, B)
        Theta-independent energies in the kernels' dtype (+inf forbids a label).
    unary_log2, unary_log2_t : (n, B), (B, n) or None
        ``unary * log2(e)``, rounded once from float64, and its transpose (the lean
        kernels' units); None without lean tables.
    obs : (n,) int64
        Observed label of each node.
    chunks : (n_chunks + 1,) int64
        Node ranges of the parallel chunks (:func:`~mrfpe.brdf.engine.tables.chunk_bounds`).
    """

    data: DataTables
    lean: LeanTables | None
    unary: np.ndarray
    unary_log2: np.ndarray | None
    unary_log2_t: np.ndarray | None
    obs: np.ndarray
    chunks: np.ndarray

    @property
    def n_nodes(self) -> int:
        return self.data.n_nodes

    @property
    def n_labels(self) -> int:
        return int(self.data.n_labels)


def make_tables(data: DataTables, lean: LeanTables | None, unary: np.ndarray,
                obs: np.ndarray) -> Tables:
    """The read-only :class:`Tables` of one target.

    ``unary`` (n, B) is taken in the tables' dtype; ``lean`` is shared with every
    target on the same scene (:func:`mrfpe.brdf.targets.tables.lean_tables_for`).
    """
    unary = np.ascontiguousarray(unary)
    log2 = log2_t = None
    if lean is not None:
        log2 = (unary.astype(np.float64) * LOG2E).astype(unary.dtype)
        log2_t = np.ascontiguousarray(log2.T)
        read_only(log2, log2_t)
    obs = np.ascontiguousarray(obs, dtype=np.int64)
    chunks = chunk_bounds(data.var_ptr)
    read_only(unary, obs, chunks)
    return Tables(data, lean, unary, log2, log2_t, obs, chunks)


@dataclass(frozen=True)
class Plan:
    """The engine's choices for one target, fixed when the target is built.

    Attributes
    ----------
    kernel : "lean" | "classic"
        The family asked for (:data:`KERNELS`).
    dtype : "float64" | "float32"
        Precision of the tables and kernels (node terms are summed in float64).
    full : bool
        Whether the model has the second lobe term (F2, G2; not Lambertian or Ward).
    lean : bool
        Whether the lean kernels run (asked for, and the template tables fit).
    isotropic : bool
        Every ``G2 = 0`` (:attr:`~mrfpe.brdf.engine.template.LeanTables.isotropic`).
    a, b : numpy scalar of ``dtype``
        Weights of ``-E_i(x_i)`` and of ``log sum_s exp(-E_i(s))``.
    inv_sigma : numpy scalar of ``dtype``
        ``1 / sigma_b`` (the classic kernels).
    inv_sigma_log2 : numpy scalar of ``dtype``
        ``log2(e) / sigma_b`` (the lean kernels work in log2 units).
    exponent_limit : float
        Largest exponent the lean kernels' ``2^x`` takes (:data:`~mrfpe.fastmath.HI32`
        or :data:`~mrfpe.fastmath.HI64`).
    """

    kernel: str
    dtype: str
    full: bool
    lean: bool
    isotropic: bool
    a: np.floating
    b: np.floating
    inv_sigma: np.floating
    inv_sigma_log2: np.floating
    exponent_limit: float

    @property
    def do_lse(self) -> bool:
        """Whether the label log-sum-exp is computed (``b != 0``)."""
        return bool(self.b != 0)


def make_plan(tables: Tables, *, kernel: str, dtype: str, full: bool, sigma_b: float,
              a: float, b: float) -> Plan:
    """The :class:`Plan` of a target with ``tables`` (see :class:`Plan` for the arguments)."""
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}; got {kernel!r}")
    if dtype not in DTYPES:
        raise ValueError(f"dtype must be one of {DTYPES}; got {dtype!r}")
    ft = np.dtype(dtype).type
    inv_sigma = 1.0 / sigma_b
    lean = kernel == "lean" and tables.lean is not None
    return Plan(kernel=kernel, dtype=dtype, full=bool(full), lean=lean,
                isotropic=bool(lean and tables.lean.isotropic), a=ft(a), b=ft(b),
                inv_sigma=ft(inv_sigma), inv_sigma_log2=ft(inv_sigma * LOG2E),
                exponent_limit=HI32 if dtype == "float32" else HI64)


def log2_units(coef: np.ndarray) -> np.ndarray:
    """A copy of ``coef`` (N, 5) with the exponent coefficients ``e1, e2`` times log2(e)."""
    out = coef.copy()
    out[:, 3:] *= LOG2E
    return out


def kernel_family(plan: Plan, tables: Tables, coef: np.ndarray) -> str:
    """The family :func:`mrfpe.brdf.engine.evaluate` runs for the coefficients ``coef`` (N, 5).

    ``plan.kernel``, except that the lean kernels' ``2^x`` skips the overflow clamp:
    a batch whose exponents could exceed it (a model whose lobes grow, not decay;
    :func:`~mrfpe.brdf.engine.template.exponent_bound`) runs the classic kernels.
    """
    if not plan.lean:
        return "classic"
    bound = exponent_bound(tables.lean, log2_units(coef)[:, 3:])
    return "lean" if bound <= plan.exponent_limit else "classic"
