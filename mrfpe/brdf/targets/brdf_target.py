"""The BRDF target family's base class: construction, evaluation, sub-lattices, description.

:class:`BRDFTarget` holds what every variant of
:mod:`mrfpe.brdf.targets.pseudolikelihood` shares: the per-node formula

    ``l_i = a (-E_i(x_i)) + b log sum_s exp(-E_i(s)) + c_i``,
    ``E_i(s) = U^A_i(s; theta) + E0_i(s)``,

(``a = 1, b = -1`` for the pseudolikelihoods 4.23-4.24, 5.64-5.66, 6.59, 6.61,
7.5), the shared data tables (:mod:`mrfpe.brdf.targets.tables`), the engine's plan and
tables built once at construction and its one call :func:`mrfpe.brdf.engine.evaluate`,
residuals (:mod:`mrfpe.brdf.targets.residuals`)
and the sub-lattice split (5.67, 5.68; :func:`mrfpe.targets.partition.split_ids`).
A variant supplies its theta-independent unary energy ``E0`` and constants
``c_i`` (``_unary``) and its own options (``_check_options``).

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

from typing import Any, ClassVar

import numpy as np

from mrfpe.brdf.engine import (
    DTYPES,
    KERNELS,
    DataTables,
    evaluate,
    lean_tables,
    make_plan,
    make_tables,
)
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.energy import DATA_TERMS
from mrfpe.brdf.targets.residuals import check_kind, transform
from mrfpe.brdf.targets.tables import fingerprint, lean_tables_for, tables_for
from mrfpe.budget import check_memory
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.options import (
    Option,
    bool_check,
    choice_check,
    number_check,
    resolve_options,
)
from mrfpe.targets.partition import split_ids

__all__ = ["COMMON_OPTIONS", "BRDFTarget", "auto_sigma_b"]


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


def _check_scene(scene: Any) -> None:
    from mrfpe.brdf.scene import Scene

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be an mrfpe.brdf.scene.Scene; got {type(scene).__name__}")


def _check_sigma_b(name: str, value: Any) -> float | str:
    if isinstance(value, str):
        if value != "auto":
            raise ValueError(f"{name} must be a positive number or 'auto'; got {value!r}")
        return value
    return number_check(0.0, np.inf, low_open=True)(name, value)


#: Options every BRDF target takes (each variant adds its own, :attr:`BRDFTarget.option_specs`).
COMMON_OPTIONS: tuple[Option, ...] = (
    Option("sigma_b", "float > 0 | 'auto'", "auto", _check_sigma_b,
           "data-energy scale of 4.12; 'auto' from the image's noise and range"),
    Option("data_term", "'pixel' | 'triplet'", "pixel", choice_check(*DATA_TERMS),
           "renderer-consistent pixel form or the thesis's literal triplet cliques"),
    Option("dtype", "'float64' | 'float32'", "float64", choice_check(*DTYPES),
           "precision of the tables and kernels"),
    Option("kernel", "'lean' | 'classic'", "lean", choice_check(*KERNELS),
           "kernel family: the fixed-template kernels or the general CSR loops"),
    Option("progress", "bool", False, bool_check,
           "show a progress bar while the data tables are built"),
)


class BRDFTarget(Target):
    """Base of the BRDF pseudolikelihood family (see :mod:`mrfpe.brdf.targets.brdf_target`).

    Parameters
    ----------
    scene : mrfpe.brdf.scene.Scene
    **options
        :data:`COMMON_OPTIONS` and the variant's own (``option_specs``; an unknown
        one raises ValueError listing the valid ones):
    sigma_b : float or "auto"
        Data-energy scale of 4.12 (see :mod:`mrfpe.brdf.targets.brdf_target`).
    data_term : "pixel" | "triplet"
        Renderer-consistent pixel form (default) or the thesis's literal triplet
        cliques (:mod:`mrfpe.brdf.targets.energy`).
    dtype : "float64" | "float32"
        Precision of the tables and kernels (float64 default). float32 is about
        twice as fast; its log_prob agrees with float64 to ~1e-6 relative
        (``tests/brdf/targets/test_pseudolikelihood.py::test_float32_accuracy``), per-node
        terms are still summed in float64. Coefficients that overflow float32
        (e.g. Ward ``alpha < 1e-19``) give ``-inf``.
    kernel : "lean" | "classic"
        Kernel family (:mod:`mrfpe.brdf.engine`): the fixed-template kernels (default;
        1.15-1.8x faster) or the general CSR loops. The same terms up to rounding;
        tables that do not fit the template, and batches whose exponents could
        overflow the lean ``2^x``, run the classic kernels whatever is asked.
    progress : bool
        Show a progress bar while the tables are built (a build whose estimated
        memory exceeds :func:`mrfpe.targets.memory_budget` fails before it starts).

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

    #: The options this target accepts (:mod:`mrfpe.targets.options`).
    option_specs: ClassVar[tuple[Option, ...]] = COMMON_OPTIONS
    #: What :func:`mrfpe.targets.get` passes as the first argument.
    data_kind: ClassVar[str] = "scene"

    def __init__(self, scene: Any, **options: Any) -> None:
        _check_scene(scene)
        opts = resolve_options(self.name or type(self).__name__, self.option_specs, options)
        sigma_b = opts.pop("sigma_b")
        data_term = opts.pop("data_term")
        dtype = opts.pop("dtype")
        kernel = opts.pop("kernel")
        progress = opts.pop("progress")
        sigma = auto_sigma_b(scene) if sigma_b == "auto" else sigma_b
        self.scene = scene
        self.model = scene.model
        self.param_names = tuple(self.model.param_names)
        self.bounds = np.array([[0.0, 1.0]] * self.model.d)
        self.sigma_b = sigma
        self.data_term = data_term
        self.dtype = dtype
        self.kernel = kernel
        if self._a != 0 and self._b != 0 and scene.n_labels < 2:
            raise ValueError(f"{self.name}: the scene has n_labels=1; a pseudolikelihood needs "
                             "n_labels >= 2 (with one label log p(x_i | x_N_i) = 0 for every "
                             "theta)")
        self.options = self._check_options(scene, opts)
        tables = tables_for(scene, data_term, dtype, progress=progress)
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
        lean = lean_tables_for(scene, data_term, dtype, self._full)
        self._set_parts(tables, unary.astype(dtype), obs,
                        np.asarray(const, dtype=np.float64).reshape(n), n_total=n, lean=lean)

    # -- construction helpers ---------------------------------------------------------
    def _check_options(self, scene: Any, options: dict) -> dict:
        """Scene-dependent checks of the variant's own (already value-checked) options.

        Returns the dict recorded as ``self.options`` (and in ``describe()``).
        """
        return dict(options)

    def _unary(self, scene: Any) -> tuple[np.ndarray, np.ndarray]:
        """Theta-independent energies E0 (H+1, W+1, B) and per-node constants."""
        n = scene.lattice.n_nodes
        return np.zeros((n, scene.n_labels)), np.zeros(n)

    @property
    def _full(self) -> bool:
        """Whether the model has the second lobe term (not Lambertian or Ward)."""
        return self.model.name not in ("lambertian", "ward")

    def _set_parts(self, tables: DataTables, unary: np.ndarray, obs: np.ndarray,
                   const: np.ndarray, n_total: int, lean: Any = None) -> None:
        """Hold the parts of the nodes ``tables`` covers and build the engine's tables and
        plan (``lean``: the template tables, built here from ``tables`` if None; the
        Jacobians of :mod:`mrfpe.brdf.targets.jacobian` use them whatever the kernel family)."""
        if lean is None:
            lean = lean_tables(tables, self._full)
        self._engine_tables = make_tables(tables, lean, unary, obs)
        self._plan = make_plan(self._engine_tables, kernel=self.kernel, dtype=self.dtype,
                               full=self._full, sigma_b=self.sigma_b, a=self._a, b=self._b)
        self._tables = tables
        self._unary_e = self._engine_tables.unary
        self._obs = self._engine_tables.obs
        self._const = const
        self._const_sum = float(np.sum(const))
        self._chunks = self._engine_tables.chunks
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
        coef = reflectance.coefficients(self.model, self.model.to_natural(theta))
        ft = np.dtype(self.dtype).type
        with np.errstate(over="ignore"):
            # e.g. rho_s / alpha^2 for alpha ~ 1e-200 (or 1e-20 in float32): -inf, not NaN
            bad = ~np.all(np.isfinite(coef.astype(ft)), axis=1)
        if bad.any():
            coef[bad] = 0.0
        res = evaluate(self._plan, self._engine_tables, coef, per_node=per_node)
        if per_node:
            res = res + self._const[None, :]
        else:
            res = res + self._const_sum
        res[bad] = -np.inf
        return res

    def _row_bytes(self) -> float:
        # per particle: the kernel's per-chunk partial sums, coefficients (3 copies), results
        return 8.0 * (self._chunks.shape[0] - 1) + 8.0 * 5 * 3 + 16.0

    def _check_per_node_memory(self, n: int, what: str) -> None:
        check_memory(8.0 * 3 * n * max(1, self._tables.n_nodes),
                     f"{type(self).__name__}.{what} on {n} parameter vectors "
                     f"x {self._tables.n_nodes} nodes", "evaluate fewer at a time")

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
        self._check_per_node_memory(theta.shape[0], "node_terms")
        return self._terms(theta, per_node=True)

    def residuals(self, theta: Any, kind: str = "inverse") -> np.ndarray:
        """Per-node error vector for least squares (7.10-7.12).

        ``kind`` is one of :data:`mrfpe.brdf.targets.residuals.RESIDUAL_KINDS`
        (``"inverse"`` 7.10, ``"one_minus"`` 7.11, ``"sqrt"``; see that module).
        LM minimises ``sum_i eps_i^2`` (7.3.2). Rows outside the unit cube get
        ``+inf`` residuals.

        Returns
        -------
        ndarray
            (N, n_nodes), or (n_nodes,) for a single (d,) vector.
        """
        check_kind(kind)
        single = np.ndim(theta) == 1
        theta = as_theta_batch(theta, self.ndim)
        self._check_per_node_memory(theta.shape[0], "residuals")
        out = np.full((theta.shape[0], self._tables.n_nodes), np.inf)
        inside = self.in_bounds(theta)
        if inside.any() and self._tables.n_nodes:
            out[inside] = transform(self._terms(theta[inside], per_node=True), kind)
        return out[0] if single else out

    @property
    def compiled_kernels(self) -> tuple:
        """The engine's main numba kernels (:func:`mrfpe.samplers.kit.warm.kernels_cached`)."""
        from mrfpe.brdf.engine import compiled_kernels

        return compiled_kernels()

    @property
    def residual_jacobian(self) -> bool:
        """Whether :meth:`residuals_and_jacobians` is available (the lean kernels' tables)."""
        from mrfpe.brdf.targets import jacobian

        return jacobian.supports(self)

    def residuals_and_jacobians(self, thetas: Any, kind: str = "inverse",
                                ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`residuals` at K points (K, d) and their Jacobians (K, n, d), in one pass
        (:func:`mrfpe.brdf.targets.jacobian.residuals_and_jacobians`)."""
        from mrfpe.brdf.targets import jacobian

        return jacobian.residuals_and_jacobians(self, np.asarray(thetas, dtype=np.float64),
                                                kind)

    @classmethod
    def check_data(cls, data: Any) -> None:
        """Refuse anything but a scene, naming the target (:func:`mrfpe.targets.get`)."""
        from mrfpe.brdf.scene import Scene

        if not isinstance(data, Scene):
            raise ValueError(f"data must be an mrfpe.brdf.scene.Scene for target "
                             f"{cls.name or cls.__name__!r}; got {type(data).__name__}")

    # -- sub-lattices ------------------------------------------------------------------------
    def partition(self, k: int, kind: str = "strided") -> list[BRDFTarget]:
        """Split into ``k`` sub-lattice targets whose log_probs sum to this one's.

        ``kind="strided"``: ``S^n = {n, n+k, ...}`` over this target's nodes (5.68,
        7.8); ``"block"``: ``k`` contiguous runs of nodes (5.67). Each part holds
        only its own nodes' precomputed entries and has ``cost`` = its share of
        the full lattice's nodes.
        """
        groups = split_ids(np.arange(self._tables.n_nodes), k, kind,
                           what="the target's nodes")
        return [self._subset(g) for g in groups]

    def codings(self) -> list[BRDFTarget]:
        """Sub-targets over Besag's codings of this target's nodes (:meth:`Lattice.codings`).

        Their log_probs sum to this one's; each is a coding likelihood.
        """
        local = {int(g): i for i, g in enumerate(self.nodes)}
        parts = [np.array([local[int(g)] for g in cls if int(g) in local], dtype=np.int64)
                 for cls in self.scene.lattice.codings()]
        return [self._subset(p) for p in parts if p.size]

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
                "fingerprint": fingerprint(sc),
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
