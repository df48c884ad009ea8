"""Process-wide numba settings: the thread limiter, the per-call budget, the vector width.

Kept apart from the kernels so that studies and samplers can cap threads
without importing (and compiling) the numba kernel module.

Vector width (:func:`configure_vector_width`, run by :mod:`mrfpe.brdf.engine` before
it defines its kernels; :func:`mrfpe.fastmath.compiled_features` tells
what the code is compiled for). LLVM tunes some AVX-512 CPUs (e.g. Rocket Lake, Ice/Cascade Lake) to
prefer 256-bit vectors, which costs the kernels 1.2-1.45x. numba has no
per-function target option and builds one LLVM target machine per process at its
first compile, so the choice is process-wide: if the CPU has AVX-512F, neither
``NUMBA_CPU_NAME`` nor ``NUMBA_CPU_FEATURES`` is set, and numba has not compiled
anything yet, mrfpe sets ``NUMBA_CPU_FEATURES`` to the host's own features plus
``-prefer-256-bit`` (so other numba code in the process gets 512-bit loops too;
results are unchanged, only the vector width). numba's cache keys include the
feature string, so cached code of the two settings never mixes. Opt out with
``MRFPE_AVX512=0`` in the environment (before importing mrfpe).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager

import numba

__all__ = ["BLAS_THREADS", "MIN_EVALS_PER_THREAD", "blas_threads", "configure_vector_width",
           "limit_threads", "thread_budget", "vector_width"]

#: Environment variable that turns the 512-bit preference off ("0", "off", "no", "false").
OPT_OUT_ENV = "MRFPE_AVX512"
_VECTOR_STATE: dict[str, str] = {}


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


#: BLAS/LAPACK threads while a sampler runs (:func:`blas_threads`); ``None`` leaves them alone.
BLAS_THREADS: int | None = 1


@contextmanager
def blas_threads(n: int | None = None) -> Iterator[None]:
    """Run the enclosed block with BLAS/LAPACK on ``n`` threads (default :data:`BLAS_THREADS`).

    :func:`mrfpe.sample` runs every sampler inside it. The samplers' BLAS calls are
    on d x d matrices (Cholesky factors and triangular solves of mixture components,
    d of order 10), which one thread does as fast as many; but OpenBLAS's idle
    worker threads spin-wait after each call, and on a machine with no core to
    spare they take the cores of numba's kernel threads: PMC 1000 x 20 (100 x 100,
    10 labels, float32, two cores) took 1.64-1.72 s with OpenBLAS's two threads
    and 0.77-0.87 s with one. The previous limits are restored on exit
    (``threadpoolctl``; about 1.5 ms per entry). ``n=None`` with
    ``BLAS_THREADS = None`` changes nothing.

    Only the main thread changes the limits: OpenBLAS lowers its thread count
    when asked from any thread but raises it again only when asked from the main
    one, so a limit set in a worker thread (``mrfpe.sample`` in a thread pool)
    would stay for the whole process; there BLAS is left as it is. Nested blocks
    share one limit, and the original limits come back when the outermost ends.
    """
    n = BLAS_THREADS if n is None else n
    if n is None or threading.current_thread() is not threading.main_thread():
        # OpenBLAS lowers its thread count from any thread but raises it again only from
        # the main one: a limit set in a worker thread would stay for the process
        yield
        return
    _blas_enter(int(n))
    try:
        yield
    finally:
        _blas_exit()


# BLAS limits are process-wide while each caller's block is its own: the first block to
# enter sets the limit and remembers the original, the last to leave restores it. (Each
# block saving and restoring its own "previous" value, as threadpool_limits does, leaves
# the limit at 1 for good when blocks in several threads overlap out of order.)
_BLAS_LOCK = threading.Lock()
_blas_state: dict[str, object] = {"users": 0, "limiter": None}


def _blas_enter(n: int) -> None:
    from threadpoolctl import threadpool_limits

    with _BLAS_LOCK:
        if _blas_state["users"] == 0:
            _blas_state["limiter"] = threadpool_limits(limits=n, user_api="blas")
        _blas_state["users"] = int(_blas_state["users"]) + 1  # type: ignore[call-overload]


def _blas_exit() -> None:
    with _BLAS_LOCK:
        _blas_state["users"] = int(_blas_state["users"]) - 1  # type: ignore[call-overload]
        if _blas_state["users"] == 0:
            limiter = _blas_state["limiter"]
            _blas_state["limiter"] = None
            limiter.restore_original_limits()  # type: ignore[union-attr]


def _numba_compiled_anything() -> bool:
    """Whether numba's CPU target (and so its LLVM target machine) already exists."""
    try:
        from numba.core.registry import cpu_target
    except ImportError:  # pragma: no cover - other numba layouts: assume it does
        return True
    return "_toplevel_target_context" in vars(cpu_target)


def configure_vector_width() -> str:
    """Let numba use 512-bit vectors on AVX-512 hosts, if that is safe (module docstring).

    Returns (and remembers) the outcome: ``"512"`` (set by mrfpe), ``"host"``
    (left to numba: no AVX-512), ``"user"`` (NUMBA_CPU_NAME/FEATURES set),
    ``"opt-out"`` (``MRFPE_AVX512=0``) or ``"late"`` (numba had already compiled).
    """
    if "state" in _VECTOR_STATE:
        return _VECTOR_STATE["state"]
    if os.environ.get(OPT_OUT_ENV, "").strip().lower() in ("0", "off", "no", "false"):
        state = "opt-out"
    elif os.environ.get("NUMBA_CPU_NAME") or os.environ.get("NUMBA_CPU_FEATURES") \
            or numba.config.CPU_NAME or numba.config.CPU_FEATURES:
        state = "user"
    elif _numba_compiled_anything():
        state = "late"
    else:
        import llvmlite.binding as ll

        feats = ll.get_host_cpu_features()
        if not feats.get("avx512f", False):
            state = "host"
        else:
            value = feats.flatten() + ",-prefer-256-bit"
            # the env var survives numba's config reload at each compile and reaches
            # worker processes on this host; the attribute covers the current process
            os.environ["NUMBA_CPU_FEATURES"] = value
            numba.config.CPU_FEATURES = value
            state = "512"
    _VECTOR_STATE["state"] = state
    return state


def vector_width() -> int:
    """Widest SIMD registers numba's code uses here: 512 with AVX-512 unless 256 is preferred."""
    import llvmlite.binding as ll

    feats = ll.get_host_cpu_features()
    if not feats.get("avx512f", False):
        return 256 if feats.get("avx2", False) or feats.get("avx", False) else 128
    cfg = numba.config.CPU_FEATURES or ""
    if _VECTOR_STATE.get("state") in ("512",) or "-prefer-256-bit" in cfg:
        return 512
    name = numba.config.CPU_NAME or ll.get_host_cpu_name()
    # LLVM's 256-bit preference on AVX-512 Intel cores (X86.td TuningPrefer256Bit)
    return 256 if name in _PREFER_256 else 512


_PREFER_256 = frozenset({
    "skylake-avx512", "cascadelake", "cooperlake", "cannonlake", "icelake-client",
    "icelake-server", "tigerlake", "rocketlake", "sapphirerapids", "alderlake",
    "graniterapids", "emeraldrapids", "x86-64-v4"})
