"""Compile the numerical kernels before a run's clock starts: :func:`warm_target`.

The pseudolikelihood kernels are numba functions compiled on their first call
and cached on disk (``cache=True``), so a fresh install spends 20–60 s
compiling in its first run and later runs load the cache in about a second. A
sampler that compiled inside its first iteration would show a progress bar
whose ETA multiplies that one-off cost by the number of iterations;
:class:`~mrfpe.samplers.kit.Run` calls :func:`warm_target` before its bar, which
makes the first call outside the bar and says, once, what the wait is.
``mrfpe warmup`` (:mod:`mrfpe.warmup`) fills the cache ahead of any run.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["BATCH", "REPORT_AFTER_S", "kernels_cached", "warm_target"]

#: A warm-up slower than this (seconds) was a compilation and is reported.
REPORT_AFTER_S = 2.0
#: Particles in the warm-up's batch: enough for the batch kernels (the pseudolikelihood
#: runs batches of fewer than 5 through its small-batch kernels).
BATCH = 8


def kernels_cached(kernels: Iterable[Any] = ()) -> bool:
    """Whether numba's on-disk cache holds ``kernels`` and PMC's mixture density.

    ``kernels`` are numba dispatchers, e.g. a target's ``compiled_kernels`` (the BRDF
    pseudolikelihood's main kernels); the mixture density that PMC weighs its
    particles with is always checked. Looks for each one's cache index (where numba
    keeps them: beside the module when that is writable, else the user's cache
    directory). False when it cannot tell.
    """
    try:
        from mrfpe import mixture

        return all(Path(k._cache._cache_file._index_path).exists()
                   for k in (*kernels, mixture._lse_rows))
    except Exception:  # numba internals differ: assume a cold cache
        return False


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def warm_target(target: Any, say: Callable[[str], None] | None = _stderr) -> float:
    """Evaluate ``target`` (and one of its sub-lattice parts) once, compiling what it needs,
    and the mixture density (:func:`mrfpe.mixture.log_mixture_density`) in its dimension.

    Prints "compiling numerical kernels (first run only …)" through ``say``
    before a first run on a cold cache, and the time taken when the warm-up was
    slow. Returns the seconds spent.
    """
    b = np.asarray(getattr(target, "bounds", np.zeros((0, 2))), dtype=float)
    if b.ndim != 2 or b.shape[0] == 0 or not np.isfinite(b).all():
        return 0.0
    cold = not kernels_cached(getattr(target, "compiled_kernels", ()))
    if cold and say is not None:
        say("compiling numerical kernels (first run only, about 20-60 s; "
            "`mrfpe warmup` does it ahead of time) ...")
    t0 = time.perf_counter()
    centre = b.mean(axis=1)[None]
    target.log_prob(centre)  # one particle and a batch: each has its own kernel
    target.log_prob(np.repeat(centre, BATCH, axis=0))
    if callable(getattr(target, "partition", None)):
        try:
            parts = target.partition(2, "strided")
        except (ValueError, TypeError, NotImplementedError):  # no split: nothing to compile
            parts = []
        if parts:
            parts[0].log_prob(centre)
    from mrfpe.mixture import log_mixture_density

    log_mixture_density(np.vstack([centre, centre]), centre, np.zeros(1), 0.1)
    dt = time.perf_counter() - t0
    if say is not None and dt > REPORT_AFTER_S:
        say(f"kernels ready in {dt:.0f} s (cached for later runs)")
    return dt
