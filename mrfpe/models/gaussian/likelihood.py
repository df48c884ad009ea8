"""The auto-normal likelihoods: the exact one, and the unnormalised one with an exact simulator.

* ``"exact"`` -- ``sum_obs [1/2 log det Q - 1/2 (x - mu)' Q (x - mu) - n/2 log 2 pi]``.
  ``log det Q = n log tau + sum_k log(1 - beta . lambda(k))`` from the joint
  spectrum of the ``W_t`` where it is known (closed form on lattices, ``eigvalsh``
  once for one coupling type on a small graph), costing ``O(N n)`` per batch;
  otherwise a sparse ``LDL'`` per theta (:mod:`mrfpe.models.gaussian.structure`
  lists the cases).
* ``"likelihood"`` -- the unnormalised ``-1/2 sum_obs (x - mu)' Q (x - mu)`` with an
  exact simulator, for doubly-intractable samplers (as ``LikelihoodTarget``).

The quadratic form comes from second moments of the data's columns ``C``
computed once (:mod:`mrfpe.models.gaussian.base`), so it costs ``O(N P^2 T)`` per
batch whatever the graph's size.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp

from mrfpe.models.gaussian.base import LOG_2PI, GaussianTarget
from mrfpe.models.gaussian.data import as_fields
from mrfpe.models.gaussian.pseudolikelihood import GaussianPLTarget
from mrfpe.models.gaussian.structure import MAX_EIGEN_NODES
from mrfpe.targets.base import as_theta_batch
from mrfpe.validation import check_positive_int, check_seed

__all__ = ["GaussianExactTarget", "GaussianLikelihoodTarget"]


class _QuadraticForm:
    """``sum_obs u' A(beta) u = a' S0 a - sum_t beta_t a' S_t a`` from precomputed moments."""

    def __init__(self, C: np.ndarray, Ws: Sequence[sp.csr_matrix]) -> None:
        P = C.shape[2]
        self.S0 = np.einsum("mip,miq->pq", C, C)
        self.St = np.zeros((len(Ws), P, P))
        for t, W in enumerate(Ws):
            for Cm in C:
                WC = W @ Cm
                self.St[t] += 0.5 * (Cm.T @ WC + WC.T @ Cm)

    def __call__(self, a: np.ndarray, beta: np.ndarray) -> np.ndarray:
        q0 = np.einsum("np,pq,nq->n", a, self.S0, a)
        qt = np.einsum("np,tpq,nq->nt", a, self.St, a)
        return q0 - np.einsum("nt,nt->n", beta, qt)


