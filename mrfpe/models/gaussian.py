"""Gaussian MRFs: Besag's auto-normal (conditional autoregressive, CAR) model.

The model (Besag 1974, Sec. 5; Rue & Held 2005, ch. 2) on a graph with
symmetric 0/1 adjacency matrices ``W_t``, one per *coupling type* ``t`` (one
type for the whole graph, or one per lattice direction / edge type with
``directional=True``)::

    x ~ N(mu, Q^{-1}),    Q = tau (I - sum_t beta_t W_t),
    x_i | x_-i ~ N(mu_i + sum_t beta_t sum_{j ~_t i} (x_j - mu_j), 1 / tau),
    mu_i = m + z_i . gamma   (m alone without covariates).

``theta = (mean, coupling | coupling_<type>..., precision, <covariate coefficients>...)``.
The field exists iff ``Q`` is positive definite (PD): ``tau > 0`` and
``1 - sum_t beta_t lambda_t(k) > 0`` for every joint eigenvalue ``lambda(k)`` of
the ``W_t``. Every estimator's ``log_prob`` is ``-inf`` outside that region (and
outside the bounds), never NaN.

Estimators (``GaussianMRF.target(estimator, data, ...)``), all batched over
theta ``(N, d)``:

* ``"pl"`` -- Besag's pseudolikelihood ``sum_i log N(x_i; E[x_i | x_-i], 1/tau)``.
  With ``u = x - mu`` the conditional residual is ``e = (I - sum_t beta_t W_t) u``,
  which is linear in the vector ``b(theta) = (a, -beta_1 a, ..., -beta_T a)`` where
  ``u = C a``, ``C = [x - x0, 1, Z - z0]``. So ``sum_i e_i^2 = b' S b`` with ``S =
  G'G``, ``G = [C, W_1 C, ..., W_T C]`` precomputed once (neighbour sums per
  coupling type): a batch costs ``O(N P^2)``, independent of the lattice size.
* ``"coding"`` -- the same over one colour class of the graph's proper
  colouring (Besag 1974, Sec. 6.1); the codings sum to the PL.
* ``"block"`` -- ``sum_B log N(x_B; mu_B - Q_BB^{-1} Q_B,rest (x_rest - mu_rest), Q_BB^{-1})``
  over tiles ``(bh, bw)`` (lattice) or a node partition (graph). The residual of
  block ``B`` is ``x_B - E[x_B | rest] = A_BB^{-1} e_B`` (``A = I - sum beta_t W_t``),
  so each block adds ``m/2 log tau + 1/2 log det A_BB - tau/2 e_B' A_BB^{-1} e_B``.
  Blocks with the same internal structure (all interior tiles) share one
  ``m x m`` factorisation per theta, and their second moments are summed once.
* ``"exact"`` -- ``sum_obs [1/2 log det Q - 1/2 (x - mu)' Q (x - mu) - n/2 log 2 pi]``.
  ``log det Q = n log tau + sum_k log(1 - beta . lambda(k))`` from the joint
  spectrum of the ``W_t`` where it is known, costing ``O(N n)`` per batch:

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
* ``"likelihood"`` -- the unnormalised ``-1/2 sum_obs (x - mu)' Q (x - mu)`` with an
  exact simulator, for doubly-intractable samplers (as ``LikelihoodTarget``).

Positive definiteness is decided before any estimator's value, from the extreme
points of the joint spectrum (``max_k beta . lambda(k) < 1`` over the convex-hull
vertices of the ``lambda(k)``; for one coupling type just ``lambda_min`` and
``lambda_max``, from closed forms, ``eigvalsh`` or ``eigsh``) -- a few dot products
per theta. Only where the joint spectrum is unknown *and* there are several
coupling types (typed general graphs with ``directional=True``, the directional
8-neighbourhood on a free lattice) is it a sparse ``LDL'`` per theta, which then
dominates the cost of ``"pl"``, ``"coding"`` and ``"block"``.

Default bounds (``GaussianMRF.default_bounds``; ``bounds=`` overrides any of them):

* ``coupling_t``: ``(1 / lambda_min(W_t), 1 / lambda_max(W_t))``, the exact
  interval in which ``Q`` is PD when the other couplings are 0 (for one
  coupling type: exactly the PD interval). On a periodic 4-neighbour lattice of
  even size that is ``(-1/4, 1/4)``; on a free ``H x W`` one it is a little wider,
  ``1 / (2 cos(pi/(H+1)) + 2 cos(pi/(W+1)))``. With several coupling types the
  box spans the PD region's axis intercepts: on the closed-form lattices that is
  exactly the region's bounding box (``log_prob`` is ``-inf`` in the box's corners
  outside the region); on a typed general graph the region may reach beyond the
  box where one coupling compensates another (widen it with ``bounds=``). A coupling type
  with no edges gets ``(-1, 1)``.
* ``precision``: ``(0, 1e4 / v)``, ``v`` the residual variance of the data
  regressed on ``[1, Z]`` (``tau`` is the inverse *conditional* variance, which
  can be far above ``1 / v`` for strongly coupled fields, hence the wide cap).
* covariate coefficient ``k``: ``+-10 s / s_k`` (``s``, ``s_k`` the ranges of
  the data and of covariate ``k``).
* ``mean``: ``[min x - s - c, max x + s + c]`` with ``c = sum_k 10 s / s_k max |z_k|``,
  the largest shift the covariate box allows.

Simulation (``GaussianMRF.simulate``, ``method``): exact draws ``x = mu + L^{-T} z``
with ``Q = L L'``:

* ``"fft"`` (periodic closed-form lattices): ``u = F^{-1} (F z / sqrt(q))``, ``q``
  the DFT eigenvalues of ``Q``: ``O(n log n)``;
* ``"dense"``: ``scipy.linalg.cholesky`` of the dense ``Q`` (auto up to
  :data:`MAX_DENSE_SIMULATION` nodes);
* ``"sparse"``: the sparse ``LDL'`` above, ``P A P' = L D L'``; with
  ``R = P' L D^{1/2}`` (``A = R R'``) a draw is ``u = A^{-1} R z / sqrt(tau)``.

References: J. Besag (1974), Spatial interaction and the statistical analysis of
lattice systems, JRSS B 36; H. Rue and L. Held (2005), Gaussian Markov Random
Fields, Chapman & Hall, ch. 2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mrfpe.models.base import Model
from mrfpe.models.discrete import ESTIMATOR_OPTIONS as DISCRETE_OPTIONS
from mrfpe.models.graph import NEIGHBOURHOODS, Graph, LatticeSpec, as_graph_spec
from mrfpe.models.options import COMMON_OPTIONS, block_option, jsonable, node_blocks, nonneg_int
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.options import Option, choice_check
from mrfpe.validation import check_bool, check_choice, check_positive_int, check_seed

__all__ = ["MAX_BLOCK_NODES", "MAX_DENSE_NODES", "MAX_DENSE_SIMULATION", "MAX_EIGEN_NODES",
           "MAX_SPARSE_NODES", "CARStructure", "GaussianBlockTarget", "GaussianExactTarget",
           "GaussianLikelihoodTarget", "GaussianMRF", "GaussianPLTarget", "GaussianTarget",
           "autonormal"]

#: Largest general graph whose adjacency spectrum is computed densely (once) for ``"exact"``.
MAX_EIGEN_NODES = 1500
#: Largest graph simulated by a dense Cholesky factor under ``method="auto"``.
MAX_DENSE_SIMULATION = 1024
#: Largest graph ``method="dense"`` accepts (an ``(n, n)`` matrix).
MAX_DENSE_NODES = 4096
#: Largest graph factorised by sparse LU (``"exact"`` without a known spectrum, simulation).
MAX_SPARSE_NODES = 1 << 18
#: Largest block of the block pseudolikelihood (a dense ``m x m`` factorisation per theta).
MAX_BLOCK_NODES = 400
#: ``1 - beta . lambda`` at or below this counts as singular (not positive definite).
PD_EPS = 1e-12

_LOG_2PI = math.log(2.0 * math.pi)
_RESERVED = ("mean", "precision", "coupling")


# ------------------------------------------------------------------------------------------------
# the model compiled on one graph
# ------------------------------------------------------------------------------------------------
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
        """Points ``lambda`` whose half-spaces ``beta . lambda < 1`` make up the PD region.

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
        """``(T, 2)`` default coupling bounds ``(1/lambda_min, 1/lambda_max)`` (see the module)."""
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


