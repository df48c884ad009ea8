"""Starting points: the thesis's evenly spaced grid, a space-filling design, uniform draws."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrfpe.validation import check_choice

__all__ = ["draw_in_support", "grid", "space_filling"]


def grid(bounds: np.ndarray, n: int, *, faces: bool = False) -> np.ndarray:
    """``n`` evenly spaced points in the box (the thesis's initial set, 6.6.1–6.6.2).

    The box is cut into ``m = ceil(n^(1/d))`` points per axis (1000 = 10³ in 3-D
    gives the thesis's 10×10×10 grid), and when ``n`` is not a perfect power,
    ``n`` of the ``m^d`` points are taken at evenly spaced positions of the
    lexicographic order. "Evenly spaced" has two readings, and they differ most
    at small ``n``:

    * ``faces=False``: the cell centres ``lo + (i + ½)/m · (hi − lo)``, which
      never touch the box's faces (the 4³ grid is {⅛, ⅜, ⅝, ⅞}³);
    * ``faces=True``: ``m`` points from face to face, ``lo + i/(m − 1) · (hi − lo)``
      (``numpy.linspace``; the 4³ grid is {0, ⅓, ⅔, 1}³, 56 of its 64 points on
      the faces), the reading under which PMC (II) reproduces Table 7.1's
      N = 125 and 64 columns (``docs/results/pmc_convergence_faces/``). With
      ``m = 1`` the single point is the centre either way.
    """
    b = np.asarray(bounds, dtype=np.float64)
    d = b.shape[0]
    m = max(1, math.ceil(round(n ** (1.0 / d), 9)))
    unit = (np.linspace(0.0, 1.0, m) if faces and m > 1 else (np.arange(m) + 0.5) / m)
    axes = [b[j, 0] + unit * (b[j, 1] - b[j, 0]) for j in range(d)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    if pts.shape[0] == n:
        return pts
    return pts[np.round(np.linspace(0, pts.shape[0] - 1, n)).astype(np.int64)]


#: The two readings of "evenly spaced" (:func:`grid`): cell centres, face to face.
GRID_READINGS = ("grid", "grid_faces")


def grid_reading(initial: str | None, *, thesis: bool) -> str:
    """The initial grid ``initial`` checked against :data:`GRID_READINGS`; ``None`` picks
    ``"grid_faces"`` for the thesis's weights (the reading that reproduces Table 7.1) and
    ``"grid"`` otherwise."""
    if initial is None:
        return "grid_faces" if thesis else "grid"
    return check_choice("initial", initial, GRID_READINGS)


def draw_in_support(run: Any, target: Any, rng: np.random.Generator, n: int,
                    bounds: np.ndarray, max_draws: int = 2048, *,
                    return_fraction: bool = False,
                    ) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, float]:
    """``n`` uniform draws in the box, with -inf ones replaced by further uniform draws.

    Candidates are drawn and evaluated through ``run.evaluate`` (so they are
    counted) in batches of ``max(n, 32)`` until every row is finite or about
    ``max_draws`` extra candidates have been tried. Rows still -inf are then
    replaced by copies of finite draws when there are any (chains separate
    through their moves), so a sampler survives a target that is -inf almost
    everywhere; if none is finite, ``ValueError`` (:meth:`Run.require_support
    <mrfpe.samplers.kit.Run.require_support>`): a target -inf everywhere has nothing
    to sample.

    Returns
    -------
    theta : (n, d) start points; log_target : (n,) their log densities;
    fraction : with ``return_fraction``, the share of all evaluated uniform
        candidates that were finite, an estimate of the support's share of the box
        (what an evidence relative to the box multiplies by when the draws are then
        taken as uniform on the support).
    """
    lo, hi = bounds[:, 0], bounds[:, 1]
    theta = lo + (hi - lo) * rng.random((n, lo.size))
    lp = run.evaluate(target, theta)
    n_tried, n_finite = n, int(np.isfinite(lp).sum())
    batch = max(n, 32)
    for _ in range(-(-max_draws // batch)):
        bad = np.flatnonzero(~np.isfinite(lp))
        if bad.size == 0:
            break
        cand = lo + (hi - lo) * rng.random((batch, lo.size))
        lpc = run.evaluate(target, cand)
        n_tried, n_finite = n_tried + batch, n_finite + int(np.isfinite(lpc).sum())
        good = np.flatnonzero(np.isfinite(lpc))[: bad.size]
        theta[bad[: good.size]], lp[bad[: good.size]] = cand[good], lpc[good]
    bad = ~np.isfinite(lp)
    if bad.all():
        run.require_support(f"as uniform draws in the bounds ({n_tried} draws)")
    if bad.any() and not bad.all():
        src = rng.choice(np.flatnonzero(~bad), size=int(bad.sum()))
        theta[bad], lp[bad] = theta[src], lp[src]
    return (theta, lp, n_finite / n_tried) if return_fraction else (theta, lp)


def space_filling(bounds: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` scrambled Halton points in the box (:mod:`scipy.stats.qmc`), scrambled from ``rng``.

    A space-filling start for any ``n`` and dimension: unlike :func:`grid`, whose
    ``ceil(n^(1/d))`` cells per axis collapse to 2 in 10-D (the corners of
    ``{0.25, 0.75}^10``), every point has distinct coordinates on every axis.
    """
    import inspect

    from scipy.stats import qmc

    b = np.asarray(bounds, dtype=np.float64)
    key = "rng" if "rng" in inspect.signature(qmc.Halton).parameters else "seed"
    u = qmc.Halton(b.shape[0], scramble=True, **{key: rng}).random(n)
    return b[:, 0] + (b[:, 1] - b[:, 0]) * u
