"""The compute engine of the BRDF pseudolikelihood family, behind one door.

A target builds, once, its read-only tables and a frozen plan, and then asks for
the terms of each batch of radiance coefficients::

    tables = make_tables(data, lean_tables(data, full), unary, obs)
    plan = make_plan(tables, kernel="lean", dtype="float64", full=full,
                     sigma_b=0.05, a=1.0, b=-1.0)
    terms = evaluate(plan, tables, coef)               # (N,) sums over nodes
    per_node = evaluate(plan, tables, coef, per_node=True)  # (N, n)

Modules, from the leaf up:

* :mod:`~mrfpe.fastmath` -- fast-math flags and vectorising exp/log/2^x
  (imports no other mrfpe module; :mod:`mrfpe.mixture` uses it too);
* :mod:`~mrfpe.brdf.engine.tables` -- the classic CSR data tables and the parallel chunks;
* :mod:`~mrfpe.brdf.engine.template` -- the lean kernels' fixed-template tables;
* :mod:`~mrfpe.brdf.engine.classic`, :mod:`~mrfpe.brdf.engine.lean`,
  :mod:`~mrfpe.brdf.engine.lean_nodes`, :mod:`~mrfpe.brdf.engine.gradient` -- the numba kernels;
* :mod:`~mrfpe.brdf.engine.plan` -- :class:`Plan`, :class:`Tables` and the per-call
  kernel choice;
* :mod:`~mrfpe.brdf.engine.evaluate` -- :func:`evaluate`.

Numba's vector width is a process setting that must be chosen before numba's
first compilation: importing this package chooses it
(:func:`mrfpe.threads.configure_vector_width`, opt out with ``MRFPE_AVX512=0``)
before any of its kernels is defined.
"""

from __future__ import annotations

from mrfpe.threads import configure_vector_width

configure_vector_width()  # before the first @njit below (mrfpe.threads explains why)

from mrfpe.brdf.engine.evaluate import evaluate  # noqa: E402
from mrfpe.brdf.engine.plan import (  # noqa: E402
    DTYPES,
    KERNELS,
    Plan,
    Tables,
    kernel_family,
    make_plan,
    make_tables,
)
from mrfpe.brdf.engine.tables import DataTables  # noqa: E402
from mrfpe.brdf.engine.template import LeanTables, lean_tables  # noqa: E402

__all__ = ["DTYPES", "KERNELS", "DataTables", "LeanTables", "Plan", "Tables",
           "compiled_kernels", "evaluate", "kernel_family", "lean_tables", "make_plan",
           "make_tables"]


def compiled_kernels() -> tuple:
    """The main numba kernels (the lean family's sums and per-node terms): the ones whose
    on-disk cache says whether a first run must compile
    (:func:`mrfpe.samplers.kit.warm.kernels_cached`)."""
    from mrfpe.brdf.engine import lean, lean_nodes

    return (lean.lean_terms, lean_nodes.lean_terms_nodes)
