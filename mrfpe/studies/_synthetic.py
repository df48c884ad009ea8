"""Shared pieces of the synthetic-data studies (thesis 7.2): problems, maximisers, traces.

A *problem* is one synthetic scene (7.2 steps 2-4: random surface, random
light at infinity, random true parameters b^n, range labels), the target built
on it, the true parameters in the unit cube (7.1-7.2) and the target's global
maximiser (:func:`mrfpe.targets.maximise`). Distances are Euclidean in the
unit cube, as the thesis's "MAP dist" ((ρ_d, ρ_s, 2α) for Ward, (R_d, R_s,
n/25) for Phong). Every convergence study reports a sampler's distance to the
truth *and* to the maximiser: a pseudolikelihood's maximum need not sit on
the truth, and the two errors have different causes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

__all__ = ["Problem", "child_seeds", "distance", "first_reach", "make_problem", "maximiser",
           "sample_traced", "weight_variance"]

#: The thesis tests each model on its own best surface type (7.2): Ward on
#: smooth thin-plate-spline surfaces, (isotropic) anisotropic Phong on jagged ones.
DEFAULT_SURFACES = {"ward": "smooth", "phong": "jagged"}


def child_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds from one trial seed (``SeedSequence.spawn``)."""
    return [int(c.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))
            for c in np.random.SeedSequence(seed).spawn(n)]


@dataclass
class Problem:
    """A synthetic scene, its target, the truth and the target's maximiser (unit cube)."""

    scene: Any
    target: Any
    truth: np.ndarray
    maximiser: np.ndarray | None
    maximiser_log_prob: float
    truth_log_prob: float

    def dataset(self) -> xr.Dataset:
        """Truth, maximiser and scene facts as variables of a trial Dataset."""
        names = list(self.target.param_names)
        data = {
            "truth": (("param",), self.truth),
            "truth_log_prob": ((), self.truth_log_prob),
            "light": (("xyz",), np.asarray(self.scene.light.direction, dtype=float)),
        }
        if self.maximiser is not None:
            data.update({
                "maximiser": (("param",), self.maximiser),
                "maximiser_log_prob": ((), self.maximiser_log_prob),
                "maximiser_to_truth": ((), float(distance(self.maximiser, self.truth))),
            })
        return xr.Dataset(data, coords={"param": names, "xyz": ["x", "y", "z"]})


def make_problem(brdf: str, seed: int, *, surface: str, shape: Sequence[int], n_labels: int,
                 noise: float = 0.0, target: str = "pls", target_options: dict | None = None,
                 truth: Sequence[float] | None = None, truth_range: Sequence[float] = (0.1, 0.9),
                 maximiser_grid: int | None = 20) -> Problem:
    """Build one problem from ``seed`` (truth, then scene, then maximiser streams).

    ``truth`` (unit cube) is drawn uniformly from ``truth_range`` per
    parameter when not given; ``maximiser_grid=None`` skips the maximiser.
    """
    import mrfpe

    s_truth, s_scene, s_max = child_seeds(seed, 3)
    model = mrfpe.brdf.get(brdf)
    if truth is None:
        lo, hi = truth_range
        u = np.random.default_rng(s_truth).uniform(lo, hi, model.d)
    else:
        u = np.asarray(truth, dtype=float)
    scene = mrfpe.synthetic.make_scene(brdf=brdf, theta=model.to_natural(u),
                                       shape=tuple(shape), n_labels=n_labels, surface=surface,
                                       noise=noise, seed=s_scene)
    tgt = mrfpe.targets.get(target, scene, **(target_options or {}))
    truth_lp = float(tgt.log_prob(u[None])[0])
    if maximiser_grid is None:
        return Problem(scene, tgt, u, None, np.nan, truth_lp)
    mx, mlp = maximiser(tgt, maximiser_grid, s_max, u)
    return Problem(scene, tgt, u, mx, mlp, truth_lp)


def maximiser(target: Any, grid: int, seed: int, truth: Any) -> tuple[np.ndarray, float]:
    """:func:`mrfpe.targets.maximise` on the evenly spaced ``grid``³ points plus the truth.

    The truth is one more start for the local refinement: a peak narrower than
    the grid spacing can otherwise be missed (measured: on a 100×100 Ward scene
    the 20³ grid alone returned a point 23 nats below the truth's value). The
    result is still the best local maximum found, wherever it lies.
    """
    import mrfpe
    from mrfpe.targets.maximise import grid_points

    pts = np.vstack([grid_points(target.bounds, grid), np.asarray(truth, dtype=float)[None]])
    mx, mlp = mrfpe.targets.maximise(target, grid=pts, seed=seed)
    return np.asarray(mx, dtype=float), float(mlp)


def distance(a: Any, b: Any) -> np.ndarray:
    """Euclidean distance along the last axis (unit cube)."""
    return np.linalg.norm(np.asarray(a, dtype=float) - np.asarray(b, dtype=float), axis=-1)


def sample_traced(name: str, target: Any, seed: int, **config: Any) -> tuple[xr.Dataset,
                                                                             np.ndarray]:
    """Run sampler ``name``; also return the cumulative target evaluations after each step."""
    import mrfpe

    evals: list[float] = []
    post = mrfpe.sample(name, target, seed=seed,
                        callback=lambda step, info: evals.append(float(info["n_target_evals"])),
                        **config)
    evals_arr = np.asarray(evals, dtype=float)
    if evals_arr.size != post.sizes["step"]:  # a sampler that skips its callback on some steps
        evals_arr = np.full(post.sizes["step"], np.nan)
    return post, evals_arr


def weight_variance(post: xr.Dataset) -> np.ndarray:
    """Variance of the normalised weights of every stored iteration (the thesis's "var")."""
    lw = post["history_log_weight"].values
    return np.exp(lw).var(axis=1)


def first_reach(dist: np.ndarray, evals: np.ndarray, level: float) -> float:
    """Target evaluations when ``dist`` (per step) first falls to ``level`` (NaN if never)."""
    hit = np.flatnonzero(np.asarray(dist) <= level)
    return float(evals[hit[0]]) if hit.size else float("nan")
