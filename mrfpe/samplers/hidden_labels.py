"""The label posterior of the ``hidden`` sampler: Rao-Blackwellised probabilities, their error.

Each post-burn-in Gibbs sweep adds every node's full conditional ``p(x_i | x_N_i, y_i,
θ)`` (the probabilities it draws from) to its chain's running sum; their average over the
sweeps estimates the posterior marginal ``p(x_i | y)`` with less variance than counting
the drawn labels (the Rao-Blackwell theorem; Gelfand & Smith 1990, Sec. 2.5). The
sweeps are cut into ``n_batches`` batches of equal length per chain, and the Monte Carlo
standard error of every probability is the batch-means estimate ``sd(batch means) /
sqrt(number of batches)`` over all chains' batches (Flegal & Jones 2010), pooled, so
that chains that disagree widen it. Batch means are near independent only when a
batch is much longer than the labels' autocorrelation time: with few, short batches
the error is underestimated.

:class:`LabelRecord` also counts how often each state is empty (no node in it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["LabelRecord", "param_diagnostics"]


class LabelRecord:
    """Batched sums of the chains' conditional label probabilities (see the module docstring).

    Parameters
    ----------
    n_chains, n_nodes, n_states : sizes
    n_steps, burn_in : the run's length; the last ``n_batches * L`` steps are recorded,
        ``L = (n_steps - burn_in) // n_batches`` (a few more count as burn-in)
    n_batches : batches per chain
    """

    def __init__(self, n_chains: int, n_nodes: int, n_states: int, n_steps: int, burn_in: int,
                 n_batches: int) -> None:
        post = n_steps - burn_in
        self.n_batches = max(1, min(n_batches, post))
        self.length = post // self.n_batches
        self.first = n_steps - self.n_batches * self.length  # first recorded step
        self.acc = np.zeros((n_chains, n_nodes, n_states))
        self.sum = np.zeros((n_nodes, n_states))
        self.sumsq = np.zeros((n_nodes, n_states))
        self.n_means = 0
        self.occupancy = np.zeros(n_states)
        self.empty = np.zeros(n_states)
        self.n_sweeps = 0

    def buffer(self, t: int) -> np.ndarray | None:
        """Where step ``t``'s Gibbs sweeps add their probabilities (None before recording)."""
        return self.acc if t >= self.first else None

    def close(self, t: int, labels: np.ndarray) -> None:
        """After step ``t``: count the states of ``labels`` (C, n); close a batch at its end."""
        if t < self.first:
            return
        q = self.occupancy.size
        for x in labels:
            counts = np.bincount(x, minlength=q)
            self.occupancy += counts / x.size
            self.empty += counts == 0
        self.n_sweeps += labels.shape[0]
        if (t - self.first + 1) % self.length == 0:
            means = self.acc / self.length
            self.sum += means.sum(axis=0)
            self.sumsq += (means ** 2).sum(axis=0)
            self.n_means += means.shape[0]
            self.acc[:] = 0.0

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(probabilities (n, q), their Monte Carlo standard errors (n, q), mean share of
        the nodes in each state (q,), fraction of sweeps each state was empty (q,))``."""
        m = max(self.n_means, 1)
        prob = self.sum / m
        if self.n_means >= 2:
            var = np.maximum(self.sumsq - m * prob ** 2, 0.0) / (m - 1)
            mcse = np.sqrt(var / m)
        else:
            mcse = np.full_like(prob, np.nan)
        s = max(self.n_sweeps, 1)
        return prob, mcse, self.occupancy / s, self.empty / s


def param_diagnostics(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per parameter: ArviZ's rank-normalised split R̂ (NaN for one chain) and the smaller
    of its bulk and tail ESS (Vehtari et al. 2021), of draws ``theta`` (draw, chain, d)."""
    import warnings

    from mrfpe._arviz import arviz

    az = arviz()
    x = np.transpose(theta, (1, 0, 2))  # (chain, draw, param)
    d = x.shape[2]
    rhat, ess = np.full(d, np.nan), np.zeros(d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for j in range(d):
            if x.shape[0] >= 2:
                rhat[j] = float(az.rhat(x[:, :, j]))
            e = min(float(az.ess(x[:, :, j], method="bulk")),
                    float(az.ess(x[:, :, j], method="tail")))
            ess[j] = e if np.isfinite(e) else 0.0
    return rhat, ess
