"""Pseudolikelihood targets over BRDF parameters (thesis 4.23-4.24, 5.64-5.68, 6.54-6.62, 7.5-7.10).

Every target here is a sum over lattice nodes ``i`` of a per-node term built
from the node's energies at each of its B labels,

    ``E_i(s) = U^A_i(s; theta) + E0_i(s)``,

with ``U^A`` the BRDF data energy (:mod:`mrfpe.targets.energy`, 4.12/4.20/4.27
or the renderer-consistent pixel form) and ``E0`` a theta-independent unary
energy that distinguishes the variants:

=====  ===========================================  ==================================
name   E0                                           per-node term
=====  ===========================================  ==================================
pl     0                                            ``log p(x_i | x_N_i)`` (4.23-4.24, 5.64-5.66)
pl2    ``V^B + U^C`` (6.57, 6.58 with 6.23-6.24)    ``log p(x_i | x_N_i)`` (6.59)
pl3    ``U^D = -T log b`` (6.60)                    ``log p(x_i | x_N_i)`` (6.61-6.62)
pls    ``U^R = psi_i`` range prior (7.4, 7.6)       ``log p(x_i | x_N_i)`` (7.5-7.7)
fit    0                                            ``-U^A_i(x_i)``
pml    prior (range, beliefs or none)               ``log sum_s p0_i(s) exp(-U^A_i(s))``
=====  ===========================================  ==================================

with ``log p(x_i | x_N_i) = -E_i(x_i) - log sum_s exp(-E_i(s))``. ``fit`` is the
log conditional likelihood of the image given the observed labels (each pixel
counted once per corner node); ``pml`` marginalises each node's label under the
normalised prior ``p0_i`` (uniform without one) -- a composite marginal
likelihood. Both are beyond the thesis; they use the same energies, so a
study can measure what the pseudolikelihood's reward for making the
alternative labels fit badly costs.

Targets sample the unit cube (7.1-7.2); ``to_natural`` maps to BRDF units.
All theta-independent geometry is precomputed at construction; ``log_prob``
runs one fused numba kernel over a batch of parameter vectors.

``sigma_b`` (the data-energy scale of 4.12, not given in the thesis). The
default ``"auto"`` is ``max(sqrt(2/pi) * noise_sigma, 0.02 * (q99 - q1))`` of
the image: the first is the mean absolute deviation of Gaussian pixel noise
of standard deviation ``noise_sigma``, i.e. the maximum-likelihood scale of
the Laplace model that the absolute-value energy 4.12 is, so a correct
prediction costs about one unit of energy per pixel; the second is a floor at
2 % of the image's robust intensity range (about 5 grey levels of an 8-bit
image), which keeps noise-free or lightly quantised data from producing a
target so sharp that no sampler can explore it. Pass a number to override.
"""

from __future__ import annotations

import hashlib
import json
import weakref
from typing import Any

import numpy as np

from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.energy import DATA_TERMS, DataTables, build_tables, chunk_bounds
from mrfpe.threads import thread_budget

__all__ = [
    "PL",
    "PL2",
    "PL3",
    "PLS",
    "RESIDUAL_KINDS",
    "BRDFTarget",
    "CompositeMarginalLikelihood",
    "ImageFit",
    "auto_sigma_b",
]

#: Residual transforms for least-squares samplers (see :meth:`BRDFTarget.residuals`).
RESIDUAL_KINDS = ("inverse", "one_minus", "sqrt")
_DTYPES = ("float64", "float32")
_LOG_CLIP = 300.0  # residuals exp(-l) are clipped at exp(300) so that their squares stay finite
#: Batches smaller than this run the labels-as-SIMD kernel (no padding of particles).
_LABEL_KERNEL_BELOW = 5

_TABLE_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def auto_sigma_b(scene: Any) -> float:
    """Default data-energy scale ``sigma_b`` for ``scene`` (see the module docstring)."""
    img = np.asarray(scene.image, dtype=np.float64)
    q1, q99 = np.percentile(img, [1.0, 99.0])
    sigma = max(np.sqrt(2.0 / np.pi) * float(scene.noise_sigma), 0.02 * float(q99 - q1))
    if not sigma > 0:
        # A constant, noise-free image carries no shading contrast; any positive scale
        # gives the same (flat) target up to a factor.
        sigma = 1e-3
    return float(sigma)


