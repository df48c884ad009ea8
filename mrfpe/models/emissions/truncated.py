"""Exact draws from truncated conjugate conditionals, and ordered (isotonic) modes.

The conditionally conjugate updates of the emissions draw each parameter from its
full conditional restricted to an interval: the interval of its prior (its bounds)
cut by its neighbours in the ordering ``mean_0 < mean_1 < ...`` that keeps labels from
switching. Each draw is by the inverse of the truncated distribution function,
computed in log space where a tail would lose every digit:

* :func:`truncated_normal`: ``N(m, 1/p)`` on ``(lo, hi)`` (``p = 0``: uniform), through
  ``log_ndtr`` and ``ndtri_exp`` on the side of the interval nearer the mean's far tail;
* :func:`truncated_gamma`: ``w^(a-1) exp(-b w)`` on ``(lo, hi)`` -- the gamma
  ``(a > 0, b > 0)`` through the regularised incomplete gamma functions, the power law
  ``(b = 0)`` in closed form and ``a = 0`` through the exponential integral ``E1``;
* :func:`truncated_inverse_gamma`: ``v^(-a-1) exp(-b / v)`` on ``(lo, hi)``, as ``1/w``.

:func:`ordered_mode` is the maximiser of a separable concave objective over the
ordered cone, ``sum_k (num_k log-like terms)`` whose per-block optimum is
``sum num / sum den`` (weighted least squares for normal means, gamma modes for
Poisson rates): the pool-adjacent-violators algorithm (Ayer et al. 1955; Barlow et
al. 1972, ch. 1).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import exp1, gammainc, gammaincc, gammainccinv, gammaincinv, log_ndtr, ndtri_exp

__all__ = ["ordered_mode", "truncated_gamma", "truncated_inverse_gamma", "truncated_normal"]


def truncated_normal(m: float, p: float, lo: float, hi: float, u: float) -> float:
    """Inverse-CDF draw (uniform ``u``) from ``N(m, 1/p)`` truncated to ``(lo, hi)``.

    ``p = 0`` (a flat prior and no observation) is the uniform distribution on the
    interval, which must then be bounded.
    """
    if not lo < hi:
        return lo
    if p <= 0.0:
        return lo + u * (hi - lo)
    s = 1.0 / math.sqrt(p)
    a, b = (lo - m) / s, (hi - m) / s
    flip = a > 0.0  # keep the interval on the left tail, where log_ndtr keeps its digits
    if flip:
        a, b, u = -b, -a, 1.0 - u
    la, lb = float(log_ndtr(a)), float(log_ndtr(b))
    if lb == -math.inf:  # the whole interval beyond any float's reach: its nearer end
        z = b
    else:
        # log(Phi(a) + u (Phi(b) - Phi(a))) = lb + log(u + (1 - u) exp(la - lb))
        lp = lb + math.log(u + (1.0 - u) * math.exp(la - lb)) if u > 0.0 else la
        z = float(ndtri_exp(lp)) if lp > -math.inf else a
    z = min(max(z, a), b)
    return m + s * (-z if flip else z)


def truncated_gamma(a: float, b: float, lo: float, hi: float, u: float) -> float:
    """Inverse-CDF draw from the density ``∝ w^(a-1) exp(-b w)`` on ``(lo, hi)``.

    ``a > 0, b > 0``: the gamma distribution (shape ``a``, rate ``b``); ``b = 0``: the
    power law (``a > 0``, or ``a = 0`` the log-uniform, ``a < 0`` with ``lo > 0``);
    ``a = 0, b > 0``: ``exp(-b w)/w``, whose distribution function is ``E1``. Where the
    interval holds too little mass for the incomplete gamma functions to resolve, the
    density's exponential approximation at the nearer end is drawn instead.
    """
    lo = max(lo, 0.0)
    if not lo < hi:
        return lo
    if b == 0.0:
        return _power_law(a, lo, hi, u)
    if a == 0.0:
        return _exp1_draw(b, max(lo, 1e-300), hi, u)
    if a < 0.0:
        raise ValueError(f"truncated_gamma needs shape a >= 0 when the rate b > 0; got a={a}")
    xl, xh = b * lo, b * hi
    if gammainc(a, xl) < 0.5:  # lower tail: P(a, x) keeps its digits
        pl, ph = gammainc(a, xl), gammainc(a, xh)
        if ph - pl > 1e-300 * max(ph, 1e-300) and ph > pl:
            return min(max(float(gammaincinv(a, pl + u * (ph - pl))) / b, lo), hi)
    else:  # upper tail: Q(a, x)
        ql, qh = gammaincc(a, xl), gammaincc(a, xh)
        if ql > qh:
            return min(max(float(gammainccinv(a, ql - u * (ql - qh))) / b, lo), hi)
    return _exponential_end(a, b, lo, hi, u)


def _power_law(a: float, lo: float, hi: float, u: float) -> float:
    """Draw from ``w^(a-1)`` on ``(lo, hi)`` (``lo > 0`` unless ``a > 0``): ``w^a`` is
    uniform between ``lo^a`` and ``hi^a`` (``a = 0``: ``log w`` is uniform)."""
    if a == 0.0:
        return math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
    return min(max((lo ** a + u * (hi ** a - lo ** a)) ** (1.0 / a), lo), hi)


def _exp1_draw(b: float, lo: float, hi: float, u: float) -> float:
    """Draw from ``exp(-b w) / w`` on ``(lo, hi)``: invert ``E1(b lo) - E1(b w)``."""
    e_lo, e_hi = float(exp1(b * lo)), float(exp1(b * hi))
    total = e_lo - e_hi
    if not total > 0.0:
        return lo + u * (hi - lo)
    f = lambda w: (e_lo - float(exp1(b * w))) - u * total  # noqa: E731 - increasing in w
    return float(brentq(f, lo, hi, xtol=1e-14 * hi, rtol=1e-12))


def _exponential_end(a: float, b: float, lo: float, hi: float, u: float) -> float:
    """The density's exponential approximation at the end of ``(lo, hi)`` nearer its mode,
    for intervals holding less mass than the incomplete gamma functions resolve."""
    mode = (a - 1.0) / b if a > 1.0 else 0.0
    end, sign = (lo, 1.0) if mode <= lo else (hi, -1.0)
    slope = sign * ((a - 1.0) / end - b)  # d log density / d distance from the end, < 0
    width = hi - lo
    if not slope < 0.0:
        return lo + u * width
    t = -math.log1p(-u * -math.expm1(slope * width)) / -slope
    return min(max(end + sign * t, lo), hi)


def truncated_inverse_gamma(a: float, b: float, lo: float, hi: float, u: float) -> float:
    """Draw from the density ``∝ v^(-a-1) exp(-b / v)`` on ``(lo, hi)``, ``lo > 0``:
    the inverse gamma (shape ``a``, scale ``b``) and its limits, as ``1 / w`` with ``w``
    from :func:`truncated_gamma` on ``(1/hi, 1/lo)``."""
    w = truncated_gamma(a, b, 1.0 / hi, 1.0 / lo if lo > 0 else math.inf, 1.0 - u)
    return min(max(1.0 / w, lo), hi)


def ordered_mode(num: np.ndarray, den: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Maximiser over ``v_0 <= v_1 <= ...`` of a separable concave objective whose
    optimum over a block of tied entries is ``sum num / sum den`` (pool adjacent
    violators).

    Entries with ``den <= 0`` carry no information: they take ``fallback``, clipped
    between their informative neighbours.
    """
    num, den = np.asarray(num, float), np.asarray(den, float)
    out = np.asarray(fallback, dtype=float).copy()
    idx = np.flatnonzero(den > 0)
    blocks: list[list[float]] = []  # [sum num, sum den, count]
    for k in idx:
        blocks.append([num[k], den[k], 1.0])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] > blocks[-1][0] / blocks[-1][1]:
            n2, d2, c2 = blocks.pop()
            blocks[-1][0] += n2
            blocks[-1][1] += d2
            blocks[-1][2] += c2
    if blocks:
        out[idx] = np.concatenate([np.full(int(c), n / d) for n, d, c in blocks])
    for k in np.flatnonzero(den <= 0):
        left, right = out[idx[idx < k]], out[idx[idx > k]]
        out[k] = min(max(out[k], left.max(initial=-np.inf)), right.min(initial=np.inf))
    return out
