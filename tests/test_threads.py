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


def _blas_threads_now() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_blas_threads_limits_and_restores():
    import numpy as np  # noqa: F401 - loads the BLAS threadpoolctl reports

    from mrfpe import threads

    before = _blas_threads_now()
    assert before, "numpy's BLAS should be visible to threadpoolctl"
    with threads.blas_threads():
        assert set(_blas_threads_now()) == {threads.BLAS_THREADS}
    assert _blas_threads_now() == before
    old = threads.BLAS_THREADS
    try:
        threads.BLAS_THREADS = None  # leave BLAS alone
        with threads.blas_threads():
            assert _blas_threads_now() == before
    finally:
        threads.BLAS_THREADS = old


def test_sample_runs_samplers_with_one_blas_thread():
    import mrfpe
    from mrfpe.testing.targets import CorrelatedGaussian

    seen = []
    mrfpe.sample("pmc", CorrelatedGaussian(), seed=0, n_samples=200, n_iterations=2,
                 callback=lambda step, info: seen.append(_blas_threads_now()))
    assert seen and all(set(s) == {1} for s in seen)


def test_blas_threads_restored_after_overlapping_blocks_in_threads():
    """Four threads entering and leaving in an interleaved order: the original BLAS
    thread count comes back (each block restoring its own 'previous' value left 1)."""
    import threading

    from threadpoolctl import threadpool_info, threadpool_limits

    from mrfpe.threads import blas_threads

    def blas():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    with threadpool_limits(limits=2, user_api="blas"):
        original = blas()
        entered = [threading.Event() for _ in range(4)]
        leave = [threading.Event() for _ in range(4)]

        def worker(i):
            with blas_threads(1):
                entered[i].set()
                leave[i].wait(10)

        threads = []
        for i in range(4):  # enter one after the other ...
            threads.append(threading.Thread(target=worker, args=(i,)))
            threads[-1].start()
            entered[i].wait(10)
        for i in (0, 2, 1, 3):  # ... leave out of order
            leave[i].set()
            threads[i].join(10)
        assert blas() == original


def test_sample_in_four_threads_leaves_blas_as_it_was():
    from concurrent.futures import ThreadPoolExecutor

    from threadpoolctl import threadpool_info

    import mrfpe
    from mrfpe.testing.targets import CorrelatedGaussian

    def blas():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    before = blas()
    with ThreadPoolExecutor(4) as ex:
        list(ex.map(lambda s: mrfpe.sample("pmc", CorrelatedGaussian(), seed=s, n_samples=200,
                                           n_iterations=3), range(8)))
    assert blas() == before
