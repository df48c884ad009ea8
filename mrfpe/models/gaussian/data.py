"""Checks of the arrays the auto-normal model and its targets take: real, finite, whole fields."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["as_fields", "real_array"]


def real_array(value: Any, what: str) -> np.ndarray:
    """``value`` as a float64 array; a ValueError naming ``what`` unless real and finite."""
    try:
        z = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be an array of real numbers") from None
    if z.dtype.kind not in "iuf":
        raise ValueError(f"{what} must hold real numbers; got dtype {z.dtype}")
    z = z.astype(np.float64)
    if not np.all(np.isfinite(z)):
        raise ValueError(f"{what} must be finite (it holds NaN or inf)")
    return z


def as_fields(x: Any, n: int) -> np.ndarray:
    """Fields ``x`` as an ``(M, n)`` float64 array (any shape holding whole fields of ``n``)."""
    arr = real_array(x, "x")
    if arr.size % n or arr.size == 0:
        raise ValueError(f"x must hold fields of {n} nodes ((M, {n}) or a lattice shape); got "
                         f"shape {arr.shape}")
    return arr.reshape(-1, n)
