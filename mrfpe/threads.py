"""How many numba threads a call gets: the thread limiter and the per-call budget.

Kept apart from the kernels so that studies and samplers can cap threads
without importing (and compiling) the numba kernel module.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager

import numba

__all__ = ["MIN_EVALS_PER_THREAD", "limit_threads", "thread_budget"]


#: Smallest work (BRDF evaluations) that earns a thread of its own. A parallel region
#: costs a fork/join and, on a loaded machine, a wait for a descheduled thread (up
#: to a time slice); measured on two cores with both busy elsewhere, a single
#: particle on a 10x10 scene (12k evaluations) took 0.1 ms on one thread and 8 ms
#: on two, while from about 2e5 evaluations per thread up two threads win or tie
#: (``python -m benchmarks`` reports the single-particle times).
MIN_EVALS_PER_THREAD = 200_000


@contextmanager
def limit_threads(n: int) -> Iterator[int]:
    """Run the enclosed block on ``n`` numba threads (clipped to 1..``NUMBA_NUM_THREADS``).

    The previous setting (thread-local in numba) is restored on exit, error or not.
    """
    have = numba.get_num_threads()
    want = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
    if want == have:
        yield have
        return
    numba.set_num_threads(want)
    try:
        yield want
    finally:
        numba.set_num_threads(have)


def thread_budget(n_evals: int) -> AbstractContextManager[int]:
    """Run the enclosed kernel call on ``min(threads, n_evals // MIN_EVALS_PER_THREAD)`` threads.

    Never more than numba's current setting (``NUMBA_NUM_THREADS`` or
    :func:`numba.set_num_threads`, which the caller may have lowered), never fewer
    than one; the previous setting is restored on exit (:func:`limit_threads`).
    Results do not depend on the thread count (the kernels' chunk sums are added
    in a fixed order).
    """
    return limit_threads(min(numba.get_num_threads(), int(n_evals) // MIN_EVALS_PER_THREAD))
