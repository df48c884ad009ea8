"""Random-walk Metropolis pieces shared by MCMC samplers: proposals in a box and the accept rule.

:func:`random_walk_proposal` draws ``theta' = theta + s L z`` (``z ~ N(0, I)``)
for every chain at once and says which proposals lie in the box;
:func:`evaluate_inside` evaluates the target at those only: proposals outside
the box are rejected without being evaluated (their density is zero; the thesis
does the same in 7.4). :func:`metropolis_accept` is the Metropolis rule (thesis
5.44, 5.45). :class:`AdaptiveRandomWalk` keeps ``s`` and ``L`` and tunes them
with ``adapt=True`` *during burn-in only* -- the scale by Robbins-Monro towards
``target_acceptance``, the shape to the chains' empirical covariance (Haario et
al. 2001) -- and then freezes them, so the post-burn-in chain is a plain
Metropolis chain.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.validation import check_bool, check_range

__all__ = ["AdaptiveRandomWalk", "evaluate_inside", "in_box", "metropolis_accept",
           "random_walk_proposal"]


def in_box(y: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(n,) bool: which rows of ``y`` (n, d) lie in the box ``bounds`` (d, 2), faces included."""
    return np.all((y >= bounds[:, 0]) & (y <= bounds[:, 1]), axis=1)


def random_walk_proposal(x: np.ndarray, spread: np.ndarray, bounds: np.ndarray,
                         rng: np.random.Generator, scale: float = 1.0,
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian random-walk proposals for every row of ``x`` (n, d), and which are in the box.

    ``theta' = theta + scale · L z`` with ``z ~ N(0, I)`` drawn from ``rng``; ``spread``
    is ``L``, a lower Cholesky factor (d, d), or one sd per parameter (d,) (``L``
    diagonal). Returns ``(proposals (n, d), inside (n,) bool)``: pass both to
    :func:`evaluate_inside`, which rejects the others without evaluating them.
    """
    z = rng.standard_normal(x.shape)
    spread = np.asarray(spread, dtype=np.float64)
    y = x + (scale * z @ spread.T if spread.ndim == 2 else scale * z * spread)
    return y, in_box(y, bounds)


def evaluate_inside(run: Any, target: Any, y: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Log density of each proposal (n,): ``run.evaluate(target, ·)`` (counted) on the rows
    ``inside`` the box, ``-inf`` without evaluation on the others (outside the box the
    density is zero)."""
    lp = np.full(y.shape[0], -np.inf)
    if inside.any():
        lp[inside] = run.evaluate(target, y[inside])
    return lp


def metropolis_accept(log_u: np.ndarray, lp_current: np.ndarray,
                      lp_proposed: np.ndarray) -> np.ndarray:
    """Accept mask of the Metropolis rule log u < log p(θ') − log p(θ_i) (5.44, 5.45).

    A chain whose current state has zero density (possible only before it has
    found the support) accepts every proposal, so it can walk into the support;
    a proposal of zero density is never accepted from a state inside it.
    ``lp_proposed - lp_current`` may be replaced by any log acceptance ratio
    (e.g. the exchange algorithm's) by passing ``lp_current = 0``.
    """
    stuck = ~np.isfinite(lp_current)
    with np.errstate(invalid="ignore"):
        ratio = np.where(stuck, np.inf, lp_proposed - np.where(stuck, 0.0, lp_current))
    return stuck | (log_u < ratio)


class AdaptiveRandomWalk:
    """Gaussian random-walk proposals in a box for ``n_chains`` chains (see module docstring).

    Parameters
    ----------
    bounds : (d, 2)
    n_chains : int
    proposal_sd : float
        Initial proposal sd as a fraction of each parameter's range.
    burn_in : int
        Steps during which the proposal adapts (if ``adapt``).
    adapt : bool
    target_acceptance : float
    spread : (d, d) lower Cholesky factor, optional
        The first proposal's shape (e.g. of a pseudolikelihood's inverse curvature),
        scaled by ``2.38 / sqrt(d)`` (the optimal Gaussian scale, Roberts, Gelman &
        Gilks 1997) instead of ``proposal_sd`` of each range.
    """

    def __init__(self, bounds: np.ndarray, n_chains: int, proposal_sd: float, burn_in: int,
                 adapt: bool = True, target_acceptance: float = 0.234,
                 spread: np.ndarray | None = None) -> None:
        self.bounds = bounds
        self.lo, self.hi = bounds[:, 0], bounds[:, 1]
        self.d = bounds.shape[0]
        self.burn_in, self.adapt, self.target_acceptance = burn_in, adapt, target_acceptance
        self.chol = np.diag(proposal_sd * (self.hi - self.lo))
        self.log_scale, self._shaped = 0.0, False
        if spread is not None:
            self.chol = np.asarray(spread, dtype=np.float64)
            self.log_scale, self._shaped = float(np.log(2.38 / np.sqrt(self.d))), True
        self._burn = np.empty((burn_in, n_chains, self.d)) if adapt else None

    @staticmethod
    def check_options(proposal_sd: float, adapt: bool, target_acceptance: float,
                      ) -> tuple[float, bool, float]:
        """Validate a sampler's random-walk options: ``proposal_sd`` > 0 (a fraction of each
        parameter's range), ``adapt`` a bool, ``target_acceptance`` in (0, 1)."""
        return (check_range("proposal_sd", proposal_sd, 0.0, np.inf, low_open=True,
                            high_open=True),
                check_bool("adapt", adapt),
                check_range("target_acceptance", target_acceptance, 0.0, 1.0, low_open=True,
                            high_open=True))

    @property
    def scale(self) -> float:
        return float(np.exp(self.log_scale))

    def propose(self, x: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``(proposals (c, d), inside (c,) bool)`` (:func:`random_walk_proposal`)."""
        return random_walk_proposal(x, self.chol, self.bounds, rng, self.scale)

    def update(self, t: int, x: np.ndarray, acceptance: float) -> None:
        """Adapt after step ``t`` (states ``x``, acceptance rate) -- during burn-in only."""
        if t >= self.burn_in or not self.adapt:
            return
        self._burn[t] = x
        self.log_scale += (acceptance - self.target_acceptance) / (t + 1) ** 0.6
        new = self._shape(self._burn[t // 2: t + 1], self.hi - self.lo) \
            if t >= 50 and t % 25 == 0 else None
        if new is not None:
            self.chol = new
            if not self._shaped:  # leaving the initial kernel: optimal Gaussian scale
                self.log_scale, self._shaped = np.log(2.38 / np.sqrt(self.d)), True

    @staticmethod
    def _shape(states: np.ndarray, width: np.ndarray) -> np.ndarray | None:
        """Cholesky factor of the burn-in states' covariance, or None if degenerate."""
        flat = states.reshape(-1, states.shape[-1])
        cov = np.atleast_2d(np.cov(flat, rowvar=False))
        floor = 1e-12 * width**2
        if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= floor):
            return None
        try:
            return np.linalg.cholesky(cov + np.diag(floor))
        except np.linalg.LinAlgError:
            return None