# ------------------------------------------------------------------------------------------------
# options
# ------------------------------------------------------------------------------------------------
COMMON = COMMON_OPTIONS

ESTIMATOR_OPTIONS: dict[str, tuple[Option, ...]] = {
    "pl": COMMON,
    "coding": (*COMMON, Option("coding", "int >= 0", 0, nonneg_int,
                               "which colour class (Besag coding) 0 .. n_codings - 1")),
    "block": (*COMMON, Option("block", "(bh, bw) | int | labels | list of arrays | None", None,
                              block_option,
                              "tiles (bh, bw) anchored at the top-left corner on a lattice; a "
                              "node partition on a general graph (blocks of <= "
                              f"{MAX_BLOCK_NODES} nodes); default (2, 2) tiles on a lattice, "
                              "runs of 4 node ids on a graph")),
    "exact": (*COMMON, Option("method", "'auto' | 'eigen' | 'sparse'", "auto",
                              choice_check("auto", "eigen", "sparse"),
                              "log det Q from the known spectrum or a sparse LU per theta")),
    "likelihood": (*COMMON, Option("sampler", "'auto' | 'fft' | 'dense' | 'sparse'", "auto",
                                   choice_check("auto", "fft", "dense", "sparse"),
                                   "the exact simulator used for auxiliary draws")),
    "pl_adjusted": (*COMMON, *DISCRETE_OPTIONS["pl_adjusted"][len(DISCRETE_OPTIONS["pl"]):]),
}


