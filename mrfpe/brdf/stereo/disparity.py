"""Probabilistic dense disparity on the corner-vertex lattice (thesis 6.1 step 6, 6.2-6.3).

:func:`disparity` = NCC/SSD cost volume on the nodes (:mod:`mrfpe.brdf.stereo.match`)
+ max-product loopy BP with a robust smoothness term (:mod:`mrfpe.brdf.stereo.bp`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.brdf.stereo.bp import Smoothness, loopy_bp
from mrfpe.brdf.stereo.match import as_image, data_energy, match_measure, pixel_to_node

__all__ = ["DEFAULTS", "DisparityResult", "disparity", "disparity_labels"]

#: Default settings of :func:`disparity` (tuned on the quarter-resolution Middlebury
#: motorcycle pair, see ``benchmarks/bench_stereo.py`` and ``docs/stereo.md``).
DEFAULTS: dict[str, Any] = {
    "window": 3, "match": "ncc", "eps": 1e-6, "data": "log", "e_d": 1e-4, "sigma_d": 0.1,
    "potential": "linear", "smoothness": 0.5, "truncation": 4.0, "e_p": 0.01, "sigma_p": 1.0,
}


@dataclass
class DisparityResult:
    """Result of :func:`disparity`; fields are also reachable as ``result["map"]``.

    Attributes
    ----------
    map : ndarray (H+1, W+1)
        MAP disparity (pixels) of every corner-vertex node (6.35).
    labels : ndarray (H+1, W+1) of int
        Index of the MAP label into ``disparities``.
    beliefs : ndarray (H+1, W+1, L)
        Max-product beliefs per node, normalised to sum to 1 (6.34).
    energy : ndarray (iterations + 1,)
        MRF energy of the MAP labelling: ``energy[0]`` before BP (winner takes
        all on the data term), ``energy[t]`` after iteration ``t``.
    disparities : ndarray (L,)
        Disparity of each label, pixels.
    costs : ndarray (H+1, W+1, L)
        Node data energies ``psi_d`` (6.23/6.30) that BP smoothed.
    measure : ndarray (H+1, W+1, L)
        Node match measure ``d`` in [0, 1] (6.37; mean over the touching pixels,
        1/2 where unmatched); ``F = 1 - measure`` (6.5) is pl2's ``U^C`` input.
    settings : dict
        Every setting used (for reports).
    """

    map: np.ndarray
    labels: np.ndarray
    beliefs: np.ndarray
    energy: np.ndarray
    disparities: np.ndarray
    costs: np.ndarray
    measure: np.ndarray
    settings: dict

    def __getitem__(self, key: str) -> Any:
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        return getattr(self, key)

    def pixel_map(self) -> np.ndarray:
        """MAP disparity of every pixel, (H, W).

        A pixel's belief is taken as the product of its four corner beliefs
        (the sum of their log-beliefs); its disparity is the argmax.
        """
        with np.errstate(divide="ignore"):
            lb = np.log(np.maximum(self.beliefs, 1e-300))
        s = lb[:-1, :-1] + lb[1:, :-1] + lb[:-1, 1:] + lb[1:, 1:]
        return self.disparities[np.argmax(s, axis=2)]


def disparity_labels(max_disparity: Any, min_disparity: Any = 0, step: Any = 1.0,
                     width: int | None = None) -> np.ndarray:
    """Disparity values of the labels: ``min_disparity, min + step, ..., max_disparity``.

    Raises
    ------
    ValueError
        ``max_disparity`` < 1 or >= ``width``, ``min_disparity`` <= ``-width`` or
        >= max, ``step`` <= 0.
    """
    try:
        dmax, dmin, st = float(max_disparity), float(min_disparity), float(step)
    except (TypeError, ValueError):
        raise ValueError("max_disparity, min_disparity and step must be numbers; got "
                         f"{max_disparity!r}, {min_disparity!r}, {step!r}") from None
    if not np.isfinite(dmax) or dmax < 1:
        raise ValueError(f"max_disparity must be >= 1; got {max_disparity!r}")
    if width is not None and dmax >= width:
        raise ValueError(f"max_disparity must be < the image width {width}; got {max_disparity!r}")
    low = -np.inf if width is None else -float(width)
    if not np.isfinite(dmin) or dmin <= low or dmin >= dmax:
        raise ValueError(f"min_disparity must be in (-width, max_disparity); got "
                         f"{min_disparity!r}")
    if not np.isfinite(st) or st <= 0:
        raise ValueError(f"step must be > 0; got {step!r}")
    n = int(np.floor((dmax - dmin) / st + 1e-9)) + 1
    return np.round(dmin + st * np.arange(n), 12)  # no 1.4000000000000001 labels


def disparity(left: Any, right: Any, max_disparity: Any, *, min_disparity: Any = 0,
              step: Any = 1.0, schedule: str = "accelerated", iterations: int = 10,
              window: int = DEFAULTS["window"], match: str = DEFAULTS["match"],
              eps: float = DEFAULTS["eps"], data: str = DEFAULTS["data"],
              e_d: float = DEFAULTS["e_d"], sigma_d: float = DEFAULTS["sigma_d"],
              potential: str = DEFAULTS["potential"], smoothness: float = DEFAULTS["smoothness"],
              truncation: float = DEFAULTS["truncation"], e_p: float = DEFAULTS["e_p"],
              sigma_p: float = DEFAULTS["sigma_p"], damping: float = 0.0) -> DisparityResult:
    """Dense probabilistic disparity of a rectified pair on the corner-vertex lattice.

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3)
        Rectified reference (left) and target (right) images, uint8/uint16 or
        float, grey or colour. A left pixel ``x`` matches right ``x - d``.
    max_disparity : float
        Largest disparity label (pixels), ``1 <= max_disparity < W``.
    min_disparity, step : float
        Smallest label and label spacing (fractional spacing -> sub-pixel labels).
        Negative labels are allowed (``x_right > x_left``, e.g. for a rig whose
        principal points differ, as Middlebury's ``doffs``).
    schedule : {"accelerated", "parallel"}
        Message schedule (6.38-6.41 or 6.33).
    iterations : int
        BP iterations (an accelerated iteration is four sweeps).
    window, match, eps : see :func:`mrfpe.brdf.stereo.match.match_measure`.
    data, e_d, sigma_d : see :func:`mrfpe.brdf.stereo.match.data_energy`.
    potential, smoothness, truncation, e_p, sigma_p : the pairwise term, see
        :class:`mrfpe.brdf.stereo.bp.Smoothness` (``smoothness`` is its weight ``lambda``).
    damping : float in [0, 1)
        Message damping.

    Returns
    -------
    DisparityResult
        ``.map`` (H+1, W+1), ``.beliefs`` (H+1, W+1, L), ``.energy`` (iterations+1,), ...

    Raises
    ------
    ValueError
        Images of different shapes or non-numeric dtype, NaN/inf pixels,
        ``max_disparity`` out of ``[1, W)``, or a bad setting (named in the message).
    """
    L_img = as_image(left, "left")
    R_img = as_image(right, "right")
    if L_img.shape != R_img.shape:
        raise ValueError(f"left and right must have the same shape; got {np.shape(left)} and "
                         f"{np.shape(right)}")
    disp = disparity_labels(max_disparity, min_disparity, step, width=L_img.shape[1])
    smooth = Smoothness(kind=potential, weight=smoothness, truncation=truncation, e_p=e_p,
                        sigma_p=sigma_p)
    # same steps as mrfpe.brdf.stereo.match.node_costs, keeping the node match measure for pl2
    m, valid = match_measure(L_img, R_img, disp, window=window, match=match, eps=eps)
    m = np.where(valid, m, 0.5)
    costs = pixel_to_node(data_energy(m, data=data, e_d=e_d, sigma_d=sigma_d))
    if not np.all(np.isfinite(costs)):
        raise ValueError("the data energy is infinite somewhere: use e_d > 0")
    res = loopy_bp(costs, smooth.table(disp), schedule=schedule, iterations=iterations,
                   damping=damping, linear=smooth.distance_transform(disp))
    settings = {"max_disparity": float(max_disparity), "min_disparity": float(min_disparity),
                "step": float(step), "schedule": schedule, "iterations": int(iterations),
                "window": window, "match": match, "eps": eps, "data": data, "e_d": e_d,
                "sigma_d": sigma_d, "potential": potential, "smoothness": smoothness,
                "truncation": truncation, "e_p": e_p, "sigma_p": sigma_p, "damping": damping}
    return DisparityResult(map=disp[res.labels], labels=res.labels, beliefs=res.beliefs,
                           energy=res.energy, disparities=disp, costs=costs,
                           measure=pixel_to_node(m), settings=settings)
