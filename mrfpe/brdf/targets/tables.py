"""Per-scene cache of the data-energy tables (:mod:`mrfpe.brdf.targets.energy`).

Building the tables is the expensive, theta-independent part of a BRDF
target. Every target built on the same :class:`mrfpe.brdf.scene.Scene` object with
the same data term and precision shares one set, held in a weak-keyed cache
(it goes when the scene goes), and likewise the lean kernels' template tables
(:func:`lean_tables_for`). A content fingerprint guards against scenes
modified in place: stale tables are dropped and rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import weakref
from typing import Any

import numpy as np

from mrfpe.brdf.engine import DataTables, LeanTables, lean_tables
from mrfpe.brdf.targets.energy import build_tables
from mrfpe.budget import check_memory

__all__ = ["estimate_table_bytes", "fingerprint", "lean_tables_for", "tables_for"]

_TABLE_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def fingerprint(scene: Any) -> str:
    """Content hash of everything in ``scene`` that the tables depend on."""
    h = hashlib.blake2b(digest_size=16)
    for arr in (scene.image, scene.label_ranges, scene.observed_labels, scene.tangent_ref):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update(json.dumps([scene.brdf, scene.camera.to_dict(), scene.light.to_dict()],
                        sort_keys=True).encode())
    return h.hexdigest()


def estimate_table_bytes(n_nodes: int, n_labels: int, data_term: str = "pixel",
                         dtype: str = "float64") -> float:
    """Peak memory (bytes) of building the tables of a lattice of ``n_nodes`` x ``n_labels``.

    Per (node, label): up to 6 variable triangles (4 cliques for ``"triplet"``),
    each with 5 float64 features and an int64 destination index, plus the
    label points (and a float32 copy of the features for ``dtype="float32"``);
    plus the geometry batches' working memory (bounded, about 80 MB).
    """
    n_var = 6 if data_term == "pixel" else 4
    per = n_var * (5 * 8 + 8) + 2 * 3 * 8
    if dtype == "float32":
        per += n_var * 5 * 4
    return float(n_nodes) * n_labels * per + float(n_nodes) * 4 * 12 * 8 + 80e6


def tables_for(scene: Any, data_term: str, dtype: str = "float64", *,
               progress: bool = False) -> DataTables:
    """Data tables of ``scene``, shared by every target built on the same scene.

    A build whose :func:`estimate_table_bytes` exceeds the memory budget raises
    :class:`mrfpe.budget.MemoryBudgetError` before it starts.
    """
    fp = fingerprint(scene)
    per_scene = _TABLE_CACHE.setdefault(scene, {})
    key = (data_term, dtype, fp)
    if key not in per_scene:
        check_memory(estimate_table_bytes(scene.lattice.n_nodes, scene.n_labels, data_term,
                                          dtype),
                     f"building the {data_term} data tables of a {scene.shape[0]}x"
                     f"{scene.shape[1]} scene with {scene.n_labels} labels",
                     "use fewer labels or a smaller scene")
        for old in [k for k in per_scene if k[:2] == (data_term, dtype)]:
            del per_scene[old]  # the scene was modified in place: drop stale tables
        if dtype == "float64":
            per_scene[key] = build_tables(scene, data_term, progress=progress)
        else:
            per_scene[key] = tables_for(scene, data_term, "float64",
                                        progress=progress).astype(dtype)
    return per_scene[key]


def lean_tables_for(scene: Any, data_term: str, dtype: str, full: bool) -> LeanTables | None:
    """The lean kernels' template tables (:func:`mrfpe.brdf.engine.lean_tables`) of
    :func:`tables_for`'s tables, shared by every target on the same scene (None if
    they do not fit the template)."""
    data = tables_for(scene, data_term, dtype)
    per_scene = _TABLE_CACHE[scene]
    key = (data_term, dtype, fingerprint(scene), "lean", bool(full))
    if key not in per_scene:
        per_scene[key] = lean_tables(data, full)
    return per_scene[key]
