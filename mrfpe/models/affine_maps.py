"""The affine maps of :class:`~mrfpe.models.calibration.AdjustedPL`: which ``W`` meets a
calibration's condition.

A condition on the calibrated target's curvature (``Wᵀ H W = I``) or covariance
(``W⁻¹ C W⁻ᵀ = I⁻¹``) fixes ``W`` up to a rotation. ``"cholesky"`` takes the
published Cholesky factors (Bouranis, Friel & Maire 2017), which depend on the
parameters' order; ``"transport"`` the symmetric solution (:func:`transport_map`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mode_map", "moment_map", "transport_map"]


def transport_map(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The symmetric positive definite ``T`` with ``T @ source @ T = target``.

    ``T = S^-1/2 (S^1/2 D S^1/2)^1/2 S^-1/2`` for ``S = source``, ``D = target``: the
    optimal-transport (Monge) map between centred Gaussians of these covariances
    (Olkin & Pukelsheim 1982; Knott & Smith 1984), the only symmetric positive definite
    solution. Its inverse is ``transport_map(target, source)``.
    """
    root = _psd_root(source)
    inv_root = np.linalg.inv(root)
    return _symmetric(inv_root @ _psd_root(root @ target @ root) @ inv_root)


def _psd_root(M: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(_symmetric(M))
    return _symmetric((V * np.sqrt(np.clip(w, 0.0, None))) @ V.T)


def _symmetric(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.T)


def mode_map(H: np.ndarray, info: np.ndarray, affine: str) -> np.ndarray:
    """``W`` with ``Wᵀ H W = I``: the Hessian at the mode is the Fisher information
    (``H`` positive definite)."""
    if affine == "transport":
        return transport_map(H, info)
    # M⁻¹N with H = MᵀM, I = NᵀN
    return np.linalg.solve(np.linalg.cholesky(H).T, np.linalg.cholesky(info).T)


def moment_map(pl_cov: np.ndarray, info: np.ndarray, affine: str) -> np.ndarray:
    """``W`` with ``W⁻¹ C W⁻ᵀ = I⁻¹``: the covariance is the inverse Fisher information."""
    if affine == "transport":
        return transport_map(np.linalg.inv(info), pl_cov)
    return np.linalg.cholesky(pl_cov) @ np.linalg.cholesky(info).T
