"""Where a warning should point: the first frame outside mrfpe (a leaf module)."""

from __future__ import annotations

import sys

__all__ = ["stacklevel_outside_mrfpe"]


def stacklevel_outside_mrfpe() -> int:
    """``stacklevel`` for a ``warnings.warn`` made by the caller of this function that names
    the first frame outside mrfpe, so a warning points at the user's line."""
    level, frame = 1, sys._getframe(1)  # level 1: the function calling warnings.warn
    while frame is not None and frame.f_globals.get("__name__", "").split(".")[0] == "mrfpe":
        frame, level = frame.f_back, level + 1
    return level
