"""Old module paths that still import, with a ``DeprecationWarning`` naming the new place.

The thesis's BRDF application moved into the wing :mod:`mrfpe.brdf` (and the Potts
short forms into :mod:`mrfpe.models.short_forms`). An import of an old path, say
``import mrfpe.synthetic`` or ``from mrfpe.engine.lean import lean_terms``, warns
once per path and gives the module at its new place -- the same module object, not
a copy, so that classes, numba kernels and caches are shared. A meta-path finder
does this for every old path and its submodules; no stub file is left at the old
places. These aliases go in the next minor version (CHANGELOG).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType
from typing import Any

__all__ = ["MOVED", "MovedModuleFinder", "install", "new_name"]

#: Old module path -> new one. A path that ends in "." maps its submodules by prefix.
MOVED: dict[str, str] = {
    "mrfpe.engine.fastmath": "mrfpe.fastmath",
    "mrfpe.engine": "mrfpe.brdf.engine",
    "mrfpe.engine.": "mrfpe.brdf.engine.",
    "mrfpe.stereo": "mrfpe.brdf.stereo",
    "mrfpe.stereo.": "mrfpe.brdf.stereo.",
    "mrfpe.geometry": "mrfpe.brdf.geometry",
    "mrfpe.shading": "mrfpe.brdf.shading",
    "mrfpe.scene": "mrfpe.brdf.scene",
    "mrfpe.lattice": "mrfpe.brdf.lattice",
    "mrfpe.synthetic": "mrfpe.brdf.synthetic",
    **{f"mrfpe.targets.{m}": f"mrfpe.brdf.targets.{m}"
       for m in ("brdf_target", "energy", "jacobian", "pseudolikelihood", "reflectance",
                 "residuals", "tables")},
    "mrfpe.targets.potts": "mrfpe.models.short_forms",
    "mrfpe.models.brdf": "mrfpe.brdf.model",
    "mrfpe.models.brdf_simulate": "mrfpe.brdf.simulate",
    "mrfpe.models.label_render": "mrfpe.brdf.label_render",
}


def new_name(old: str) -> str | None:
    """The new path of module ``old``, or None if it did not move."""
    if old in MOVED:
        return MOVED[old]
    for prefix, target in MOVED.items():
        if prefix.endswith(".") and old.startswith(prefix):
            return target + old[len(prefix):]
    return None


class _AliasLoader(importlib.abc.Loader):
    """Hands the import system the module at its new place, unchanged."""

    def __init__(self, old: str, new: str) -> None:
        self.old, self.new = old, new
        self._spec: Any = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        warnings.warn(f"{self.old} has moved to {self.new}; import it from there (the old "
                      f"path goes in the next minor version)", DeprecationWarning,
                      stacklevel=2)  # the import statement: warnings skips importlib's frames
        module = importlib.import_module(self.new)
        self._spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # the import system has set the alias's spec on the module: give it back its own
        module.__spec__ = self._spec


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of :data:`MOVED` (and nothing else)."""

    def find_spec(self, fullname: str, path: Any = None,
                  target: Any = None) -> importlib.machinery.ModuleSpec | None:
        new = new_name(fullname)
        if new is None:
            return None
        spec = importlib.util.find_spec(new)
        if spec is None:
            return None
        package = spec.submodule_search_locations is not None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(fullname, new),
                                              is_package=package)


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once per process)."""
    if not any(isinstance(f, MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedModuleFinder())