# ------------------------------------------------------------------------------------------------
# the model
# ------------------------------------------------------------------------------------------------
class GaussianMRF(Model):
    """Besag's auto-normal (CAR) model on a lattice or a graph (see the module docstring).

    Parameters
    ----------
    graph : lattice(...), Graph, 4, 8, adjacency matrix or networkx graph
    directional : bool
        One coupling per lattice direction (or per edge type of a graph):
        ``coupling_horizontal``, ``coupling_vertical``, ... A ``lattice(...)`` rule
        that is itself directional (or periodic) stays so.
    periodic : bool
        Torus boundary (lattices only; a ValueError for a fixed graph).
    covariates : int >= 0 or sequence of str
        Number of anonymous node covariates (parameters ``z`` for one, ``z_0``,
        ``z_1``, ... for several; passed as an array ``(H, W[, k])``) or their
        names (each passed as ``{name: (H, W)}``, or stacked in that order).
    bounds : (d, 2) array or mapping name -> (low, high), optional
        Overrides of the data-driven default bounds.
    name : str
    """

    estimators = ("pl", "coding", "block", "exact", "likelihood", "pl_adjusted")
    estimator_options = ESTIMATOR_OPTIONS

    def __init__(self, graph: Any = 4, *, directional: bool = False, periodic: bool = False,
                 covariates: int | Sequence[str] = 0, bounds: Any = None,
                 name: str = "autonormal") -> None:
        check_bool("directional", directional)
        check_bool("periodic", periodic)
        spec = as_graph_spec(graph)
        if isinstance(spec, LatticeSpec):
            spec = replace(spec, periodic=bool(spec.periodic or periodic),
                           directional=bool(spec.directional or directional))
            self.directional = spec.directional
        else:
            if periodic:
                raise ValueError("periodic applies to lattices; the graph given is fixed (build "
                                 "a periodic lattice with lattice(..., periodic=True))")
            self.directional = bool(directional)
        self.graph_spec: Graph | LatticeSpec = spec
        if isinstance(covariates, bool) or not (
                isinstance(covariates, int | np.integer | Sequence)):
            raise ValueError(f"covariates must be a number of covariates or a sequence of "
                             f"names; got {covariates!r}")
        if isinstance(covariates, int | np.integer):
            k = check_positive_int("covariates", covariates, minimum=0)
            self.covariate_names: tuple[str, ...] = ("z",) if k == 1 else tuple(
                f"z_{j}" for j in range(k))
            self._anonymous = True
        else:
            names = (covariates,) if isinstance(covariates, str) else tuple(covariates)
            if not all(isinstance(c, str) and c for c in names) or len(set(names)) != len(names):
                raise ValueError(f"covariates must be distinct non-empty names; got "
                                 f"{covariates!r}")
            self.covariate_names = names
            self._anonymous = False
        clash = [c for c in self.covariate_names
                 if c in _RESERVED or c.startswith("coupling_")]
        if clash:
            raise ValueError(f"covariates must not be named {', '.join(map(repr, clash))} (a "
                             f"parameter of the model)")
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty string; got {name!r}")
        self.name = name
        self._structures: dict[Any, CARStructure] = {}
        self._bounds = None if bounds is None else self._bounds_override(bounds, "bounds")

    # -- structure -------------------------------------------------------------------------------
    @property
    def n_covariates(self) -> int:
        return len(self.covariate_names)

    @property
    def coupling_type_names(self) -> tuple[str, ...]:
        names = self.graph_spec.edge_type_names
        return names if self.directional and len(names) > 1 else ("edge",)

    def graph(self, shape: Any = None) -> Graph:
        """The graph for data of ``shape`` (a lattice's ``(H, W)``; ignored for a fixed graph)."""
        return self.structure(shape).graph

    def structure(self, shape: Any = None) -> CARStructure:
        """The compiled :class:`CARStructure` on the graph of ``shape`` (cached)."""
        if isinstance(self.graph_spec, LatticeSpec):
            if shape is None:
                raise ValueError("shape must be given: the model is declared on a lattice")
            g = self.graph_spec.build(shape)
            key = g.shape
        else:
            g, key = self.graph_spec, None
        if key not in self._structures:
            if len(self._structures) >= 8:
                self._structures.pop(next(iter(self._structures)))
            spec = self.graph_spec if isinstance(self.graph_spec, LatticeSpec) else None
            self._structures[key] = CARStructure(g, spec, self.directional)
        return self._structures[key]

    def node_shape(self, shape: Any = None) -> tuple[int, ...]:
        """Shape of one field: ``(H, W)`` on a lattice, ``(n_nodes,)`` otherwise."""
        g = self.graph(shape)
        return g.shape if g.shape is not None else (g.n_nodes,)

    def n_codings(self, shape: Any = None) -> int:
        return self.graph(shape).n_colours

    def param_names(self, covariates: Any = None, shape: Any = None) -> tuple[str, ...]:
        """``("mean", "coupling" | "coupling_<type>"..., "precision", <covariates>...)``.

        The names do not depend on the data (``covariates``, ``shape`` are accepted for
        the interface of :class:`mrfpe.models.MRF` and ignored).
        """
        types = self.coupling_type_names
        coup = ("coupling",) if len(types) == 1 else tuple(f"coupling_{t}" for t in types)
        return ("mean", *coup, "precision", *self.covariate_names)

    # -- data ------------------------------------------------------------------------------------
    def _fields(self, data: Any) -> tuple[CARStructure, np.ndarray]:
        """Structure and (M, n) float64 fields; ValueError naming ``data`` otherwise."""
        try:
            arr = np.asarray(data)
        except (TypeError, ValueError):
            raise ValueError(f"data must be an array of real numbers; got "
                             f"{type(data).__name__}") from None
        if arr.dtype.kind not in "iuf":
            raise ValueError(f"data must hold real numbers; got dtype {arr.dtype}")
        if isinstance(self.graph_spec, LatticeSpec):
            if arr.ndim not in (2, 3) or 0 in arr.shape:
                raise ValueError(f"data must be an (H, W) or (M, H, W) array of real numbers on "
                                 f"the lattice model {self.name!r}; got shape {arr.shape}")
            st = self.structure(arr.shape[-2:])
            node_shape: tuple[int, ...] = arr.shape[-2:]
        else:
            st = self.structure()
            node_shape = self.node_shape()
            if arr.shape == node_shape:
                arr = arr[None]
            if arr.shape[1:] != node_shape or arr.ndim != len(node_shape) + 1 or \
                    arr.shape[0] < 1:
                raise ValueError(f"data must have shape {node_shape} or (M, "
                                 f"{', '.join(map(str, node_shape))}) on the graph of model "
                                 f"{self.name!r}; got {np.shape(data)}")
        x = np.asarray(arr, dtype=np.float64).reshape(-1, st.n)
        if not np.all(np.isfinite(x)):
            bad = np.argwhere(~np.isfinite(x))[0]
            raise ValueError(f"data must be finite; observation {bad[0]} node {bad[1]} is "
                             f"{x[bad[0], bad[1]]}")
        return st, x

    def covariate_matrix(self, covariates: Any, shape: Any = None) -> np.ndarray:
        """Covariates as an ``(n_nodes, k)`` float array, checked against the declaration."""
        g = self.graph(shape)
        node_shape = g.shape if g.shape is not None else (g.n_nodes,)
        names, K = self.covariate_names, self.n_covariates
        if covariates is not None and isinstance(covariates, Mapping) and not covariates:
            covariates = None
        if K == 0:
            if covariates is not None:
                raise ValueError("covariates: the model declares none (build it with "
                                 "autonormal(covariates=k or names))")
            return np.zeros((g.n_nodes, 0))
        if covariates is None:
            raise ValueError(f"covariates must be given: the model declares {K} "
                             f"({', '.join(names)})")
        if isinstance(covariates, Mapping):
            if self._anonymous and set(covariates) == {"z"}:
                covariates = covariates["z"]
            else:
                if set(covariates) != set(names):
                    raise ValueError(f"covariates must hold exactly {', '.join(map(repr, names))};"
                                     f" got {', '.join(map(repr, sorted(map(str, covariates))))}")
                cols = []
                for c in names:
                    z = _real_array(covariates[c], f"covariate {c!r}")
                    if z.shape not in (tuple(node_shape), (*node_shape, 1)):
                        raise ValueError(f"covariate {c!r} must have shape {tuple(node_shape)}, "
                                         f"one value per node; got {z.shape}")
                    cols.append(z.reshape(g.n_nodes))
                return np.stack(cols, axis=1)
        z = _real_array(covariates, "covariates")
        ok = (*node_shape, K) if K > 1 else None
        if z.shape == tuple(node_shape) and K == 1:
            return z.reshape(g.n_nodes, 1)
        if z.shape != (*node_shape, K):
            want = f"{tuple(node_shape)} or {(*node_shape, 1)}" if ok is None else str(ok)
            raise ValueError(f"covariates must have shape {want} ({K} per node: "
                             f"{', '.join(names)}); got {z.shape}")
        return z.reshape(g.n_nodes, K)

    def _bounds_override(self, value: Any, what: str) -> dict[str, tuple[float, float]]:
        names = self.param_names()
        if isinstance(value, Mapping):
            unknown = [k for k in value if k not in names]
            if unknown:
                raise ValueError(f"{what} names unknown parameter(s) "
                                 f"{', '.join(map(repr, unknown))}; parameters: {names}")
            items = list(value.items())
        else:
            b = np.asarray(value, dtype=np.float64)
            if b.shape != (len(names), 2):
                raise ValueError(f"{what} must be ({len(names)}, 2), one row per parameter "
                                 f"{names}; got {b.shape}")
            items = list(zip(names, b, strict=True))
        out = {}
        for k, pair in items:
            try:
                lo, hi = (float(v) for v in pair)
            except (TypeError, ValueError):
                raise ValueError(f"{what}[{k!r}] must be (low, high); got {pair!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"{what}[{k!r}] must be finite with low < high; got "
                                 f"({lo}, {hi})")
            out[k] = (lo, hi)
        return out

    def default_bounds(self, data: Any, covariates: Any = None) -> np.ndarray:
        """``(d, 2)`` data-driven default bounds (see the module docstring), before overrides."""
        st, x = self._fields(data)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        return self._default_bounds(st, x, Z)

    def _default_bounds(self, st: CARStructure, x: np.ndarray, Z: np.ndarray) -> np.ndarray:
        lo_x, hi_x = float(x.min()), float(x.max())
        s = hi_x - lo_x if hi_x > lo_x else 1.0
        K = Z.shape[1]
        D = np.column_stack([np.ones(st.n), Z])
        coef, *_ = np.linalg.lstsq(D, x.T, rcond=None)  # (1 + K, M)
        v = float(np.mean((x.T - D @ coef) ** 2))
        v = v if v > 0 else s * s
        span_z = np.ptp(Z, axis=0) if K else np.zeros(0)
        span_z = np.where(span_z > 0, span_z, 1.0)
        gmax = 10.0 * s / span_z
        c = float(np.sum(gmax * np.abs(Z).max(axis=0))) if K else 0.0
        rows = [(lo_x - s - c, hi_x + s + c), *map(tuple, st.coupling_box()),
                (0.0, 1e4 / v), *((-g, g) for g in gmax)]
        return np.array(rows, dtype=np.float64)

    def _bounds_for(self, st: CARStructure, x: np.ndarray, Z: np.ndarray,
                    option: Any) -> np.ndarray:
        b = self._default_bounds(st, x, Z)
        names = self.param_names()
        for over in (self._bounds, option):
            for k, pair in (over or {}).items():
                b[names.index(k)] = pair
        bad = np.flatnonzero(b[:, 0] >= b[:, 1])
        if bad.size:
            k = names[bad[0]]
            raise ValueError(f"bounds of {k!r} must have low < high; got {b[bad[0]].tolist()}")
        return b

    # -- targets ---------------------------------------------------------------------------------
    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        st, x = self._fields(data)
        Z = self.covariate_matrix(options["covariates"], st.graph.shape)
        over = None if options["bounds"] is None else self._bounds_override(
            options["bounds"], "bounds")
        common = {"model": self, "structure": st, "x": x, "Z": Z, "estimator": estimator}
        if estimator == "coding":
            classes = st.graph.colour_classes()
            k = options["coding"]
            if k >= len(classes):
                raise ValueError(f"coding must be in [0, {len(classes) - 1}] (the graph has "
                                 f"{len(classes)} codings); got {k}")
        if estimator == "block":
            blocks = make_blocks(st.graph, options["block"])
        if st.needs_factorisation():
            st.check_sparse_size(f"deciding positive definiteness (estimator {estimator!r})")
        common["bounds"] = self._bounds_for(st, x, Z, over)
        if estimator == "pl":
            return GaussianPLTarget(**common)
        if estimator == "coding":
            return GaussianPLTarget(nodes=classes[k], cost=classes[k].size / st.n,
                                    extra={"coding": k, "n_codings": len(classes)}, **common)
        if estimator == "block":
            return GaussianBlockTarget(blocks=blocks, extra={
                "block": jsonable(options["block"]), "n_blocks": len(blocks)}, **common)
        if estimator == "exact":
            return GaussianExactTarget(method=options["method"], **common)
        if estimator == "likelihood":
            return GaussianLikelihoodTarget(sampler=options["sampler"], **common)
        if estimator == "pl_adjusted":
            from mrfpe.models.calibration import AdjustedPL

            return AdjustedPL(GaussianPLTarget(**{**common, "estimator": "pl"}),
                              GaussianLikelihoodTarget(**{**common, "estimator": "likelihood"}),
                              mode=options["mode"], n_draws=options["n_draws"],
                              seed=options["seed"])
        raise AssertionError(estimator)  # pragma: no cover - check_estimator ran

    # -- parameters in use -----------------------------------------------------------------------
    def _one_theta(self, theta: Any) -> np.ndarray:
        names = self.param_names()
        try:
            th = np.asarray(theta, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"theta must be {len(names)} finite numbers {names}; got "
                             f"{theta!r:.80}") from None
        if th.shape != (len(names),) or not np.all(np.isfinite(th)):
            raise ValueError(f"theta must be {len(names)} finite numbers {names}; got "
                             f"{np.asarray(theta).tolist()}")
        return th

    def precision_matrix(self, theta: Any, shape: Any = None) -> sp.csr_matrix:
        """The sparse precision ``Q = tau (I - sum_t beta_t W_t)`` at ``theta``."""
        st = self.structure(shape)
        th = self._one_theta(theta)
        return (th[1 + st.T] * st.A(th[1:1 + st.T])).tocsr()

    def mean_vector(self, theta: Any, shape: Any = None, covariates: Any = None) -> np.ndarray:
        """``mu = m + Z gamma`` (n_nodes,) at ``theta``."""
        st = self.structure(shape)
        th = self._one_theta(theta)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        return th[0] + Z @ th[2 + st.T:]

    def simulate(self, theta: Any, shape: Any = None, n: int = 1, *, seed: int | None = None,
                 covariates: Any = None, method: str = "auto") -> np.ndarray:
        """``n`` exact draws at ``theta``: ``(n, H, W)`` on a lattice, ``(n, n_nodes)`` otherwise.

        Parameters
        ----------
        theta : (d,) parameters (:meth:`param_names`).
        shape : (H, W) on a lattice.
        n : int >= 1
        seed : int or None
            ``numpy.random.default_rng(seed)``: the same seed gives the same draws.
        covariates : as for :meth:`target`.
        method : 'auto' | 'fft' | 'dense' | 'sparse'
            FFT on periodic lattices, a dense Cholesky factor up to
            :data:`MAX_DENSE_SIMULATION` nodes, a sparse ``LDL'`` beyond (auto).

        Raises
        ------
        ValueError
            For bad arguments, or a theta outside the positive-definite region.
        """
        n = check_positive_int("n", n)
        seed = check_seed(seed)
        method = check_choice("method", method, ("auto", "fft", "dense", "sparse"))
        st = self.structure(shape)
        th = self._one_theta(theta)
        Z = self.covariate_matrix(covariates, st.graph.shape)
        rng = np.random.default_rng(seed)
        u = st.sample(th[1:1 + st.T], float(th[1 + st.T]), n, rng, method,
                      f"theta {th.tolist()}")
        x = th[0] + Z @ th[2 + st.T:] + u
        g = st.graph
        return x.reshape(n, *(g.shape if g.shape is not None else (g.n_nodes,)))

    def describe(self) -> dict:
        out = super().describe()
        out.update({"graph": self.graph_spec.describe(), "directional": self.directional,
                    "param_names": list(self.param_names()),
                    "covariates": list(self.covariate_names),
                    "bounds": None if self._bounds is None else {
                        k: list(v) for k, v in self._bounds.items()}})
        return out

    def __repr__(self) -> str:
        return (f"GaussianMRF(name={self.name!r}, graph={self.graph_spec!r}, "
                f"directional={self.directional}, covariates={self.covariate_names})")


