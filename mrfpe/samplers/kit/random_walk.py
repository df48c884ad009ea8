"""Random-walk Metropolis pieces shared by MCMC samplers: the proposal and the accept rule.

:class:`AdaptiveRandomWalk` proposes ``theta' = theta + s L z`` (``z ~ N(0, I)``)
for every chain at once and says which proposals lie in the box; proposals
outside it are rejected without being evaluated (their density is zero; the
thesis does the same in 7.4). With ``adapt=True`` it is tuned *during burn-in
only* -- the scale by Robbins-Monro towards ``target_acceptance``, the shape to
the chains' empirical covariance (Haario et al. 2001) -- and then frozen, so
the post-burn-in chain is a plain Metropolis chain.
:func:`metropolis_accept` is the Metropolis rule (thesis 5.44, 5.45).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AdaptiveRandomWalk", "metropolis_accept"]


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
    """

    def __init__(self, bounds: np.ndarray, n_chains: int, proposal_sd: float, burn_in: int,
                 adapt: bool = True, target_acceptance: float = 0.234) -> None:
        self.lo, self.hi = bounds[:, 0], bounds[:, 1]
        self.d = bounds.shape[0]
        self.burn_in, self.adapt, self.target_acceptance = burn_in, adapt, target_acceptance
        self.chol = np.diag(proposal_sd * (self.hi - self.lo))
        self.log_scale, self._shaped = 0.0, False
        self._burn = np.empty((burn_in, n_chains, self.d)) if adapt else None

    @property
    def scale(self) -> float:
        return float(np.exp(self.log_scale))

    def propose(self, x: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``(proposals (c, d), inside (c,) bool)``."""
        y = x + self.scale * rng.standard_normal(x.shape) @ self.chol.T
        return y, np.all((y >= self.lo) & (y <= self.hi), axis=1)

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
