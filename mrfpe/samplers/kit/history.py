"""The optional per-step record of a weighted set (``keep_history``): :class:`History`."""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.resampling import normalise_log_weights

__all__ = ["History"]


class History:
    """Every step's weighted set, kept only when asked (``keep_history=True``).

    ``record(x, lw)`` after each step; ``build_kwargs()`` gives
    ``history_theta (step, sample, param)`` and ``history_log_weight (step, sample)``
    (normalised) for :meth:`Run.finish` — both None when not kept, so a sampler
    writes the same two lines either way.
    """

    def __init__(self, keep: bool):
        self.keep = bool(keep)
        self._x: list[np.ndarray] = []
        self._lw: list[np.ndarray] = []

    def record(self, theta: np.ndarray, log_weight: np.ndarray) -> None:
        if self.keep:
            self._x.append(np.array(theta, copy=True))
            self._lw.append(normalise_log_weights(log_weight))

    def build_kwargs(self) -> dict[str, Any]:
        if not self.keep:
            return {"history_theta": None, "history_log_weight": None}
        return {"history_theta": np.asarray(self._x),
                "history_log_weight": np.asarray(self._lw)}