def autonormal(graph: Any = 4, *, directional: bool = False,
               covariates: int | Sequence[str] = 0, periodic: bool = False,
               bounds: Any = None) -> GaussianMRF:
    """Besag's auto-normal (Gaussian CAR) model.

    ``x_i | x_-i ~ N(mu_i + sum_t beta_t sum_{j ~_t i} (x_j - mu_j), 1/tau)``,
    ``mu_i = mean + z_i . gamma``; ``theta = (mean, coupling[_<type>]..., precision,
    gamma...)``. See :mod:`mrfpe.models.gaussian` for estimators, default bounds
    and simulation.

    Parameters
    ----------
    graph : 4, 8, lattice(...), Graph, adjacency matrix or networkx graph
    directional : bool
        One coupling per direction (lattice) or edge type (graph).
    covariates : int >= 0 or sequence of str
        Anonymous covariates (``z`` or ``z_0``, ``z_1`` ...) or named ones.
    periodic : bool
        Torus boundary (lattices only).
    bounds : (d, 2) array or mapping name -> (low, high), optional
        Overrides of the default bounds.
    """
    return GaussianMRF(graph, directional=directional, periodic=periodic,
                       covariates=covariates, bounds=bounds)


def _real_array(value: Any, what: str) -> np.ndarray:
    try:
        z = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be an array of real numbers") from None
    if z.dtype.kind not in "iuf":
        raise ValueError(f"{what} must hold real numbers; got dtype {z.dtype}")
    z = z.astype(np.float64)
    if not np.all(np.isfinite(z)):
        raise ValueError(f"{what} must be finite (it holds NaN or inf)")
    return z


