"""Resampling noise: Gaussian jitter truncated to the box, and its normalising masses.

:func:`jitter` moves each resampled particle by a Gaussian kernel truncated to
the bounds; :func:`log_kernel_mass` gives those kernels' normalisers, which a
sampler needs to write the exact density of the jittered resampling mixture
(:func:`mrfpe.mixture.log_mixture_density`). For a full-covariance kernel, whose
box mass has no closed form, :func:`jitter_resampled` redraws a point that
leaves the box from a fresh ancestor, which leaves one global normaliser, and
:func:`log_mixture_density_chol` gives the (untruncated) mixture density.
"""

from __future__ import annotations

import numpy as np

__all__ = ["jitter", "jitter_resampled", "log_kernel_mass", "log_mixture_density_chol"]


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


def jitter_resampled(centres: np.ndarray, chol: np.ndarray, bounds: np.ndarray,
                     rng: np.random.Generator, max_rounds: int = 10_000) -> np.ndarray:
    """Draw one point per resampled centre from ``N(c, L Lᵀ)``, kept inside the box.

    A point that leaves the box is redrawn from a *new* centre chosen uniformly among
    all ``centres`` (and fresh noise), until inside. Summed over particles, the draws'
    densities are then proportional to the untruncated mixture
    ``q(x) = (1/N) Σ_i N(x; c_i, L Lᵀ)`` on the box — the normaliser is one global
    constant, ``P_q(box)`` — so deterministic-mixture weights ``ϱ(x) / q(x)`` with
    :func:`log_mixture_density_chol` are exact after self-normalisation, for any
    kernel shape (a full covariance has no closed-form box mass per centre).

    Parameters
    ----------
    centres : (N, d) the resampled ancestors ``x[idx]`` (repeats allowed).
    chol : (d, d) lower Cholesky factor ``L`` of the kernel covariance.
    """
    n, d = centres.shape
    lo, hi = bounds[:, 0], bounds[:, 1]
    out = centres + rng.standard_normal((n, d)) @ chol.T
    bad = np.flatnonzero(~np.all((out >= lo) & (out <= hi), axis=1))
    for _ in range(max_rounds):
        if bad.size == 0:
            return out
        src = centres[rng.integers(n, size=bad.size)]
        out[bad] = src + rng.standard_normal((bad.size, d)) @ chol.T
        bad = bad[~np.all((out[bad] >= lo) & (out[bad] <= hi), axis=1)]
    return np.clip(out, lo, hi)  # pragma: no cover - a kernel far wider than the box


def log_mixture_density_chol(x: np.ndarray, centres: np.ndarray, log_w: np.ndarray,
                             chol: np.ndarray) -> np.ndarray:
    """``log Σ_u w_u N(x; c_u, L Lᵀ)`` (untruncated) for every row of ``x``: whitened by
    ``L⁻¹`` and evaluated by :func:`mrfpe.mixture.log_mixture_density` with unit scale."""
    from scipy.linalg import solve_triangular

    from mrfpe.mixture import log_mixture_density

    xw = solve_triangular(chol, x.T, lower=True).T
    cw = solve_triangular(chol, centres.T, lower=True).T
    return log_mixture_density(xw, cw, log_w, 1.0) - np.sum(np.log(np.diag(chol)))
