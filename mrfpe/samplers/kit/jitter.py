"""Resampling noise: Gaussian jitter truncated to the box, and its normalising masses.

:func:`jitter` moves each resampled particle by a Gaussian kernel truncated to
the bounds; :func:`log_kernel_mass` gives those kernels' normalisers, which a
sampler needs to write the exact density of the jittered resampling mixture
(:func:`mrfpe.mixture.log_mixture_density`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["jitter", "log_kernel_mass"]


def jitter(x: np.ndarray, sigma: float | np.ndarray, bounds: np.ndarray,
           rng: np.random.Generator) -> np.ndarray:
    """Add N(0, diag(σ²)) noise to each row, redrawing any row that leaves the bounds.

    ``sigma`` is a scalar (the thesis's spherical kernel, 5.12) or one scale per
    parameter (d,).

    Each new point is therefore drawn from the Gaussian kernel centred on its
    ancestor *truncated to the box* (density: :func:`log_kernel_mass` gives the
    normalising constants). Particles never leave the bounds, so none is wasted.
    """
    sigma = np.asarray(sigma, dtype=np.float64)
    if np.all(sigma <= 0):
        return x.copy()
    lo, hi = bounds[:, 0], bounds[:, 1]
    out = x + sigma * rng.standard_normal(x.shape)
    bad = np.flatnonzero(~np.all((out >= lo) & (out <= hi), axis=1))
    for _ in range(10_000):  # acceptance >= 2^-d for ancestors inside the box
        if bad.size == 0:
            return out
        out[bad] = x[bad] + sigma * rng.standard_normal((bad.size, x.shape[1]))
        bad = bad[~np.all((out[bad] >= lo) & (out[bad] <= hi), axis=1)]
    return np.clip(out, lo, hi)  # pragma: no cover - ancestors outside the box


def log_kernel_mass(centres: np.ndarray, sigma: float | np.ndarray,
                    bounds: np.ndarray) -> np.ndarray:
    """``log P(c + σZ ∈ box)`` for each centre (U,): the truncated kernels' normalisers
    (``sigma`` scalar or per parameter; the kernel is diagonal so the mass factorises)."""
    from scipy.special import ndtr

    lo = (bounds[:, 0] - centres) / sigma
    hi = (bounds[:, 1] - centres) / sigma
    return np.sum(np.log(np.clip(ndtr(hi) - ndtr(lo), 1e-300, None)), axis=1)