def _fingerprint(scene: Any) -> str:
    h = hashlib.blake2b(digest_size=16)
    for arr in (scene.image, scene.label_ranges, scene.observed_labels, scene.tangent_ref):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update(json.dumps([scene.brdf, scene.camera.to_dict(), scene.light.to_dict()],
                        sort_keys=True).encode())
    return h.hexdigest()


def _tables_for(scene: Any, data_term: str, dtype: str = "float64") -> DataTables:
    """Data tables of ``scene``, shared by every target built on the same scene."""
    fp = _fingerprint(scene)
    per_scene = _TABLE_CACHE.setdefault(scene, {})
    key = (data_term, dtype, fp)
    if key not in per_scene:
        for old in [k for k in per_scene if k[:2] == (data_term, dtype)]:
            del per_scene[old]  # the scene was modified in place: drop stale tables
        if dtype == "float64":
            per_scene[key] = build_tables(scene, data_term)
        else:
            per_scene[key] = _tables_for(scene, data_term, "float64").astype(dtype)
    return per_scene[key]


def _check_scene(scene: Any) -> None:
    from mrfpe.scene import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be an mrfpe.scene.Scene; got {type(scene).__name__}")


def _positive(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number; got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number; got {value!r}")
    return v


def _robust(x: np.ndarray, sigma: float, e: float) -> np.ndarray:
    """Truncated robust potential ``-ln((1-e) exp(-|x|/sigma) + e)`` (6.23, 6.24)."""
    return -np.log((1.0 - e) * np.exp(-np.abs(x) / sigma) + e)


class BRDFTarget(Target):
    """Base of the BRDF pseudolikelihood family (see the module docstring).

    Parameters
    ----------
    scene : mrfpe.scene.Scene
    sigma_b : float or "auto"
        Data-energy scale of 4.12 (see the module docstring).
    data_term : "pixel" | "triplet"
        Renderer-consistent pixel form (default) or the thesis's literal triplet
        cliques (:mod:`mrfpe.targets.energy`).
    dtype : "float64" | "float32"
        Precision of the tables and kernels (float64 default). float32 is about
        twice as fast; its log_prob agrees with float64 to ~1e-6 relative
        (``tests/targets/test_pseudolikelihood.py::test_float32_accuracy``), per-node
        terms are still summed in float64. Coefficients that overflow float32
        (e.g. Ward ``alpha < 1e-19``) give ``-inf``.

    Attributes
    ----------
    name : str
    param_names, bounds : unit-cube sampling space of ``scene.brdf``
    cost : float
        Share of the lattice's nodes this target covers (1 for the full target).
    nodes : ndarray
        Global ids of the nodes whose terms this target sums.
    """

    name = ""
    #: Weights of ``-E_i(x_i)`` and of ``log sum_s exp(-E_i(s))`` in the per-node term.
    _a, _b = 1.0, -1.0

    def __init__(self, scene: Any, *, sigma_b: float | str = "auto", data_term: str = "pixel",
                 dtype: str = "float64", **options: Any) -> None:
        _check_scene(scene)
        if data_term not in DATA_TERMS:
            raise ValueError(f"data_term must be one of {DATA_TERMS}; got {data_term!r}")
        if dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {_DTYPES}; got {dtype!r}")
        if isinstance(sigma_b, str):
            if sigma_b != "auto":
                raise ValueError(f"sigma_b must be a positive number or 'auto'; got {sigma_b!r}")
            sigma = auto_sigma_b(scene)
        else:
            sigma = _positive("sigma_b", sigma_b)
        self.scene = scene
        self.model = scene.model
        self.param_names = tuple(self.model.param_names)
        self.bounds = np.array([[0.0, 1.0]] * self.model.d)
        self.sigma_b = sigma
        self.data_term = data_term
        self.dtype = dtype
        self.options = self._check_options(scene, options)
        tables = _tables_for(scene, data_term, dtype)
        unary, const = self._unary(scene)
        n = scene.lattice.n_nodes
        B = scene.n_labels
        unary = np.ascontiguousarray(np.asarray(unary, dtype=np.float64).reshape(n, B))
        if dtype == "float32" and np.any(np.isfinite(unary) & (np.abs(unary) > 1e30)):
            raise ValueError(f"{self.name}: unary energies beyond 1e30 do not fit float32")
        obs = np.ascontiguousarray(scene.observed_labels.reshape(n).astype(np.int64))
        if np.any(np.isnan(unary)) or np.any(unary == -np.inf):
            raise ValueError(f"{self.name}: unary energies contain NaN or -inf")
        if self._a != 0 and not np.all(np.isfinite(unary[np.arange(n), obs])):
            raise ValueError(f"{self.name}: an observed label has infinite unary energy "
                             "(zero belief or prior), so every parameter vector has "
                             "probability 0")
        self._set_parts(tables, unary.astype(dtype), obs,
                        np.asarray(const, dtype=np.float64).reshape(n), n_total=n)

    # -- construction helpers ---------------------------------------------------------
    def _check_options(self, scene: Any, options: dict) -> dict:
        if options:
            raise ValueError(f"{self.name} takes no options {sorted(options)}; common options "
                             "are sigma_b, data_term, dtype")
        return {}

    def _unary(self, scene: Any) -> tuple[np.ndarray, np.ndarray]:
        """Theta-independent energies E0 (H+1, W+1, B) and per-node constants."""
        n = scene.lattice.n_nodes
        return np.zeros((n, scene.n_labels)), np.zeros(n)

    def _set_parts(self, tables: DataTables, unary: np.ndarray, obs: np.ndarray,
                   const: np.ndarray, n_total: int) -> None:
        self._tables = tables
        self._unary_e = unary
        self._obs = obs
        self._const = const
        self._const_sum = float(np.sum(const))
        self._chunks = chunk_bounds(tables.var_ptr)
        self._n_total = int(n_total)
        self.nodes = tables.nodes
        self.cost = tables.n_nodes / self._n_total

    # -- parameters ----------------------------------------------------------------------
    def to_natural(self, theta: Any) -> np.ndarray:
        """Unit-cube parameters -> natural BRDF units (7.1-7.2)."""
        return self.model.to_natural(theta)

    def to_unit(self, theta: Any) -> np.ndarray:
        """Natural BRDF units -> unit cube."""
        return self.model.to_unit(theta)

    @property
    def true_theta(self) -> np.ndarray | None:
        """The scene's true parameters in the sampling space (unit cube), if known."""
        tt = self.scene.true_theta
        return None if tt is None else self.model.to_unit(np.asarray(tt, dtype=np.float64))

    # -- evaluation ------------------------------------------------------------------------
    def _terms(self, theta: np.ndarray, per_node: bool) -> np.ndarray:
        from mrfpe.targets import kernels, reflectance

        t = self._tables
        N = theta.shape[0]
        coef = reflectance.coefficients(self.model, self.model.to_natural(theta))
        ft = np.dtype(self.dtype).type
        with np.errstate(over="ignore"):
            # e.g. rho_s / alpha^2 for alpha ~ 1e-200 (or 1e-20 in float32): -inf, not NaN
            bad = ~np.all(np.isfinite(coef.astype(ft)), axis=1)
        if bad.any():
            coef[bad] = 0.0
        full = self.model.name not in ("lambertian", "ward")
        labels_simd = N < _LABEL_KERNEL_BELOW
        if labels_simd:  # a few particles: the labels are the SIMD lanes, no padding
            npad = N
            coef_t = np.ascontiguousarray(coef.T, dtype=ft)
        else:
            bl = kernels.block_size(N)
            npad = -(-N // bl) * bl
            coef_t = np.empty((5, npad), dtype=ft)
            coef_t[:, :N] = coef.T
            coef_t[:, N:] = coef[:1].T  # padding particles: copies of the first, discarded
        n_chunks = self._chunks.shape[0] - 1
        if per_node:
            out_chunk = np.zeros((1, 1))
            out_node = np.zeros((t.n_nodes, npad))
        else:
            out_chunk = np.zeros((n_chunks, npad))
            out_node = np.zeros((1, 1))
        args = (t.slot_ptr, t.slot_y, t.slot_w, t.slot_nvar, t.fix_feat, t.var_ptr, t.var_feat,
                self._unary_e, self._obs, ft(1.0 / self.sigma_b), self._chunks, ft(self._a),
                ft(self._b), self._b != 0, out_chunk, out_node, per_node)
        with thread_budget(N * t.brdf_evals_per_particle):
            if labels_simd:
                kernels.pl_terms_labels(coef_t, full, *args)
            else:
                kernels.pl_terms(coef_t, bl, full, *args)
        if per_node:
            res = out_node[:, :N].T + self._const[None, :]
            res[bad] = -np.inf
            return res
        res = out_chunk[:, :N].sum(axis=0) + self._const_sum
        res[bad] = -np.inf
        return res

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        if self._tables.n_nodes == 0:
            return np.zeros(theta.shape[0])
        return self._terms(theta, per_node=False)

    def node_terms(self, theta: Any) -> np.ndarray:
        """Per-node terms (N, n_nodes) whose sum over nodes is ``log_prob`` (in bounds)."""
        theta = as_theta_batch(theta, self.ndim)
        if not np.all(self.in_bounds(theta)):
            raise ValueError(f"theta must lie in the unit cube {self.bounds.tolist()} for "
                             "node_terms")
        return self._terms(theta, per_node=True)

    def residuals(self, theta: Any, kind: str = "inverse") -> np.ndarray:
        """Per-node error vector for least squares (7.10-7.12).

        With ``l_i`` the node's term (``log p(x_i | x_N_i, theta)`` for the PL family):

        * ``"inverse"`` (7.10, the thesis's choice): ``eps_i = 1 / p_i = exp(-l_i)``,
          clipped at ``exp(300)`` so that ``sum eps_i^2`` stays finite;
        * ``"one_minus"`` (7.11): ``eps_i = 1 - exp(l_i)``;
        * ``"sqrt"``: ``eps_i = sqrt(-l_i)``, so ``sum eps_i^2 = -log_prob``.

        LM minimises ``sum_i eps_i^2`` (7.3.2). Rows outside the unit cube get
        ``+inf`` residuals.

        Returns
        -------
        ndarray
            (N, n_nodes), or (n_nodes,) for a single (d,) vector.
        """
        if kind not in RESIDUAL_KINDS:
            raise ValueError(f"kind must be one of {RESIDUAL_KINDS}; got {kind!r}")
        single = np.ndim(theta) == 1
        theta = as_theta_batch(theta, self.ndim)
        out = np.full((theta.shape[0], self._tables.n_nodes), np.inf)
        inside = self.in_bounds(theta)
        if inside.any() and self._tables.n_nodes:
            ell = self._terms(theta[inside], per_node=True)
            if kind == "inverse":
                res = np.exp(np.minimum(-ell, _LOG_CLIP))
            elif kind == "one_minus":
                res = 1.0 - np.exp(np.minimum(ell, 0.0))
            else:
                res = np.sqrt(np.maximum(-ell, 0.0))
            out[inside] = np.where(np.isnan(res), np.inf, res)
        return out[0] if single else out

    # -- sub-lattices ------------------------------------------------------------------------
    def partition(self, k: int, kind: str = "strided") -> list[BRDFTarget]:
        """Split into ``k`` sub-lattice targets whose log_probs sum to this one's.

        ``kind="strided"``: ``S^n = {n, n+k, ...}`` over this target's nodes (5.68,
        7.8); ``"block"``: ``k`` contiguous runs of nodes (5.67). Each part holds
        only its own nodes' precomputed entries and has ``cost`` = its share of
        the full lattice's nodes.
        """
        n = self._tables.n_nodes
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k <= n:
            raise ValueError(f"k must be an integer in [1, {n}] (the target's nodes); got {k!r}")
        if kind == "strided":
            groups = [np.arange(j, n, int(k)) for j in range(int(k))]
        elif kind == "block":
            groups = np.array_split(np.arange(n), int(k))
        else:
            raise ValueError(f"kind must be 'strided' or 'block'; got {kind!r}")
        return [self._subset(g) for g in groups]

    def _subset(self, local: np.ndarray) -> BRDFTarget:
        sub = object.__new__(type(self))
        sub.__dict__.update({k: v for k, v in self.__dict__.items() if not k.startswith("_")})
        sub._set_parts(self._tables.subset(local), self._unary_e[local], self._obs[local],
                       self._const[local], self._n_total)
        return sub

    # -- description -----------------------------------------------------------------------------
    def describe(self) -> dict:
        """JSON description (name, options, scene summary) for posteriors."""
        sc = self.scene
        tt = sc.true_theta
        return {
            "name": self.name,
            "class": type(self).__name__,
            "param_names": list(self.param_names),
            "bounds": self.bounds.tolist(),
            "sampling_space": "unit cube; natural = unit_scale * theta (thesis 7.1-7.2)",
            "unit_scale": np.asarray(self.model.unit_scale, dtype=float).tolist(),
            "options": {"sigma_b": self.sigma_b, "data_term": self.data_term,
                        "dtype": self.dtype, **self.options},
            "n_nodes": int(self._tables.n_nodes),
            "n_nodes_total": self._n_total,
            "cost": float(self.cost),
            "scene": {
                "shape": list(sc.shape),
                "n_labels": int(sc.n_labels),
                "brdf": sc.brdf,
                "true_theta": None if tt is None else np.asarray(tt, dtype=float).tolist(),
                "true_theta_unit": None if tt is None else self.true_theta.tolist(),
                "noise_sigma": float(sc.noise_sigma),
                "camera": sc.camera.to_dict(),
                "light": sc.light.to_dict(),
                "meta": sc.meta,
                "fingerprint": _fingerprint(sc),
            },
        }

    @property
    def nbytes(self) -> int:
        """Bytes held by this target's precomputed tables."""
        return int(self._tables.nbytes + self._unary_e.nbytes + self._obs.nbytes
                   + self._const.nbytes)

    def __repr__(self) -> str:
        H, W = self.scene.shape
        return (f"{type(self).__name__}(name={self.name!r}, brdf={self.model.name!r}, "
                f"shape=({H}, {W}), n_labels={self.scene.n_labels}, nodes={self._tables.n_nodes}, "
                f"data_term={self.data_term!r}, sigma_b={self.sigma_b:.4g})")


class PL(BRDFTarget):
    """Pseudolikelihood of the BRDF MRF, thesis 4.23-4.24 / 5.64-5.66 (no unary energy)."""

    name = "pl"


class PLS(BRDFTarget):
    """Synthetic-data pseudolikelihood ``PL_s`` with the range prior ``U^R`` (7.3-7.7).

    Options
    -------
    prior_weight : float, default 1
        Multiplies the scene's range potentials ``psi_i(x_i, z_i) = |z_i - r_i(x_i)|/sigma``
        (7.4, stored as ``scene.range_prior``); 1 is the thesis's PL_s. A weight
        ``w`` is the same as a prior scale ``sigma / w`` (synthetic scenes use
        ``sigma = B/5`` label steps, ``make_scene(prior_sigma=...)``); 0 gives ``pl``.
    """

    name = "pls"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        w = opts.pop("prior_weight", 1.0)
        if opts:
            raise ValueError(f"pls options are prior_weight, sigma_b, data_term, dtype; "
                             f"got unknown {sorted(opts)}")
        if scene.range_prior is None:
            raise ValueError("scene has no range_prior; pls (7.5-7.7) needs the range "
                             "potentials psi_i of 7.4 (mrfpe.synthetic.make_scene sets them)")
        w = float(w)
        if not (np.isfinite(w) and w >= 0):
            raise ValueError(f"prior_weight must be finite and >= 0; got {w!r}")
        return {"prior_weight": w}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        u = self.options["prior_weight"] * np.asarray(scene.range_prior).reshape(n, -1)
        return u, np.zeros(n)


class PL3(BRDFTarget):
    """Pseudolikelihood ``PL_3`` with the stereo belief potential ``U^D`` (6.60-6.62).

    ``U^D_i(x) = -T log(b_i(x) / k1)``; ``k1`` cancels in 6.61 and is taken as 1.
    With uniform beliefs ``U^D`` is constant per node and PL3 equals :class:`PL`.
    A zero belief forbids its label (infinite energy).

    Options
    -------
    beliefs : (H+1, W+1, B) array, optional
        Overrides ``scene.beliefs``; normalised per node.
    temperature : float, default 1
        ``T`` of 6.60.
    """

    name = "pl3"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        beliefs = opts.pop("beliefs", None)
        T = opts.pop("temperature", 1.0)
        if opts:
            raise ValueError(f"pl3 options are beliefs, temperature, sigma_b, data_term, dtype; "
                             f"got unknown {sorted(opts)}")
        T = _positive("temperature", T)
        shape = (*scene.lattice.node_shape, scene.n_labels)
        if beliefs is None:
            if scene.beliefs is None:
                raise ValueError("scene has no beliefs; pl3 (6.60-6.62) needs per-node label "
                                 "beliefs (pass beliefs=... or use a stereo scene)")
            b = np.asarray(scene.beliefs, dtype=np.float64)
            source = "scene"
        else:
            b = np.asarray(beliefs, dtype=np.float64)
            source = "option"
            if b.shape != shape:
                raise ValueError(f"beliefs must have shape {shape}; got {b.shape}")
            if not np.all(np.isfinite(b)) or np.any(b < 0):
                raise ValueError("beliefs must be finite and >= 0")
            if not np.allclose(b.sum(axis=2), 1.0, rtol=0, atol=1e-6):
                raise ValueError("beliefs must be normalised per node (sum over labels = 1)")
        self._beliefs = b
        return {"temperature": T, "beliefs": source}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        b = self._beliefs.reshape(n, -1)
        with np.errstate(divide="ignore"):
            u = -self.options["temperature"] * np.log(b)
        return u, np.zeros(n)


class PL2(BRDFTarget):
    """Pseudolikelihood ``PL_2`` with pairwise smoothness ``V^B`` and match energy ``U^C`` (6.59).

    ``V^B_i(s) = sum_{t in N_i} psi_p(d_i(s), d_t(x_t))`` over the node's four
    lattice neighbours (6.57: every pairwise term of the node, even though this
    counts each pair twice over the lattice) with the robust potential
    ``psi_p(d, d') = -ln((1 - e_p) exp(-|d - d'| / sigma_p) + e_p)`` (6.24).
    ``d`` is measured in label steps: by default the node's *range* divided by
    its label spacing (``pairwise_on="range"``), which equals the thesis's
    disparity difference for a label set of shared disparities and stays
    meaningful when each node's labels sit about its own range (synthetic
    scenes); ``pairwise_on="label"`` uses the label indices literally.

    ``U^C_i(s) = psi_d(F_i(s))`` (6.58, 6.23) from a stereo match cost
    ``F = 1 - match`` in [0, 1] (6.5), taken from the ``match_cost`` option or
    a ``scene.match_cost`` attribute; without one the term is omitted (as a
    synthetic scene has no stereo match), which ``describe()`` records.

    Options
    -------
    smoothness : bool, default True
        Include ``V^B`` (6.59's text: omit it for surfaces not expected to be smooth).
    smoothness_sigma, smoothness_e : float, default 1.0, 0.01
        ``sigma_p`` (label steps) and ``e_p`` of 6.24 (the thesis's Fig. 6.3 values).
    pairwise_on : "range" | "label"
    match_cost : (H+1, W+1, B) array, optional
    match_sigma, match_e : float, default 1.0, 0.01
        ``sigma_d`` and ``e_d`` of 6.23.
    """

    name = "pl2"

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        smooth = bool(opts.pop("smoothness", True))
        sp = _positive("smoothness_sigma", opts.pop("smoothness_sigma", 1.0))
        ep = float(opts.pop("smoothness_e", 0.01))
        on = opts.pop("pairwise_on", "range")
        mc = opts.pop("match_cost", None)
        sd = _positive("match_sigma", opts.pop("match_sigma", 1.0))
        ed = float(opts.pop("match_e", 0.01))
        if opts:
            raise ValueError(
                "pl2 options are smoothness, smoothness_sigma, smoothness_e, pairwise_on, "
                f"match_cost, match_sigma, match_e, sigma_b, data_term, dtype; got unknown "
                f"{sorted(opts)}")
        for nm, e in (("smoothness_e", ep), ("match_e", ed)):
            if not 0 <= e < 1:
                raise ValueError(f"{nm} must lie in [0, 1); got {e!r}")
        if on not in ("range", "label"):
            raise ValueError(f"pairwise_on must be 'range' or 'label'; got {on!r}")
        shape = (*scene.lattice.node_shape, scene.n_labels)
        source = None
        if mc is None and getattr(scene, "match_cost", None) is not None:
            mc, source = scene.match_cost, "scene"
        elif mc is not None:
            source = "option"
        if mc is not None:
            mc = np.asarray(mc, dtype=np.float64)
            if mc.shape != shape or not np.all(np.isfinite(mc)):
                raise ValueError(f"match_cost must be a finite array of shape {shape}; "
                                 f"got shape {mc.shape}")
        self._match = mc
        return {"smoothness": smooth, "smoothness_sigma": sp, "smoothness_e": ep,
                "pairwise_on": on, "match_cost": source, "match_sigma": sd, "match_e": ed}

    def _unary(self, scene):
        o = self.options
        H1, W1 = scene.lattice.node_shape
        B = scene.n_labels
        u = np.zeros((H1, W1, B))
        if o["smoothness"]:
            if o["pairwise_on"] == "range":
                val = np.asarray(scene.label_ranges, dtype=np.float64)  # world units
                step = (np.median(np.abs(np.diff(val, axis=2)), axis=2) if B > 1
                        else np.ones((H1, W1)))
                step = np.where(step > 0, step, 1.0)  # the node's label spacing
            else:
                val = np.broadcast_to(np.arange(B, dtype=np.float64), (H1, W1, B))
                step = np.ones((H1, W1))
            obs = scene.observed_labels
            val_obs = np.take_along_axis(val, obs[..., None], axis=2)[..., 0]
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                # node (r, c) in `me`, its neighbour (r + dr, c + dc) in `nb`, where it exists
                me = (slice(max(0, -dr), H1 - max(0, dr)), slice(max(0, -dc), W1 - max(0, dc)))
                nb = (slice(max(0, dr), H1 - max(0, -dr)), slice(max(0, dc), W1 - max(0, -dc)))
                diff = (val[me] - val_obs[nb][..., None]) / step[me][..., None]
                u[me] += _robust(diff, o["smoothness_sigma"], o["smoothness_e"])
        if self._match is not None:
            u += _robust(self._match, o["match_sigma"], o["match_e"])
        n = H1 * W1
        return u.reshape(n, B), np.zeros(n)


class ImageFit(BRDFTarget):
    """``fit``: ``-sum_i U^A_i(x_i)``, the image's log conditional likelihood given the labels.

    Beyond the thesis. Unary energies at the observed labels would only add a
    theta-independent constant and are left out. Each pixel enters once per
    corner node (4 times in the interior) with the pixel data term.
    """

    name = "fit"
    _a, _b = 1.0, 0.0


class CompositeMarginalLikelihood(BRDFTarget):
    """``pml``: ``sum_i log sum_s p0_i(s) exp(-U^A_i(s))`` (beyond the thesis).

    Each node's label is marginalised under the normalised prior
    ``p0_i(s) = exp(-E0_i(s)) / sum_s' exp(-E0_i(s'))`` with ``E0`` the range
    prior (7.4), the belief potential (6.60) or zero (uniform over the B labels).

    Options
    -------
    prior : "auto" | "range" | "beliefs" | "none"
        "auto" uses the scene's range prior, else its beliefs, else none.
    """

    name = "pml"
    _a, _b = 0.0, 1.0

    def _check_options(self, scene: Any, options: dict) -> dict:
        opts = dict(options)
        prior = opts.pop("prior", "auto")
        if opts:
            raise ValueError(f"pml options are prior, sigma_b, data_term, dtype; got unknown "
                             f"{sorted(opts)}")
        choices = ("auto", "range", "beliefs", "none")
        if prior not in choices:
            raise ValueError(f"prior must be one of {choices}; got {prior!r}")
        if prior == "auto":
            prior = ("range" if scene.range_prior is not None
                     else "beliefs" if scene.beliefs is not None else "none")
        if prior == "range" and scene.range_prior is None:
            raise ValueError("prior='range' but the scene has no range_prior")
        if prior == "beliefs" and scene.beliefs is None:
            raise ValueError("prior='beliefs' but the scene has no beliefs")
        return {"prior": prior}

    def _unary(self, scene):
        n = scene.lattice.n_nodes
        B = scene.n_labels
        prior = self.options["prior"]
        if prior == "range":
            e0 = np.asarray(scene.range_prior, dtype=np.float64).reshape(n, B)
        elif prior == "beliefs":
            with np.errstate(divide="ignore"):
                e0 = -np.log(np.asarray(scene.beliefs, dtype=np.float64).reshape(n, B))
        else:
            e0 = np.zeros((n, B))
        m = np.min(e0, axis=1, keepdims=True)
        log_z = -m[:, 0] + np.log(np.sum(np.exp(-(e0 - m)), axis=1))
        return e0, -log_z
