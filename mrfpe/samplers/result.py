"""What a sampler returns, checked before anyone uses or writes it."""

from __future__ import annotations

from typing import Any

import xarray as xr

__all__ = ["check_result"]


def check_result(post: Any, sampler: str) -> xr.Dataset:
    """``post`` if it follows the posterior schema (:func:`mrfpe.posterior.validate`).

    :func:`mrfpe.sample` and ``mrfpe estimate`` pass every sampler's result
    through it, so a plugin returning ``None``, a foreign Dataset or NaN samples
    stops with one line instead of being returned, printed or written.

    Raises
    ------
    ValueError
        ``"sampler 'NAME' returned an invalid posterior: <the first problem>"``.
    """
    from mrfpe.posterior import validate

    try:
        validate(post)
    except ValueError as exc:
        raise ValueError(f"sampler {sampler!r} returned an invalid posterior: {exc}") from None
    return post
