"""The sub-lattice rule every target's ``partition`` follows."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.targets.partition import split_ids


def test_split_ids_is_the_one_rule():
    ids = np.arange(10, 23)
    for kind in ("strided", "block"):
        for k in (1, 2, 5, 13):
            parts = split_ids(ids, k, kind)
            assert len(parts) == k
            assert np.array_equal(np.sort(np.concatenate(parts)), ids)  # disjoint, covering
            assert all(p.size >= 1 for p in parts)
    assert [p.tolist() for p in split_ids(ids[:5], 2, "strided")] == [[10, 12, 14], [11, 13]]
    assert [p.tolist() for p in split_ids(ids[:5], 2, "block")] == [[10, 11, 12], [13, 14]]
    for bad in (0, 14, 2.0, True):
        with pytest.raises(ValueError, match="k must be"):
            split_ids(ids, bad)
    with pytest.raises(ValueError, match="kind must be"):
        split_ids(ids, 2, "random")