def make_blocks(graph: Graph, block: Any) -> list[np.ndarray]:
    """:func:`mrfpe.models.options.node_blocks`, each of at most :data:`MAX_BLOCK_NODES` nodes."""
    blocks = node_blocks(graph, block)
    _check_block_sizes(blocks)
    return blocks


def _check_block_sizes(blocks: Sequence[np.ndarray]) -> None:
    m = max((b.size for b in blocks), default=0)
    if m > MAX_BLOCK_NODES:
        raise ValueError(f"block of {m} nodes is too large: block pseudolikelihood factorises "
                         f"an (m, m) matrix per block structure and theta, m <= "
                         f"{MAX_BLOCK_NODES} (use smaller blocks, or 'exact')")


# ------------------------------------------------------------------------------------------------
# targets
# ------------------------------------------------------------------------------------------------
class GaussianTarget(Target):
    """What every auto-normal target shares: parameters, data columns, PD check, description.

    ``u = x - mu = C a(theta)`` with ``C = [x - x0, 1, Z - z0]`` (centred, so that
    expanded quadratic forms lose little to cancellation) and ``a = (1, -(m - x0 +
    z0 . gamma), -gamma)``.
    """

    data_kind = "fields"

    def __init__(self, *, model: GaussianMRF, structure: CARStructure, x: np.ndarray,
                 Z: np.ndarray, bounds: np.ndarray, estimator: str, cost: float = 1.0,
                 extra: dict | None = None) -> None:
        self.model = model
        self.structure = structure
        self.x = x
        self.Z = Z
        self.param_names = model.param_names()
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.estimator = estimator
        self.name = f"{model.name}:{estimator}"
        self.cost = float(cost)
        self._extra = dict(extra or {})
        self.T = structure.T
        self.K = Z.shape[1]
        self.P = 2 + self.K
        self._x0 = float(x.mean())
        self._z0 = Z.mean(axis=0) if self.K else np.zeros(0)
        self._C = self.columns(x)

    def columns(self, x: np.ndarray) -> np.ndarray:
        """``C = [x - x0, 1, Z - z0]`` (M, n, P) of fields ``x`` (M, n), centred as the data."""
        M, n = x.shape
        C = np.empty((M, n, self.P))
        C[:, :, 0] = x - self._x0
        C[:, :, 1] = 1.0
        if self.K:
            C[:, :, 2:] = (self.Z - self._z0)[None]
        return C

    @property
    def n_observations(self) -> int:
        return int(self.x.shape[0])

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(mean (N,), coupling (N, T), precision (N,), gamma (N, K))``."""
        T = self.T
        return theta[:, 0], theta[:, 1:1 + T], theta[:, 1 + T], theta[:, 2 + T:]

    def _a(self, theta: np.ndarray) -> np.ndarray:
        m, _, _, g = self.split(theta)
        a = np.empty((theta.shape[0], self.P))
        a[:, 0] = 1.0
        a[:, 1] = -(m - self._x0 + g @ self._z0)
        a[:, 2:] = -g
        return a

    def _b(self, theta: np.ndarray) -> np.ndarray:
        """``(a, -beta_1 a, ..., -beta_T a)`` (N, P (1 + T)): ``e = G b``."""
        a = self._a(theta)
        beta = self.split(theta)[1]
        return np.concatenate([a] + [-beta[:, t:t + 1] * a for t in range(self.T)], axis=1)

    def _G(self) -> np.ndarray:
        """``(M, n, P (1 + T))``: ``[C, W_1 C, ..., W_T C]`` per observation."""
        M, n, P = self._C.shape
        G = np.empty((M, n, P * (1 + self.T)))
        for m in range(M):
            G[m, :, :P] = self._C[m]
            for t, W in enumerate(self.structure.W):
                G[m, :, P * (1 + t):P * (2 + t)] = W @ self._C[m]
        return G

    def valid(self, theta: np.ndarray) -> np.ndarray:
        """``(N,)``: rows with ``precision > 0`` and ``Q`` positive definite."""
        tau = self.split(theta)[2]
        ok = tau > 0
        if ok.any():
            ok[ok] = self.structure.pd_mask(self.split(theta[ok])[1])
        return ok

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        out = np.full(theta.shape[0], -np.inf)
        ok = self.valid(theta)
        if ok.any():
            out[ok] = self._value(theta[ok])
        return out

    def _value(self, theta: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__, "model": self.model.name,
                "estimator": self.estimator, "param_names": list(self.param_names),
                "bounds": self.bounds.tolist(), "graph": self.structure.describe(),
                "n_observations": self.n_observations, "covariates": list(
                    self.model.covariate_names), "cost": self.cost, **self._extra}


class GaussianPLTarget(GaussianTarget):
    """Pseudolikelihood (all nodes) or a coding likelihood (one colour class ``nodes``).

    ``sum_obs sum_{i in nodes} [1/2 log(tau / 2 pi) - tau/2 e_i^2]`` with
    ``sum e_i^2 = b' S b`` (see the module docstring): one small quadratic form per theta.
    """

    def __init__(self, *, nodes: np.ndarray | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        G = self._G()
        if nodes is not None:
            G = G[:, np.asarray(nodes, dtype=np.int64)]
        self.n_terms = int(G.shape[0] * G.shape[1])
        Gf = G.reshape(-1, G.shape[2])
        self._S = Gf.T @ Gf

    def _row_bytes(self) -> float:
        return 8.0 * 4 * self._S.shape[0]

    def residual_sum_of_squares(self, theta: Any) -> np.ndarray:
        """``sum e_i^2`` (N,): the conditional residuals' sum of squares (no PD check)."""
        b = self._b(as_theta_batch(theta, self.ndim))
        return np.einsum("np,pq,nq->n", b, self._S, b)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        tau = self.split(theta)[2]
        b = self._b(theta)
        rss = np.maximum(np.einsum("np,pq,nq->n", b, self._S, b), 0.0)
        return 0.5 * self.n_terms * (np.log(tau) - _LOG_2PI) - 0.5 * tau * rss


