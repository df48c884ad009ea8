"""Log density of a Gaussian mixture with diagonal kernels: a leaf numeric module.

PMC needs the density of its jittered resampling mixture at every new particle
(Cappé et al. 2004's deterministic-mixture weights), and AGMMP (8.3–8.5) the
density of one weighted set's kernel estimate at another's points.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

__all__ = ["log_mixture_density"]


def log_mixture_density(x: np.ndarray, centres: np.ndarray, log_w: np.ndarray,
                        sigma: float | np.ndarray, chunk: int = 2_000_000) -> np.ndarray:
    """``log Σ_u w_u N(x; c_u, diag(σ²))`` for every row of ``x`` (N, d).

    ``sigma`` is a scalar or one scale per parameter; ``log_w`` (U,) are log
    mixture weights. Rows are processed in chunks so that at most ``chunk``
    (row, component) pairs are held at once.
    """
    d = x.shape[1]
    sig = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (d,))
    xs, cs = x / sig, centres / sig  # whiten: the kernel becomes spherical with unit scale
    out = np.empty(x.shape[0])
    rows = max(1, chunk // max(1, centres.shape[0]))
    norm = -0.5 * d * np.log(2.0 * np.pi) - np.sum(np.log(sig))
    for s in range(0, x.shape[0], rows):
        diff = xs[s:s + rows, None, :] - cs[None, :, :]
        out[s:s + rows] = logsumexp(log_w - 0.5 * np.einsum("nud,nud->nu", diff, diff), axis=1)
    return out + norm
