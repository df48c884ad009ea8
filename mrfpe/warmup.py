"""``mrfpe warmup``: compile the numerical kernels into numba's cache ahead of any run.

The pseudolikelihood kernels are numba functions compiled on their first call
and cached on disk, so a fresh install spends 20–60 s compiling in its first
run. :func:`main` fills the cache for the targets the demo and the studies use;
:func:`mrfpe.samplers.kit.warm.warm_target` (what a sampler's run log calls
before its progress bar) does the same for one target.
"""

from __future__ import annotations

import time

import numpy as np

from mrfpe.samplers.kit.warm import kernels_cached, warm_target

__all__ = ["main"]


def main() -> int:
    """``mrfpe warmup``: compile and cache the kernels of the pls, fit and pml targets."""
    from mrfpe.brdf import get as get_brdf
    from mrfpe.brdf.engine import compiled_kernels
    from mrfpe.brdf.synthetic import make_scene
    from mrfpe.targets import get as get_target

    t0 = time.perf_counter()
    if kernels_cached(compiled_kernels()):
        print("checking numba's cache of the numerical kernels ...")
    else:
        print("compiling the numerical kernels into numba's cache (once per install, "
              "about a minute) ...")
    for brdf in ("ward", "phong"):
        model = get_brdf(brdf)
        theta = np.asarray(model.to_natural(np.full(model.d, 0.5)), dtype=float)
        scene = make_scene(brdf=brdf, theta=theta.reshape(-1), shape=(12, 12), n_labels=4,
                           seed=0)
        for name, options in (("pls", {}), ("pls", {"dtype": "float32"}), ("fit", {}),
                              ("pml", {})):
            warm_target(get_target(name, scene, **options), say=None)
    print(f"done in {time.perf_counter() - t0:.0f} s; later runs start without compiling")
    return 0
