"""Sub-lattices of a target: the one rule every ``partition(k, kind)`` follows.

A target may offer ``partition(k, kind)``, its log density split into ``k``
sub-lattice parts that sum to the whole (thesis 5.67-5.68, 7.8): the sub-lattice
importance functions of PMC, PPF and SIR. :func:`split_ids` is that split, used
by the BRDF targets, the declared models' block estimators and the analytic test
targets alike, so that a sub-lattice means the same thing everywhere.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PARTITION_KINDS", "split_ids"]

#: Sub-lattice split rules accepted by :func:`split_ids` (and every target's ``partition``).
PARTITION_KINDS = ("strided", "block")


def split_ids(ids: Any, k: Any, kind: str = "strided", *, what: str = "n") -> list[np.ndarray]:
    """Split ``ids`` into ``k`` disjoint, covering sub-lattices: THE sub-lattice rule.

    ``kind="strided"``: ``S^n = {ids[n], ids[n+k], ...}`` (thesis 5.68, 7.8);
    ``kind="block"``: ``k`` contiguous runs of nearly equal size (5.67, with the
    number of blocks rather than their size given). Every ``partition`` in mrfpe
    (the lattice's, the BRDF and Potts targets', the analytic test targets')
    calls this, so a sub-lattice means the same thing everywhere.

    Parameters
    ----------
    ids : (n,) array
        The ids to split (in order).
    k : int
        Number of parts, ``1 <= k <= n``.
    kind : "strided" | "block"
    what : str
        How ``n`` is called in the error message.

    Returns
    -------
    list of k arrays, in order, whose concatenation is a permutation of ``ids``.

    Raises
    ------
    ValueError
        If ``k`` is not an integer in ``[1, n]`` or ``kind`` is unknown.
    """
    ids = np.asarray(ids)
    n = ids.shape[0]
    if isinstance(k, bool) or not isinstance(k, int | np.integer):
        raise ValueError(f"k must be an integer in [1, {what}={n}]; got {k!r}")
    if not 1 <= k <= n:
        raise ValueError(f"k must be in [1, {what}={n}]; got {k}")
    if kind == "strided":
        return [ids[j::int(k)] for j in range(int(k))]
    if kind == "block":
        return list(np.array_split(ids, int(k)))
    raise ValueError(f"kind must be 'strided' or 'block'; got {kind!r}")
