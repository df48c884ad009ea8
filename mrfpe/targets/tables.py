"""Per-scene cache of the data-energy tables (:mod:`mrfpe.targets.energy`).

Building the tables is the expensive, theta-independent part of a BRDF
target. Every target built on the same :class:`mrfpe.scene.Scene` object with
the same data term and precision shares one set, held in a weak-keyed cache
(it goes when the scene goes). A content fingerprint guards against scenes
modified in place: stale tables are dropped and rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import weakref
from typing import Any

import numpy as np

from mrfpe.targets.energy import DataTables, build_tables

__all__ = ["fingerprint", "tables_for"]

_TABLE_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def fingerprint(scene: Any) -> str:
    """Content hash of everything in ``scene`` that the tables depend on."""
    h = hashlib.blake2b(digest_size=16)
    for arr in (scene.image, scene.label_ranges, scene.observed_labels, scene.tangent_ref):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update(json.dumps([scene.brdf, scene.camera.to_dict(), scene.light.to_dict()],
                        sort_keys=True).encode())
    return h.hexdigest()


def tables_for(scene: Any, data_term: str, dtype: str = "float64") -> DataTables:
    """Data tables of ``scene``, shared by every target built on the same scene."""
    fp = fingerprint(scene)
    per_scene = _TABLE_CACHE.setdefault(scene, {})
    key = (data_term, dtype, fp)
    if key not in per_scene:
        for old in [k for k in per_scene if k[:2] == (data_term, dtype)]:
            del per_scene[old]  # the scene was modified in place: drop stale tables
        if dtype == "float64":
            per_scene[key] = build_tables(scene, data_term)
        else:
            per_scene[key] = tables_for(scene, data_term, "float64").astype(dtype)
    return per_scene[key]