class GaussianBlockTarget(GaussianTarget):
    """Block pseudolikelihood: ``sum_B log p(x_B | x_rest)`` (see the module docstring)."""

    def __init__(self, *, blocks: Sequence[np.ndarray], **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
        G = self._G()
        M, _, Pp = G.shape
        self._groups = []
        for nodes, Wloc in _block_groups(self.structure, self.blocks):
            m = nodes.shape[1]
            GB = G[:, nodes].reshape(-1, m, Pp)  # (R, m, P')
            R = GB.shape[0]
            if m * Pp <= R:  # summed second moments: cost independent of the number of blocks
                F = GB.reshape(R, m * Pp)
                S = (F.T @ F).reshape(m, Pp, m, Pp)
                self._groups.append(("moment", Wloc, R, S))
            else:
                self._groups.append(("direct", Wloc, R, np.ascontiguousarray(GB)))
        self.n_terms = M * self.structure.n

    @property
    def n_groups(self) -> int:
        """Distinct block structures (one ``m x m`` factorisation each per theta)."""
        return len(self._groups)

    def _row_bytes(self) -> float:
        total = 0.0
        for kind, Wloc, R, data in self._groups:
            m = Wloc.shape[1]
            total += 8.0 * (4 * m * m + (m * m * data.shape[1] if kind == "moment" else 2 * R * m))
        return total

    def _value(self, theta: np.ndarray) -> np.ndarray:
        tau = self.split(theta)[2]
        beta = self.split(theta)[1]
        b = self._b(theta)
        N = theta.shape[0]
        logdet = np.zeros(N)
        quad = np.zeros(N)
        for kind, Wloc, R, data in self._groups:
            m = Wloc.shape[1]
            A = np.eye(m)[None] - np.einsum("nt,tij->nij", beta, Wloc)
            sign, ld = np.linalg.slogdet(A)
            ld = np.where(sign > 0, ld, -np.inf)
            Ainv = np.linalg.inv(A)
            logdet += R * ld
            if kind == "moment":
                X = np.tensordot(data, b, axes=([3], [1]))  # (m, P', m, N)
                Y = np.einsum("ipjn,np->nij", X, b)
                quad += np.einsum("nij,nij->n", Ainv, Y)
            else:
                E = np.tensordot(data, b, axes=([2], [1]))  # (R, m, N)
                Y = np.einsum("nij,rjn->rin", Ainv, E)
                quad += np.einsum("rin,rin->n", E, Y)
        quad = np.maximum(quad, 0.0)
        return (0.5 * self.n_terms * (np.log(tau) - _LOG_2PI) + 0.5 * logdet
                - 0.5 * tau * quad)

    def describe(self) -> dict:
        return {**super().describe(), "n_block_structures": self.n_groups}


def _block_groups(st: CARStructure, blocks: Sequence[np.ndarray]
                  ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Blocks grouped by size and internal structure: ``[(nodes (nb, m), W_BB (T, m, m))]``."""
    n = st.n
    block_of = np.full(n, -1, dtype=np.int64)
    pos_of = np.zeros(n, dtype=np.int64)
    for b, nodes in enumerate(blocks):
        block_of[nodes] = b
        pos_of[nodes] = np.arange(nodes.size)
    e = st.graph.edges
    internal = np.flatnonzero(block_of[e[:, 0]] == block_of[e[:, 1]])
    p, q = pos_of[e[internal, 0]], pos_of[e[internal, 1]]
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    tt = st.edge_coupling[internal]
    bb = block_of[e[internal, 0]]
    order = np.lexsort((tt, hi, lo, bb))
    rows = np.stack([lo, hi, tt], axis=1)[order]
    parts = np.split(rows, np.cumsum(np.bincount(bb[order], minlength=len(blocks)))[:-1])
    groups: dict[tuple[int, bytes], list[int]] = {}
    for b, nodes in enumerate(blocks):
        groups.setdefault((nodes.size, parts[b].tobytes()), []).append(b)
    out = []
    for (m, _), ids in groups.items():
        Wloc = np.zeros((st.T, m, m))
        r = parts[ids[0]]
        Wloc[r[:, 2], r[:, 0], r[:, 1]] = 1.0
        Wloc[r[:, 2], r[:, 1], r[:, 0]] = 1.0
        out.append((np.stack([blocks[b] for b in ids]), Wloc))
    return out


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
    lattices, ``eigvalsh`` once for one coupling on up to :data:`MAX_EIGEN_NODES`
    nodes; ``O(N n)`` per batch), ``"sparse"`` (a sparse ``LDL'`` per theta, up to
    :data:`MAX_SPARSE_NODES` nodes) or ``"auto"`` (eigen where known).
    """

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
        return 0.5 * self.structure.n * _LOG_2PI - 0.5 * self.log_det_precision(theta)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        _, beta, tau, _ = self.split(theta)
        M, n = self.x.shape
        logdet = n * np.log(tau) + self.structure.logdet_A(beta, self.method)
        quad = np.maximum(self._quad(self._a(theta), beta), 0.0)
        return M * 0.5 * (logdet - n * _LOG_2PI) - 0.5 * tau * quad

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

    #: Draws are exact (Cholesky / FFT): the exchange algorithm is then exact too.
    exact_simulator = True

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
            self.columns(_as_fields(x, self.structure.n)), self.structure.W)
        _, beta, tau, _ = self.split(theta)
        return -0.5 * tau * q(self._a(theta), beta)

    def _value(self, theta: np.ndarray) -> np.ndarray:
        _, beta, tau, _ = self.split(theta)
        return -0.5 * tau * self._quad(self._a(theta), beta)

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


def _as_fields(x: Any, n: int) -> np.ndarray:
    arr = _real_array(x, "x")
    if arr.size % n or arr.size == 0:
        raise ValueError(f"x must hold fields of {n} nodes ((M, {n}) or a lattice shape); got "
                         f"shape {arr.shape}")
    return arr.reshape(-1, n)
