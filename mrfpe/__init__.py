"""mrfpe: Markov random field parameter estimation by sampling.

The front doors are :func:`sample` (run a registered sampler on a target) and
:func:`distance` (compare two posteriors). Submodules are imported lazily so
that ``import mrfpe`` and the command line stay fast.
"""

from __future__ import annotations

import importlib
from typing import Any

from mrfpe import _moved
from mrfpe._version import __version__

_moved.install()  # old paths of moved modules import, with a DeprecationWarning

_SUBMODULES = {
    "brdf", "models", "targets", "samplers", "posterior", "distances", "classify", "testing",
    "study", "resampling", "mixture", "validation", "threads", "fastmath",
    # old paths (mrfpe._moved): the module at its new place, with a DeprecationWarning
    "geometry", "lattice", "shading", "scene", "synthetic", "stereo", "engine",
}


def sample(sampler: Any, target: Any, *, seed: int | None = None, progress: bool = False,
           callback: Any = None, **config: Any):
    """Run a sampler on ``target`` and return its posterior Dataset.

    ``sampler`` is a registered name (``mrfpe samplers`` lists them), a sampler
    class (registered or not) or an already configured instance. ``config``
    holds the keyword settings for a name or a class, e.g.
    ``mrfpe.sample("pmc", target, seed=0, n_samples=1000, n_iterations=20)``;
    an instance carries its own (passing ``config`` with one is a ``TypeError``).
    A setting the sampler does not take is a ``ValueError`` naming the nearest one;
    so is a ``seed`` outside [0, 2**63 - 1], before the run. The result is checked
    against the posterior schema before it is returned
    (:func:`mrfpe.samplers.check_result`): a plugin returning anything else is a
    ``ValueError`` naming it. BLAS runs on one thread meanwhile
    (:func:`mrfpe.threads.blas_threads`).
    """
    import inspect

    from mrfpe.samplers import check_result, get, validate_sampler
    from mrfpe.threads import blas_threads
    from mrfpe.validation import check_keywords, check_seed, keyword_names

    seed = check_seed(seed)
    if isinstance(sampler, str) or inspect.isclass(sampler):
        cls = get(sampler)
        check_keywords(config, keyword_names(cls.__init__, 1), f"sampler {cls.__name__}")
        instance = cls(**config)
        name = sampler if isinstance(sampler, str) else cls.__name__
    else:
        validate_sampler(type(sampler))
        if config:
            raise TypeError(f"configuration {sorted(config)} given with an already constructed "
                            f"sampler {sampler!r}; pass the class or a name instead")
        instance = sampler
        name = getattr(instance, "name", "") or type(instance).__name__
    with blas_threads():
        post = instance.run(target, seed=seed, progress=progress, callback=callback)
    return check_result(post, name)


def distance(name: str, a: Any, b: Any, **params: Any) -> float:
    """Distance ``name`` between posteriors ``a`` and ``b`` (lower = more alike)."""
    from mrfpe.distances import distance as _distance

    return _distance(name, a, b, **params)


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"mrfpe.{name}")
    if name == "PosteriorWarning":
        from mrfpe.posterior.diagnostics import PosteriorWarning

        return PosteriorWarning
    if name == "Scene":
        import warnings

        from mrfpe.brdf.scene import Scene

        warnings.warn("mrfpe.Scene has moved to mrfpe.brdf.Scene (mrfpe.brdf.scene.Scene); "
                      "the old name goes in the next minor version", DeprecationWarning,
                      stacklevel=2)
        return Scene
    raise AttributeError(f"module 'mrfpe' has no attribute {name!r}")


__all__ = ["__version__", "distance", "sample"]
