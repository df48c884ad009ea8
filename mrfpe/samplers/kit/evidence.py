"""The evidence an importance sampler reports: ``log_evidence`` relative to the box.

Convention (every built-in and the SMC plugin): ``log_evidence`` is

    log Z = log( ∫_box p(θ) dθ / vol(box) ) = log E_{θ ~ U(box)}[p(θ)],

the log normaliser of the target ``p = exp(target.log_prob)`` *relative to the
box*, i.e. the evidence under the uniform prior on the target's bounds (the
thesis's flat prior). In the unit cube it is the plain integral. From draws of a
normalised proposal ``q`` on the box, ``Ẑ_abs = mean(p/q)`` estimates ``∫ p``
(:func:`mrfpe.resampling.log_evidence`) and ``log Z = log Ẑ_abs − log vol(box)``.

A full-covariance jitter kernel (:func:`~mrfpe.samplers.kit.jitter_resampled`)
draws from the untruncated mixture ``q`` restricted to the box, whose density is
``q / M`` with ``M = P_q(box)``: then ``∫ p = M · E[p/q]``, and
:func:`log_mixture_box_mass` estimates ``M`` by Monte Carlo (draws only, no target
evaluation).
"""

from __future__ import annotations

import math

import numpy as np

from mrfpe.resampling import log_evidence

__all__ = ["MASS_DRAWS", "box_log_evidence", "log_box_volume", "log_mixture_box_mass"]

#: Draws of :func:`log_mixture_box_mass`: its SE is ``√((1 − M)/(M · n))``, < 0.003 for
#: M ≥ 0.5; no target evaluation is spent on them.
MASS_DRAWS = 100_000


def log_box_volume(bounds: np.ndarray) -> float:
    """``log vol(box)`` of (d, 2) bounds."""
    b = np.asarray(bounds, dtype=np.float64)
    return float(np.sum(np.log(b[:, 1] - b[:, 0])))


def log_mixture_box_mass(centres: np.ndarray, log_w: np.ndarray, chol: np.ndarray,
                         bounds: np.ndarray, rng: np.random.Generator,
                         n_draws: int = MASS_DRAWS) -> tuple[float, float]:
    """``(log M, se)``: Monte Carlo estimate of the box mass ``M`` of the untruncated
    mixture ``Σ_u w_u N(c_u, L Lᵀ)`` (``log_w`` normalised or not) and its delta-method SE.

    With no draw inside the box ``M`` is reported as ``1/(2 n)`` with SE ``inf``.
    """
    w = np.exp(log_w - np.max(log_w))
    comp = rng.choice(centres.shape[0], size=n_draws, p=w / w.sum())
    y = centres[comp] + rng.standard_normal((n_draws, centres.shape[1])) @ chol.T
    k = int(np.count_nonzero(np.all((y >= bounds[:, 0]) & (y <= bounds[:, 1]), axis=1)))
    if k == 0:
        return math.log(0.5 / n_draws), math.inf
    m = k / n_draws
    return math.log(m), math.sqrt((1.0 - m) / (m * n_draws))


def box_log_evidence(log_w: np.ndarray, bounds: np.ndarray, log_mass: float = 0.0,
                     log_mass_se: float = 0.0) -> tuple[float, float]:
    """``(log_evidence, log_evidence_se)`` relative to the box (module docstring).

    Parameters
    ----------
    log_w : (S,) ``log p(x) − log q(x)`` with ``q`` an absolute density on the
        sampling space (normalised on the box up to the factor ``M``).
    log_mass, log_mass_se : ``log M`` and its SE (0 for a proposal normalised on the
        box; :func:`log_mixture_box_mass` for the untruncated covariance mixture).
        The two SEs add in quadrature (independent estimates).
    """
    lz, se = log_evidence(log_w)
    return (lz + log_mass - log_box_volume(bounds),
            float(math.sqrt(se**2 + log_mass_se**2)))
