"""Reading trial results back: grouping by cell for the summaries."""

from __future__ import annotations

import json
from collections.abc import Iterable

import xarray as xr

__all__ = ["by_cell"]


def by_cell(results: Iterable[xr.Dataset], *keys: str) -> dict[tuple, list[xr.Dataset]]:
    """Group trial Datasets by the values of grid ``keys`` in their cell (insertion order)."""
    groups: dict[tuple, list[xr.Dataset]] = {}
    for ds in results:
        cell = json.loads(ds.attrs["cell"])
        groups.setdefault(tuple(cell[k] for k in keys), []).append(ds)
    return groups