class GaussianExactTarget(GaussianTarget):
    """The exact log-likelihood ``sum_obs log N(x; mu, Q^{-1})`` (see the module docstring).

    ``method``: ``"eigen"`` (the joint spectrum of the ``W_t``: closed form on
    lattices, ``eigvalsh`` once for one coupling on up to
    :data:`~mrfpe.models.gaussian.structure.MAX_EIGEN_NODES` nodes; ``O(N n)`` per
    batch), ``"sparse"`` (a sparse ``LDL'`` per theta, up to
    :data:`~mrfpe.models.gaussian.structure.MAX_SPARSE_NODES` nodes) or ``"auto"``
    (eigen where known).
    """

    calibrated = True

    def __init__(self, *, method: str = "auto", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        st = self.structure
        if method == "auto":
            method = "eigen" if st.has_spectrum() else "sparse"
        if method == "eigen" and not st.has_spectrum():
            raise ValueError(f"method 'eigen' needs the joint spectrum of the coupling matrices: "
                             f"a lattice with a closed form, or one coupling type on at most "
                             f"{MAX_EIGEN_NODES} nodes (this graph has {st.n} nodes, {st.T} "
                             f"coupling types); use method='sparse'")
        if method == "sparse":
            st.check_sparse_size("the exact likelihood")
        else:
            st.eigenvalues()
        self.method = method
        self._quad = _QuadraticForm(self._C, self.structure.W)
        self._extra["method"] = method

    def _row_bytes(self) -> float:
        uniq = self.structure._unique if self.method == "eigen" else None
        k = uniq[0].shape[0] if uniq is not None else self.structure.n
        return 8.0 * 3 * k if self.method == "eigen" else 0.0

    def log_det_precision(self, theta: Any) -> np.ndarray:
        """``log det Q(theta)`` (N,), ``-inf`` outside the PD region."""
        theta = as_theta_batch(theta, self.ndim)
        _, beta, tau, _ = self.split(theta)
        out = np.full(theta.shape[0], -np.inf)
        ok = tau > 0
        out[ok] = self.structure.n * np.log(tau[ok]) + self.structure.logdet_A(
            beta[ok], self.method)
        return out

    def log_partition(self, theta: Any) -> np.ndarray:
        """``log Z = n/2 log 2 pi - 1/2 log det Q`` (N,) of one observation."""
        return 0.5 * self.structure.n * LOG_2PI - 0.5 * self.log_det_precision(theta)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        _, beta, tau, _ = self.split(theta)
        M, n = self.x.shape
        logdet = n * np.log(tau) + self.structure.logdet_A(beta, self.method)
        quad = np.maximum(self._quad(self._a(theta), beta), 0.0)
        return M * 0.5 * (logdet - n * LOG_2PI) - 0.5 * tau * quad

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        if self.method == "sparse" and self.structure.vertices() is None:
            # the factorisation decides PD itself: do not factorise twice
            out = np.full(theta.shape[0], -np.inf)
            ok = self.split(theta)[2] > 0
            if ok.any():
                v = self._value(theta[ok])
                out[ok] = v
            return out
        return super()._log_prob(theta)


class GaussianLikelihoodTarget(GaussianTarget):
    """Unnormalised log-likelihood ``-1/2 sum_obs (x - mu)' Q (x - mu)`` with an exact simulator.

    ``log_prob`` omits ``M (1/2 log det Q - n/2 log 2 pi)``: it is *not* a density
    over theta on its own; doubly-intractable samplers (the exchange algorithm)
    use it with :meth:`simulate`. It is ``-inf`` outside the PD region.
    """

    calibrated = True

    #: Draws are exact (Cholesky / FFT): the exchange algorithm is then exact too.
    exact_simulator = True
    #: ``log_prob`` is not a density over theta (it omits the log-determinant term).
    normalised = False

    def __init__(self, *, sampler: str = "auto", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if sampler == "fft" and self.structure.fft_grid is None:
            raise ValueError("sampler 'fft' needs a periodic lattice of at least 3 x 3 whose "
                             "offsets do not wrap onto each other; use 'dense' or 'sparse'")
        self.sampler = sampler
        self._quad = _QuadraticForm(self._C, self.structure.W)
        self._extra["sampler"] = sampler

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``-1/2 sum (x - mu)' Q (x - mu)`` (N,) for fields ``x`` (default the data)."""
        theta = as_theta_batch(theta, self.ndim)
        q = self._quad if x is None else _QuadraticForm(
            self.columns(as_fields(x, self.structure.n)), self.structure.W)
        _, beta, tau, _ = self.split(theta)
        return -0.5 * tau * q(self._a(theta), beta)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        _, beta, tau, _ = self.split(theta)
        return -0.5 * tau * self._quad(self._a(theta), beta)

    def pseudolikelihood(self) -> GaussianPLTarget:
        """Besag's pseudolikelihood on the same data, covariates and bounds (``"pl"``): where
        the exchange sampler starts its chains."""
        return GaussianPLTarget(model=self.model, structure=self.structure, x=self.x, Z=self.Z,
                                bounds=self.bounds, estimator="pl")

    def log_f_of_draws(self, y: Any) -> Any:
        """``theta (N, d) -> log f(y_k | theta)`` (N, K) for fields ``y`` (K, n): the draws'
        second moments once (``O(K n P^2 T)``), then ``O(N K P^2 T)`` per call."""
        C = self.columns(as_fields(y, self.structure.n))
        S0 = np.einsum("kip,kiq->kpq", C, C)
        St = np.zeros((len(self.structure.W), *S0.shape))
        for t, W in enumerate(self.structure.W):
            WC = np.stack([W @ Ck for Ck in C])
            St[t] = 0.5 * (np.einsum("kip,kiq->kpq", C, WC) + np.einsum("kip,kiq->kpq", WC, C))

        def log_f(theta: Any) -> np.ndarray:
            theta = as_theta_batch(theta, self.ndim)
            a, (_, beta, tau, _) = self._a(theta), self.split(theta)
            q = np.einsum("np,kpq,nq->nk", a, S0, a)
            q -= np.einsum("nt,np,tkpq,nq->nk", beta, a, St, a)
            return -0.5 * tau[:, None] * q
        return log_f

    def simulate(self, theta: Any, n: int | None = None, *, seed: int | None = None
                 ) -> np.ndarray:
        """``n`` fields (default as many as observed) at ``theta``: ``(n, n_nodes)``."""
        th = as_theta_batch(theta, self.ndim)
        if th.shape[0] != 1:
            raise ValueError(f"theta must be one parameter vector; got {th.shape[0]}")
        n = self.n_observations if n is None else check_positive_int("n", n)
        rng = np.random.default_rng(check_seed(seed))
        m, beta, tau, g = self.split(th)
        if not np.all(np.isfinite(th)):
            raise ValueError(f"theta must be finite; got {th[0].tolist()}")
        u = self.structure.sample(beta[0], float(tau[0]), n, rng, self.sampler,
                                  f"theta {th[0].tolist()}")
        return m[0] + self.Z @ g[0] + u
