"""Exact log partition functions of discrete pairwise MRFs.

``LogPartition(design, method)(psi)`` gives ``log Z(psi)`` (N,) for a batch of
feature vectors:

* ``"enumerate"``: all ``q^n`` configurations, grouped by their sufficient
  statistics ``S(x)`` (distinct rows and their multiplicities), so that
  ``log Z = logsumexp_s (s . psi + log mult_s)`` is one matrix product.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from mrfpe.models.design import Design, enumerate_configurations, unique_rows

__all__ = ["MAX_ENUMERATION", "LogPartition"]

#: Largest number of configurations enumerated.
MAX_ENUMERATION = 1 << 20


class LogPartition:
    """``log Z(psi)`` of a design, by the cheapest exact method that applies."""

    def __init__(self, design: Design, method: str = "auto") -> None:
        self.design = design
        n, q = design.graph.n_nodes, design.q
        size = float(q) ** n
        if method in ("auto", "enumerate"):
            if size > MAX_ENUMERATION:
                raise ValueError(f"the exact likelihood needs log Z over {q}^{n} "
                                 f"configurations; enumeration is limited to "
                                 f"{MAX_ENUMERATION} (n_nodes={n}, n_states={q})")
            self.method = "enumerate"
            stats = []
            for a in range(0, int(size), 1 << 14):
                codes = np.arange(a, min(int(size), a + (1 << 14)))
                x = np.stack(np.unravel_index(codes, (q,) * n), axis=1)
                stats.append(design.statistics(x))
            s = np.concatenate(stats)
            first, counts, _ = unique_rows(s)
            self._stats, self._log_mult = s[first], np.log(counts)
        else:
            raise ValueError(f"method must be 'auto' or 'enumerate'; got {method!r}")

    def __call__(self, psi: np.ndarray) -> np.ndarray:
        psi = np.atleast_2d(np.asarray(psi, dtype=np.float64))
        return logsumexp(psi @ self._stats.T + self._log_mult[None, :], axis=1)
