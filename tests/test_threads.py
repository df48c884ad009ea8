from __future__ import annotations

import numba
import pytest

from mrfpe.threads import MIN_EVALS_PER_THREAD, thread_budget


def test_thread_budget_scales_with_work_and_restores():
    have = numba.get_num_threads()
    with thread_budget(10) as n:
        assert n == numba.get_num_threads() == 1
    assert numba.get_num_threads() == have
    with thread_budget(10**12) as n:  # never more than the current setting
        assert n == numba.get_num_threads() == have
    with thread_budget(2 * MIN_EVALS_PER_THREAD) as n:
        assert n == min(have, 2)
    with pytest.raises(RuntimeError), thread_budget(1):
        raise RuntimeError("restored on error too")
    assert numba.get_num_threads() == have
