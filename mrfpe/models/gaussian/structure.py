"""The auto-normal model compiled on one graph: its matrices, their spectra, PD region and draws.

:class:`CARStructure` holds the symmetric 0/1 adjacency matrices ``W_t``, one per
*coupling type* ``t`` (one type for the whole graph, or one per lattice direction /
edge type with ``directional=True``), and what is known of their joint spectrum.
With ``A(beta) = I - sum_t beta_t W_t`` the precision is ``Q = tau A(beta)``.

The field exists iff ``Q`` is positive definite (PD): ``tau > 0`` and
``1 - sum_t beta_t lambda_t(k) > 0`` for every joint eigenvalue ``lambda(k)`` of
the ``W_t``. Positive definiteness is decided before any estimator's value, from
the extreme points of the joint spectrum (``max_k beta . lambda(k) < 1`` over the
convex-hull vertices of the ``lambda(k)``; for one coupling type just ``lambda_min``
and ``lambda_max``, from closed forms, ``eigvalsh`` or ``eigsh``) -- a few dot
products per theta. Only where the joint spectrum is unknown *and* there are several
coupling types (typed general graphs with ``directional=True``, the directional
8-neighbourhood on a free lattice) is it a sparse ``LDL'`` per theta, which then
dominates the cost of ``"pl"``, ``"coding"`` and ``"block"``.

Log-determinants: ``log det Q = n log tau + sum_k log(1 - beta . lambda(k))`` from
the joint spectrum of the ``W_t`` where it is known, costing ``O(N n)`` per batch:

- free-boundary lattices with offsets among the 8-neighbourhood: path
  eigenvalues ``a_k = 2 cos(pi k / (H + 1))``, ``b_l = 2 cos(pi l / (W + 1))``;
  horizontal ``b_l``, vertical ``a_k``, the two diagonals together ``a_k b_l``
  (``P_H (x) P_W``) -- so one coupling, directional 4-neighbour couplings and the
  undirected 8-neighbourhood are closed-form, separate diagonal/antidiagonal
  couplings are not;
- periodic lattices (``H, W >= 3`` and no offset wrapping onto another): the
  2-D DFT diagonalises every offset, ``2 cos(2 pi (k dr / H + l dc / W))``;
- any graph with one coupling type and at most :data:`MAX_EIGEN_NODES` nodes:
  the eigenvalues of ``W`` once (dense ``eigvalsh``).

Otherwise (several coupling types on a general graph, the directional
8-neighbourhood on a free lattice, larger general graphs) ``log det`` is a
sparse LU factorisation per theta (``scipy.sparse.linalg.splu`` with
symmetric diagonal pivoting, i.e. an ``LDL'``; a non-positive pivot means Q is
not PD), up to :data:`MAX_SPARSE_NODES` nodes.

Simulation (:meth:`CARStructure.sample`; ``GaussianMRF.simulate``, ``method``): exact
draws ``x = mu + L^{-T} z`` with ``Q = L L'``:

* ``"fft"`` (periodic closed-form lattices): ``u = F^{-1} (F z / sqrt(q))``, ``q``
  the DFT eigenvalues of ``Q``: ``O(n log n)``;
* ``"dense"``: ``scipy.linalg.cholesky`` of the dense ``Q`` (auto up to
  :data:`MAX_DENSE_SIMULATION` nodes);
* ``"sparse"``: the sparse ``LDL'`` above, ``P A P' = L D L'``; with
  ``R = P' L D^{1/2}`` (``A = R R'``) a draw is ``u = A^{-1} R z / sqrt(tau)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mrfpe.models.graph import NEIGHBOURHOODS, Graph, LatticeSpec

__all__ = ["MAX_DENSE_NODES", "MAX_DENSE_SIMULATION", "MAX_EIGEN_NODES", "MAX_SPARSE_NODES",
           "PD_EPS", "CARStructure"]

#: Largest general graph whose adjacency spectrum is computed densely (once) for ``"exact"``.
MAX_EIGEN_NODES = 1500
#: Largest graph simulated by a dense Cholesky factor under ``method="auto"``.
MAX_DENSE_SIMULATION = 1024
#: Largest graph ``method="dense"`` accepts (an ``(n, n)`` matrix).
MAX_DENSE_NODES = 4096
#: Largest graph factorised by sparse LU (``"exact"`` without a known spectrum, simulation).
MAX_SPARSE_NODES = 1 << 18
#: ``1 - beta·lambda`` at or below this counts as singular (not positive definite).
PD_EPS = 1e-12


class CARStructure:
    """The auto-normal model's matrices ``W_t`` on one graph, and what is known of their spectra.

    Parameters
    ----------
    graph : Graph
    spec : LatticeSpec or None
        The lattice rule the graph was built from (enables closed-form spectra).
    directional : bool
        One coupling per edge type of ``graph`` (else one for all edges).
    """

    def __init__(self, graph: Graph, spec: LatticeSpec | None, directional: bool) -> None:
        self.graph = graph
        self.n = graph.n_nodes
        self.spec = spec
        self.directional = bool(directional) and graph.n_edge_types > 1
        if self.directional:
            self.W = [graph.adjacency(t).tocsr() for t in range(graph.n_edge_types)]
            self.type_names = graph.edge_type_names
            self.edge_coupling = np.asarray(graph.edge_type, dtype=np.int64)
        else:
            self.W = [graph.adjacency().tocsr()]
            self.type_names = ("edge",)
            self.edge_coupling = np.zeros(graph.n_edges, dtype=np.int64)
        self.T = len(self.W)
        self._grid = self._lattice_spectrum()  # (H, W, T) closed form, or None
        self._eig: np.ndarray | None = None
        self._eig_done = False
        self._unique: tuple[np.ndarray, np.ndarray] | None = None
        self._vertices: np.ndarray | None = None
        self._vertices_done = False
        self._intervals: np.ndarray | None = None

    # -- spectra ----------------------------------------------------------------------------------
    def _lattice_spectrum(self) -> np.ndarray | None:
        spec, g = self.spec, self.graph
        if spec is None or g.shape is None:
            return None
        H, W = g.shape
        offsets = list(spec.offsets)
        groups = [[o] for o in offsets] if self.directional else [offsets]
        if len(groups) != self.T:  # pragma: no cover - the graph was built from the spec
            return None
        out = np.zeros((H, W, self.T))
        if spec.periodic:
            # every offset must add H*W distinct edges (no self-loop, no wrap onto another)
            if g.n_edges != H * W * len(offsets):
                return None
            k = np.arange(H)[:, None] / H
            l = np.arange(W)[None, :] / W
            for t, group in enumerate(groups):
                for dr, dc in group:
                    out[:, :, t] += 2.0 * np.cos(2.0 * np.pi * (k * dr + l * dc))
            return out
        if not set(offsets) <= set(NEIGHBOURHOODS[8]):
            return None
        a = 2.0 * np.cos(np.pi * np.arange(1, H + 1) / (H + 1))[:, None]  # P_H (vertical)
        b = 2.0 * np.cos(np.pi * np.arange(1, W + 1) / (W + 1))[None, :]  # P_W (horizontal)
        for t, group in enumerate(groups):
            diag = {(1, 1), (1, -1)} & set(group)
            if len(diag) == 1:
                return None  # one diagonal alone is not diagonal in the sine basis
            if (0, 1) in group:
                out[:, :, t] += b
            if (1, 0) in group:
                out[:, :, t] += a
            if diag:
                out[:, :, t] += a * b  # diagonal + antidiagonal = P_H (x) P_W
        return out

    @property
    def fft_grid(self) -> np.ndarray | None:
        """``(H, W, T)`` eigenvalues of the ``W_t`` on the 2-D DFT grid (periodic lattices)."""
        if self._grid is not None and self.spec is not None and self.spec.periodic:
            return self._grid
        return None

    def has_spectrum(self) -> bool:
        """Whether the joint spectrum is known without factorising per theta."""
        return self._grid is not None or (self.T == 1 and self.n <= MAX_EIGEN_NODES)

    def eigenvalues(self) -> np.ndarray | None:
        """``(n, T)``: the joint eigenvalues ``lambda_t(k)`` of the ``W_t``, or None if unknown."""
        if not self._eig_done:
            if self._grid is not None:
                self._eig = self._grid.reshape(-1, self.T)
            elif self.T == 1 and self.n <= MAX_EIGEN_NODES:
                self._eig = np.linalg.eigvalsh(self.W[0].toarray())[:, None]
            self._eig_done = True
        return self._eig

    def _unique_eigenvalues(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self._unique is None:
            ev = self.eigenvalues()
            if ev is None:
                return None
            u, counts = np.unique(ev, axis=0, return_counts=True)
            self._unique = (u, counts.astype(np.float64))
        return self._unique

    def intervals(self) -> np.ndarray:
        """``(T, 2)``: ``(lambda_min(W_t), lambda_max(W_t))`` of each coupling type."""
        if self._intervals is None:
            if self._grid is not None:
                g = self._grid.reshape(-1, self.T)
                iv = np.stack([g.min(axis=0), g.max(axis=0)], axis=1)
            elif self._eig_done and self._eig is not None:
                iv = np.array([[self._eig.min(), self._eig.max()]])
            else:
                iv = np.array([_extreme_eigenvalues(w) for w in self.W])
            self._intervals = iv
        return self._intervals

    def vertices(self) -> np.ndarray | None:
        """Points ``lambda`` whose half-spaces ``beta·lambda < 1`` make up the PD region.

        The convex-hull vertices of the joint spectrum (or its extremes for one
        coupling type); None when the joint spectrum is unknown (then PD is
        decided by factorising).
        """
        if not self._vertices_done:
            if self.T == 1:
                iv = self.intervals()[0]
                self._vertices = np.array([[iv[0]], [iv[1]]])
            elif self._grid is not None:
                pts = np.unique(self._grid.reshape(-1, self.T), axis=0)
                self._vertices = _hull_points(pts)
            self._vertices_done = True
        return self._vertices

    def coupling_box(self) -> np.ndarray:
        """``(T, 2)`` default coupling bounds ``(1/lambda_min, 1/lambda_max)``.

        See :mod:`mrfpe.models.gaussian.bounds`.
        """
        out = np.empty((self.T, 2))
        for t, (lo, hi) in enumerate(self.intervals()):
            out[t] = (1.0 / lo, 1.0 / hi) if (lo < -1e-12 and hi > 1e-12) else (-1.0, 1.0)
        return out

    # -- matrices ---------------------------------------------------------------------------------
    def A(self, beta: Any) -> sp.csc_matrix:
        """``I - sum_t beta_t W_t`` (sparse) for one coupling vector."""
        beta = np.asarray(beta, dtype=np.float64).reshape(self.T)
        A = sp.identity(self.n, format="csr")
        for t in range(self.T):
            A = A - beta[t] * self.W[t]
        return A.tocsc()

    def needs_factorisation(self) -> bool:
        """Whether deciding PD needs a sparse factorisation per theta."""
        return self.vertices() is None

    def check_sparse_size(self, what: str) -> None:
        if self.n > MAX_SPARSE_NODES:
            raise ValueError(f"{what} on {self.n} nodes needs a sparse LU factorisation per "
                             f"parameter vector, limited to {MAX_SPARSE_NODES} nodes; use "
                             f"'pl', 'coding' or 'block' (or a graph whose spectrum is "
                             f"closed-form)")

    def pd_mask(self, beta: np.ndarray) -> np.ndarray:
        """``(N,)``: whether ``I - sum_t beta_t W_t`` is positive definite, per row of ``beta``."""
        beta = np.atleast_2d(beta)
        V = self.vertices()
        if V is not None:
            return (1.0 - (beta @ V.T).max(axis=1)) > PD_EPS
        return np.isfinite(self.logdet_A(beta, method="sparse"))

    def logdet_A(self, beta: np.ndarray, method: str = "auto") -> np.ndarray:
        """``(N,)`` ``log det (I - sum_t beta_t W_t)``; ``-inf`` where it is not PD."""
        beta = np.atleast_2d(np.asarray(beta, dtype=np.float64))
        uniq = self._unique_eigenvalues() if method in ("auto", "eigen") else None
        if uniq is not None:
            lam, w = uniq
            vals = 1.0 - beta @ lam.T  # (N, K)
            bad = vals.min(axis=1) <= PD_EPS
            with np.errstate(divide="ignore", invalid="ignore"):
                out = np.log(np.where(vals > PD_EPS, vals, 1.0)) @ w
            out[bad] = -np.inf
            return out
        out = np.empty(beta.shape[0])
        for i, b in enumerate(beta):
            f = _ldl(self.A(b))
            out[i] = -np.inf if f is None else float(np.log(f[1]).sum())
        return out

    # -- simulation -------------------------------------------------------------------------------
    def sample(self, beta: np.ndarray, tau: float, n_draws: int, rng: np.random.Generator,
               method: str, what: str) -> np.ndarray:
        """``(n_draws, n)`` exact draws of ``u ~ N(0, (tau A)^{-1})``.

        ``what`` names the parameters in the error raised when Q is not PD.
        """
        bad = ValueError(f"{what} is outside the positive-definite region: Q = precision * "
                         f"(I - sum_t coupling_t W_t) is not positive definite, so no "
                         f"Gaussian field has these parameters")
        if not tau > 0:
            raise bad
        if self.vertices() is not None and not self.pd_mask(beta[None])[0]:
            raise bad
        if method == "auto":
            method = ("fft" if self.fft_grid is not None else
                      "dense" if self.n <= MAX_DENSE_SIMULATION else "sparse")
        n = self.n
        if method == "fft":
            grid = self.fft_grid
            if grid is None:
                raise ValueError("method 'fft' needs a periodic lattice of at least 3 x 3 "
                                 "whose offsets do not wrap onto each other; use 'dense' or "
                                 "'sparse'")
            H, W = self.graph.shape
            q = tau * (1.0 - grid @ beta)  # (H, W) eigenvalues of Q
            z = rng.standard_normal((n_draws, H, W))
            u = np.fft.ifft2(np.fft.fft2(z, norm="ortho") / np.sqrt(q), norm="ortho").real
            return u.reshape(n_draws, n)
        if method == "dense":
            if n > MAX_DENSE_NODES:
                raise ValueError(f"method 'dense' builds an (n, n) matrix, limited to "
                                 f"{MAX_DENSE_NODES} nodes; got {n} (use 'sparse')")
            Q = tau * self.A(beta).toarray()
            try:
                L = sla.cholesky(Q, lower=True)
            except np.linalg.LinAlgError:
                raise bad from None
            z = rng.standard_normal((n, n_draws))
            return sla.solve_triangular(L, z, lower=True, trans="T").T
        self.check_sparse_size("sparse simulation")
        f = _ldl(self.A(beta))
        if f is None:
            raise bad
        lu, d = f
        z = rng.standard_normal((n, n_draws))
        Pr = sp.csc_matrix((np.ones(n), (lu.perm_r, np.arange(n))), shape=(n, n))
        Rz = Pr.T @ (lu.L @ (np.sqrt(d)[:, None] * z))
        return (lu.solve(np.asarray(Rz)) / math.sqrt(tau)).T

    def describe(self) -> dict:
        return {**self.graph.describe(), "coupling_types": list(self.type_names),
                "closed_form_spectrum": self._grid is not None}


def _extreme_eigenvalues(W: sp.csr_matrix) -> tuple[float, float]:
    """Smallest and largest eigenvalue of a symmetric sparse matrix (0, 0 if it is empty)."""
    if W.nnz == 0:
        return 0.0, 0.0
    n = W.shape[0]
    if n <= 500:
        ev = np.linalg.eigvalsh(W.toarray())
        return float(ev[0]), float(ev[-1])
    try:
        lo = spla.eigsh(W, k=1, which="SA", return_eigenvectors=False, tol=1e-12,
                        maxiter=20 * n)[0]
        hi = spla.eigsh(W, k=1, which="LA", return_eigenvectors=False, tol=1e-12,
                        maxiter=20 * n)[0]
        return float(lo), float(hi)
    except spla.ArpackNoConvergence:  # pragma: no cover - Gershgorin: a box around the region
        deg = float(np.abs(W).sum(axis=1).max())
        return -deg, deg


def _hull_points(pts: np.ndarray) -> np.ndarray:
    """The convex-hull vertices of ``pts`` (all points if the hull is degenerate)."""
    if pts.shape[0] <= pts.shape[1] + 1:
        return pts
    try:
        from scipy.spatial import ConvexHull

        return pts[ConvexHull(pts).vertices]
    except Exception:  # QhullError for a flat (lower-dimensional) spectrum
        return pts


def _ldl(A: sp.csc_matrix) -> tuple[Any, np.ndarray] | None:
    """``(SuperLU, pivots)`` of a symmetric matrix factorised with symmetric diagonal pivoting.

    ``P A P' = L D L'`` with ``D`` the pivots; None unless every pivot is > 0,
    i.e. unless ``A`` is positive definite (Sylvester's criterion on ``P A P'``).
    """
    try:
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None  # a zero diagonal pivot forced a row swap: not PD
    d = lu.U.diagonal()
    if not np.all(d > 0):
        return None
    return lu, d
