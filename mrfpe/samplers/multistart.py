"""Multi-start optimisers: the seed points and the driver shared by ``lm_multiseed`` and
``nlopt_multiseed`` (thesis 7.3.2).

One local optimisation starts from each of ``n_seeds`` points of the parameter box
(:func:`seed_points`: the evenly spaced grid of 7.3.2, optionally shifted by one
random offset); :class:`MultiSeedOptimiser` runs them, offers each optimum to the
best-so-far trace (step = seed) and returns the optima, weighted by their target
values, as a posterior of ``kind="optima"``. The optimisers themselves are
:mod:`mrfpe.samplers.lm_multiseed` and :mod:`mrfpe.samplers.nlopt_multiseed`
(:mod:`mrfpe.samplers.multiseed` describes both).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int
from mrfpe.samplers.kit import Run, check_seed, check_target, grid

__all__ = ["SEED_GRIDS", "MultiSeedOptimiser", "seed_points"]

#: The seed grids: the thesis's evenly spaced grid, or that grid shifted by one offset.
SEED_GRIDS = ("even", "shifted")


def seed_points(bounds: np.ndarray, n: int, kind: str = "even",
                rng: np.random.Generator | None = None) -> np.ndarray:
    """The ``n`` starting points (n, d): the evenly spaced grid of 7.3.2, optionally shifted.

    ``kind="shifted"`` adds one offset per axis, uniform within ± half the grid
    spacing on that axis, to every point (so the points stay inside the box).
    """
    pts = grid(bounds, n)
    if kind == "even":
        return pts
    if rng is None:
        raise ValueError("a shifted seed grid needs rng")
    width = bounds[:, 1] - bounds[:, 0]
    half = np.empty(bounds.shape[0])
    for j in range(bounds.shape[0]):
        gaps = np.diff(np.unique(pts[:, j]))
        half[j] = 0.5 * (gaps.min() if gaps.size else width[j])
    return np.clip(pts + rng.uniform(-half, half), bounds[:, 0], bounds[:, 1])


class MultiSeedOptimiser(Sampler):
    """Shared driver: one local optimisation per seed point, optima as the sample set.

    A subclass validates its settings (calling :meth:`_check_common` for ``n_seeds``
    and ``seed_grid``) and implements :meth:`_optimise` (one seed's optimisation);
    it may override :meth:`_prepare` (target requirements) and :meth:`_optimise_all`
    (to run the seeds together).
    """

    # The randomly shifted grid makes the seed matter, for the reproducibility check.
    conformance: ClassVar[dict] = {"quick_config": {"n_seeds": 27, "seed_grid": "shifted"}}

    def _check_common(self, n_seeds: int, seed_grid: str) -> None:
        self.n_seeds = check_positive_int("n_seeds", n_seeds)
        self.seed_grid = check_choice("seed_grid", seed_grid, SEED_GRIDS)

    def _optimise(self, target: Any, x0: np.ndarray, run: Run, bounds: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, dict[str, float]]:
        raise NotImplementedError  # pragma: no cover

    def _prepare(self, target: Any, bounds: np.ndarray) -> None:
        """Check target requirements before any evaluation (override)."""

    def _optimise_all(self, target: Any, starts: np.ndarray, run: Run, bounds: np.ndarray,
                      rng: np.random.Generator) -> Iterator[tuple[np.ndarray, dict[str, float]]]:
        """Each seed's ``(optimum, stats)`` in seed order (override to run them together)."""
        for x0 in starts:
            yield self._optimise(target, x0, run, bounds, rng)

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Optimise from every seed point and return the posterior Dataset."""
        bounds = check_target(target)
        check_seed(seed)
        self._prepare(target, bounds)
        rng = np.random.default_rng(seed)
        starts = seed_points(bounds, self.n_seeds, self.seed_grid, rng)
        # the first step is one optimum: a small support may need several seeds to find
        run = Run(target, starts.shape[0], progress=progress, callback=callback, desc=self.name,
                  check_first_step=False)
        opt = np.empty_like(starts)
        lt = np.empty(starts.shape[0])
        info: dict[str, list[float]] = {}
        for i, (x, stats) in enumerate(self._optimise_all(target, starts, run, bounds, rng)):
            opt[i] = np.clip(x, bounds[:, 0], bounds[:, 1])
            lt[i] = run.evaluate(target, opt[i:i + 1])[0]
            run.offer(opt[i:i + 1], lt[i:i + 1])
            for k, v in stats.items():
                info.setdefault(k, []).append(v)
            run.step(i, np.nan, **{k: float(v) for k, v in stats.items()})
        extra = {"seed_theta": (("sample", "param"), starts)}
        extra.update({k: (("sample",), np.asarray(v, dtype=np.float64)) for k, v in info.items()})
        return run.finish(opt, lt, lt, sampler=self.name, config=self.get_config(), seed=seed,
                          extra_vars=extra, kind="optima")
