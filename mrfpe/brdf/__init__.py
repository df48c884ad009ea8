"""The thesis's application: a parametric BRDF estimated as MRF parameter estimation.

A photograph of a surface of known shape, under a known light, is a noisy view of
the reflectance. The thesis casts the estimation of a parametric BRDF from a
probabilistic surface reconstruction as the estimation of the parameters of an
MRF on a lattice of corner-vertex nodes with triplet cliques, whose labels are the
candidate depths of each node. This wing holds all of it, built on the generic
core (:mod:`mrfpe.models`, :mod:`mrfpe.targets`, :mod:`mrfpe.samplers`, ...), which
imports nothing from here:

* :mod:`mrfpe.brdf.functions` -- the parametric BRDFs (Lambertian, Ward,
  Ashikhmin-Shirley/Phong, ...) for batches of parameters; their names and
  :func:`get` are also importable from ``mrfpe.brdf`` itself;
* :mod:`mrfpe.brdf.geometry`, :mod:`mrfpe.brdf.shading` -- vectors, normals,
  lights and the rendering equation;
* :mod:`mrfpe.brdf.lattice`, :mod:`mrfpe.brdf.scene`, :mod:`mrfpe.brdf.synthetic`
  -- the corner-vertex lattice, a scene (image, lights, camera, candidate
  labels) and the thesis's synthetic scenes;
* :mod:`mrfpe.brdf.engine` -- the compiled kernels of the BRDF pseudolikelihoods;
* :mod:`mrfpe.brdf.targets` -- PL, PL2, PL3, PL_s and the image fit, registered as
  the targets ``pl``, ``pl2``, ``pl3``, ``pls``, ``fit`` and ``pml`` of
  :func:`mrfpe.targets.get`;
* :mod:`mrfpe.brdf.model`, :mod:`mrfpe.brdf.simulate`,
  :mod:`mrfpe.brdf.label_render` -- the BRDF label field as a declared model
  (``mrfpe.models.get("brdf")``), its simulator and label rendering;
* :mod:`mrfpe.brdf.stereo` -- a probabilistic surface reconstruction from a
  calibrated stereo pair (the beliefs PL3 takes).

The targets and the model register through the entry-point groups
``mrfpe.targets`` and ``mrfpe.models``, as a third party's would.
"""

from __future__ import annotations

import importlib
from typing import Any

from mrfpe.brdf.functions import (
    BRDF,
    AshikhminShirley,
    AshikhminShirleyIsotropic,
    Lambertian,
    Ward,
    WardAnisotropic,
    get,
    names,
)

__all__ = ["BRDF", "AshikhminShirley", "AshikhminShirleyIsotropic", "Lambertian", "Scene",
           "Ward", "WardAnisotropic", "get", "make_scene", "names"]

_SUBMODULES = {"functions", "geometry", "shading", "lattice", "scene", "synthetic", "engine",
               "targets", "model", "simulate", "label_render", "stereo"}
_NAMES = {"Scene": "mrfpe.brdf.scene", "make_scene": "mrfpe.brdf.synthetic"}


def __getattr__(name: str) -> Any:
    # imported on first use, so that `import mrfpe.brdf` stays light
    if name in _SUBMODULES:
        return importlib.import_module(f"mrfpe.brdf.{name}")
    if name in _NAMES:
        return getattr(importlib.import_module(_NAMES[name]), name)
    raise AttributeError(f"module 'mrfpe.brdf' has no attribute {name!r}")
