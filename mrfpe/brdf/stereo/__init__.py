"""Probabilistic dense stereo on the corner-vertex lattice (thesis chapter 6).

* :func:`disparity` -- NCC/SSD cost volume + max-product loopy BP (parallel or
  accelerated schedule) -> MAP disparities and per-node beliefs.
* :func:`scene_from_stereo` -- rectified pair + cameras + light -> a
  :class:`mrfpe.brdf.scene.Scene` whose labels are the disparity labels and whose
  beliefs feed the stereo potential ``U^D`` of ``pl3`` (6.60-6.62).
* calibration helpers (OpenCV): :func:`find_chessboard`, :func:`calibrate_stereo`,
  :func:`calibrate_from_images`, :func:`stereo_rectify`, :func:`rectify_pair`,
  :func:`to_lattice_convention`.

See ``docs/stereo.md``.
"""

from __future__ import annotations

from mrfpe.brdf.stereo.calibration import (
    Rectification,
    StereoCalibration,
    calibrate_from_images,
    calibrate_stereo,
    chessboard_points,
    find_chessboard,
    rectify_pair,
    stereo_rectify,
    to_lattice_convention,
)
from mrfpe.brdf.stereo.disparity import DisparityResult, disparity, disparity_labels
from mrfpe.brdf.stereo.reconstruct import label_points, scene_from_stereo

__all__ = [
    "DisparityResult",
    "Rectification",
    "StereoCalibration",
    "calibrate_from_images",
    "calibrate_stereo",
    "chessboard_points",
    "disparity",
    "disparity_labels",
    "find_chessboard",
    "label_points",
    "rectify_pair",
    "scene_from_stereo",
    "stereo_rectify",
    "to_lattice_convention",
]
