"""ArviZ, imported without its once-a-day notice of a coming refactor.

ArviZ 0.2x prints a ``FutureWarning`` about its own next major version on the
first import of each day; it says nothing about the user's posterior, yet
would appear in the middle of a sampler's output. Every mrfpe module imports
ArviZ through :func:`arviz`.
"""

from __future__ import annotations

import warnings
from types import ModuleType

__all__ = ["arviz"]


def arviz() -> ModuleType:
    """The ``arviz`` module (imported on first use, its refactor notice left out)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"\s*ArviZ is undergoing a major refactor",
                                category=FutureWarning)
        import arviz as az
    return az
