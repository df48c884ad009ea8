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

__all__ = ["COV_ESS", "KERNEL_SCALE", "covariance_kernel", "jitter", "jitter_mixture",
           "jitter_resampled", "log_kernel_mass", "log_mixture_density_chol",
           "log_resampling_mixture", "resampling_components"]


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


def log_resampling_mixture(x_new: np.ndarray, source: np.ndarray, idx: np.ndarray,
                           sigma: float | np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Log density at ``x_new`` of the mixture :func:`jitter` drew it from.

    ``x_new = jitter(source[idx], sigma, bounds, rng)``: each row comes from the
    box-truncated Gaussian around ``source[idx[i]]``, so summed over rows the
    draws follow ``q(x) = (1/N) Σ_i N_box(x; source[idx_i], σ²)`` — the density
    that deterministic-mixture weights ``ϱ(x)/q(x)`` divide by (Cappé et al. 2004).
    """
    from mrfpe.mixture import log_mixture_density

    centres, log_share = resampling_components(source, idx)
    log_w = log_share - log_kernel_mass(centres, sigma, bounds)
    return log_mixture_density(x_new, centres, log_w, sigma)


def resampling_components(source: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The components of the mixture a jittered resample ``source[idx]`` is drawn from:
    the distinct ancestors ``(U, d)`` and their log shares ``log(count / N)`` (U,)."""
    anc, counts = np.unique(idx, return_counts=True)
    return source[anc], np.log(counts / idx.size)


#: :func:`covariance_kernel` defaults: scale on Silverman's factor, and the ESS fraction
#: the weights are flattened to before estimating the cloud's covariance. Measured on
#: 3-D and 10-D (AR(1) ρ = 0.7) Gaussians (benchmarks/bench_accuracy.py): scale 1 on
#: the raw weights collapses in 10-D (PMC sd ratio 0.06–0.6); 1.5 with 0.1 gives
#: 0.91–1.03 and a final ESS ~300 of 1000.
KERNEL_SCALE = 1.5
COV_ESS = 0.1


def covariance_kernel(x: np.ndarray, log_w: np.ndarray, scale: float = KERNEL_SCALE,
                      min_ess: float = COV_ESS) -> np.ndarray:
    """Lower Cholesky factor of a Gaussian kernel shaped like the weighted cloud.

    ``(scale · h)² Ĉ`` with ``h = (4/((d+2) N))^{1/(d+4)}`` (Silverman's factor) and
    ``Ĉ`` the weighted covariance of ``x`` under the weights flattened to
    ``w^λ`` (largest λ = 0.7^k ≤ 1) whose Kish ESS is at least ``min_ess · N``, so
    a cloud whose weights collapse onto a few particles keeps a kernel as wide as
    the cloud instead of shrinking with it.
    """
    from mrfpe.resampling import ess, normalise_log_weights

    lw = np.where(np.isfinite(log_w), log_w, -np.inf)
    lam = 1.0
    if np.isfinite(lw).sum() > 1:
        for _ in range(30):
            if ess(lam * lw) >= min_ess * lw.size:
                break
            lam *= 0.7
    w = np.exp(normalise_log_weights(lam * lw))
    dev = x - w @ x
    cov = (dev * w[:, None]).T @ dev
    n, d = x.shape
    h = scale * (4.0 / ((d + 2) * n)) ** (1.0 / (d + 4))
    ridge = 1e-12 * np.ones(d) + 1e-9 * np.trace(cov) / d  # a collapsed cloud stays PD
    return np.linalg.cholesky(h**2 * cov + np.diag(ridge))


def jitter_mixture(x: np.ndarray, idx: np.ndarray, chol: np.ndarray, bounds: np.ndarray,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Jitter the resampled ``x[idx]`` by ``N(0, L Lᵀ)`` inside the box
    (:func:`jitter_resampled`) and return ``(x_new, log q(x_new))`` with ``q`` the
    mixture the draws follow (up to one global constant): what deterministic-mixture
    weights ``ϱ / q`` need."""
    x_new = jitter_resampled(x[idx], chol, bounds, rng)
    return x_new, log_mixture_density_chol(x_new, *resampling_components(x, idx), chol)
