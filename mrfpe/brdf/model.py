"""The thesis's BRDF MRF through the model door.

The BRDF MRF (thesis ch. 4-6) has corner-vertex nodes labelled with depths
and potentials that are not log-linear in the BRDF parameters: its targets
are the fused-kernel pseudolikelihoods of :mod:`mrfpe.brdf.targets.pseudolikelihood`.
:class:`BRDFModel` offers them as estimators of one declared model, so that
``models.get("brdf").target("pl", scene)`` and ``mrfpe.targets.get("pl",
scene)`` build the very same target, and adds Besag's coding estimator on the
node lattice's four codings (:meth:`mrfpe.brdf.lattice.Lattice.codings`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from mrfpe.brdf.label_render import data_terms, draw_features
from mrfpe.brdf.simulate import (
    DEFAULT_SWEEPS,
    DEFAULT_THIN,
    PRIORS,
    _energies,
    _unary_energies,
    label_field,
    simulate_labels,
)
from mrfpe.brdf.simulate import _as_labellings as _labellings
from mrfpe.brdf.targets import reflectance
from mrfpe.brdf.targets.brdf_target import COMMON_OPTIONS
from mrfpe.brdf.targets.pseudolikelihood import (
    PL,
    PL2,
    PL3,
    PLS,
    CompositeMarginalLikelihood,
    ImageFit,
)
from mrfpe.budget import check_memory
from mrfpe.models.base import Model
from mrfpe.models.options import PL_ADJUSTED_OPTIONS
from mrfpe.targets.base import Target, as_theta_batch
from mrfpe.targets.options import Option, choice_check, number_check, resolve_options
from mrfpe.validation import check_positive_int

__all__ = ["BRDFLikelihood", "BRDFModel"]

_CLASSES = {"pl": PL, "pl2": PL2, "pl3": PL3, "pls": PLS, "fit": ImageFit,
            "pml": CompositeMarginalLikelihood}


def _coding_index(name: str, value: Any) -> int:
    return check_positive_int(name, value, minimum=0)


#: Options of the joint p(x | theta) (:func:`mrfpe.brdf.simulate.label_field`).
_FIELD_OPTIONS = (
    *(o for o in COMMON_OPTIONS if o.name in ("sigma_b", "data_term")),
    Option("prior", "'none' | 'range' | 'beliefs'", "none", choice_check(*PRIORS),
           "unary energy: none (pl), range prior 7.4 (pls) or beliefs 6.60 (pl3)"),
    Option("prior_weight", "float >= 0", 1.0, number_check(0.0), "weight of the range prior"),
    Option("temperature", "float > 0", 1.0, number_check(0.0, low_open=True), "T of 6.60"),
)
_LIKELIHOOD_OPTIONS = (*_FIELD_OPTIONS, Option(
    "n_sweeps", "int >= 1", DEFAULT_SWEEPS, lambda n, v: check_positive_int(n, v),
    "Gibbs sweeps per auxiliary draw"))


def _joint_pl(scene: Any, field: dict[str, Any]) -> Target:
    cls, extra = {"none": (PL, {}), "range": (PLS, {"prior_weight": field["prior_weight"]}),
                  "beliefs": (PL3, {"temperature": field["temperature"]})}[field["prior"]]
    return cls(scene, sigma_b=field["sigma_b"], data_term=field["data_term"], **extra)


class BRDFLikelihood(Target):
    """``-U(x; theta)``, the observed labelling's log-likelihood without ``-log Z(theta)``.

    ``U`` is :func:`mrfpe.brdf.simulate.label_energy`; with :meth:`simulate`
    and :meth:`unnormalised` this is the likelihood interface of the exchange
    sampler and of :mod:`mrfpe.models.calibration` (one observed labelling). Its
    ``log_prob`` is not a density over theta (``normalised = False``).
    """

    calibrated = True

    normalised = False
    data_kind = "scene"
    n_observations = 1

    def __init__(self, scene: Any, *, n_sweeps: int = DEFAULT_SWEEPS, **options: Any) -> None:
        self.field = label_field(scene, **options)
        self.scene, self.options = scene, dict(options)
        self.param_names = tuple(scene.model.param_names)
        self.bounds = np.array([[0.0, 1.0]] * scene.model.d)
        self.name = "brdf:likelihood"
        self.n_sweeps = check_positive_int("n_sweeps", n_sweeps)
        self.x = scene.observed_labels.reshape(1, -1).copy()

    def unnormalised(self, theta: Any, x: Any = None) -> np.ndarray:
        """``-sum_k U(x_k; theta_j)`` (N,) for labellings ``x`` (default the observed one);
        ``-inf`` outside the unit cube."""
        x = _labellings(self.field, self.x if x is None else x, "x")[0]  # (M, n_nodes)
        rows, coef, out = self._coefficients(theta)
        if rows.size:  # the labellings' geometry once, every parameter vector's radiance
            out[rows] = -_energies(self.field, coef, x).sum(axis=1)
        return out

    def _coefficients(self, theta: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows of ``theta`` inside the unit cube with finite radiance coefficients, their
        coefficients, and an output of ``-inf`` (N,) for the others."""
        theta = as_theta_batch(theta, self.ndim)
        out = np.full(theta.shape[0], -np.inf)
        rows = np.flatnonzero(self.in_bounds(theta))
        model = self.scene.model
        coef = reflectance.coefficients(model, model.to_natural(theta[rows]))
        ok = np.all(np.isfinite(coef), axis=1)
        return rows[ok], coef[ok], out

    def log_f_of_draws(self, y: Any) -> Callable[[Any], np.ndarray]:
        """``theta (N, d) -> -U(y_k; theta_j)`` (N, K) for labellings ``y`` reused at many theta.

        Each labelling's theta-independent render is kept
        (:func:`~mrfpe.brdf.label_render.draw_features`, ``40 n_triangles`` bytes per
        labelling), so a parameter vector costs one exponential per triangle and
        labelling (the Monte Carlo MLE's hook, :mod:`mrfpe.models.calibration`).
        """
        x = _labellings(self.field, y, "y")[0]
        check_memory(40.0 * x.shape[0] * self.field.tri.shape[0],
                     f"the renders of {x.shape[0]} labellings", "pass fewer draws")
        feats = draw_features(self.field, x).reshape(-1, 5)
        unary, K = _unary_energies(self.field, x), x.shape[0]

        def log_f(theta: Any) -> np.ndarray:
            rows, coef, first = self._coefficients(theta)
            out = np.repeat(first[:, None], K, axis=1)
            for j, c in zip(rows, coef, strict=True):  # one row at a time: K n_tri floats each
                rad = reflectance.radiance(c[None], feats).reshape(1, K, -1)
                out[j] = -(data_terms(self.field, rad)[0].sum(axis=1) + unary)
            return out

        return log_f

    def _row_bytes(self) -> float:
        return 8.0 * 4 * (self.field.tri.shape[0] + self.field.n_nodes)

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return self.unnormalised(theta)

    def simulate(self, theta: Any, n: int | None = None, *, seed: Any = None,
                 init: Any = "data", n_sweeps: int | None = None,
                 thin: int = DEFAULT_THIN) -> np.ndarray:
        """Labellings at ``theta`` (n, H+1, W+1): ``n_sweeps`` (default the target's) of
        burn-in from ``init`` (``"data"``: the observed labelling), then one draw
        every ``thin`` sweeps (:func:`~mrfpe.brdf.simulate.simulate_labels`)."""
        th = as_theta_batch(theta, self.ndim)
        if th.shape[0] != 1:
            raise ValueError(f"theta must be one parameter vector; got {th.shape[0]}")
        start = "observed" if isinstance(init, str) and init == "data" else init
        return simulate_labels(self.field, th[0], 1 if n is None else n, seed=seed,
                               init=start, thin=thin,
                               n_sweeps=self.n_sweeps if n_sweeps is None else n_sweeps)

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__, "model": "brdf",
                "estimator": "likelihood", "param_names": list(self.param_names),
                "bounds": self.bounds.tolist(), "n_sweeps": self.n_sweeps,
                "options": {**self.options, "sigma_b": self.field.sigma_b},
                "scene": {"shape": list(self.scene.shape), "n_labels": self.scene.n_labels,
                          "brdf": self.scene.brdf}}


class BRDFModel(Model):
    """The BRDF MRF of the thesis, whose data are a Scene (depth labels and an image).

    Estimators: ``pl`` (4.23-4.24, 5.64-5.66), ``pl2`` (6.54-6.59), ``pl3``
    (6.60-6.62), ``pls`` (7.5-7.7), ``fit`` and ``pml`` (beyond the thesis),
    ``coding``: the PL summed over one of the node lattice's four codings, and,
    from the label simulator (:meth:`simulate`), ``likelihood``
    (:class:`BRDFLikelihood`, for the exchange sampler) and ``pl_adjusted`` (the
    ``pl``, ``pls`` or ``pl3`` of the simulated joint, per ``prior``, calibrated by
    :class:`mrfpe.models.calibration.AdjustedPL`).
    """

    name = "brdf"
    estimators = (*_CLASSES, "coding", "likelihood", "pl_adjusted")
    estimator_options: ClassVar[dict[str, tuple[Option, ...]]] = {
        **{k: tuple(c.option_specs) for k, c in _CLASSES.items()},
        "coding": (*PL.option_specs, Option("coding", "int in 0..3", 0, _coding_index,
                                            "which of the node lattice's four codings")),
        "likelihood": _LIKELIHOOD_OPTIONS,
        "pl_adjusted": (*_LIKELIHOOD_OPTIONS, *PL_ADJUSTED_OPTIONS)}

    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> Target:
        if estimator in ("likelihood", "pl_adjusted"):
            return self._build_likelihood(estimator, data, options)
        if estimator != "coding":
            return _CLASSES[estimator](data, **options)
        k = options.pop("coding")
        parts = PL(data, **options).codings()
        if k >= len(parts):
            raise ValueError(f"coding must be in [0, {len(parts) - 1}]; got {k}")
        return parts[k]

    def _build_likelihood(self, estimator: str, scene: Any, options: dict[str, Any]) -> Target:
        field = {k: options.pop(k) for k in [o.name for o in _LIKELIHOOD_OPTIONS]}
        lik = BRDFLikelihood(scene, **field)
        if estimator == "likelihood":
            return lik
        from mrfpe.models.calibration import AdjustedPL

        field.pop("n_sweeps")
        return AdjustedPL(_joint_pl(scene, field), lik, **options)

    def joint_pl(self, scene: Any, /, **options: Any) -> Target:
        """The pseudolikelihood whose conditionals are those of the simulated joint
        p(x | theta): ``pl``, ``pls`` or ``pl3`` per ``prior`` (the PL ``"pl_adjusted"``
        calibrates, e.g. for :meth:`mrfpe.models.calibration.AdjustedPL.restore`).

        Parameters
        ----------
        scene : mrfpe.brdf.scene.Scene
        **options
            The joint's options, with the defaults of ``"likelihood"`` and
            ``"pl_adjusted"``: ``sigma_b``, ``data_term``, ``prior``, ``prior_weight``,
            ``temperature``.
        """
        return _joint_pl(scene, resolve_options(f"{self.name} joint_pl", _FIELD_OPTIONS,
                                                options))

    def param_names(self, brdf: str = "ward") -> tuple[str, ...]:
        """Unit-cube parameters of the scene's BRDF model (``"ward"`` or ``"phong"``)."""
        from mrfpe.brdf.functions import get as get_brdf

        return tuple(get_brdf(brdf).param_names)

    def simulate(self, theta: Any, scene: Any = None, n: int = 1, *, seed: int | None = None,
                 n_sweeps: int | None = None, thin: int | None = None, init: Any = "observed",
                 progress: bool = False, shape: Any = None, **options: Any) -> np.ndarray:
        """Draw ``n`` depth labellings of ``scene`` from ``p(x | theta) ∝ exp(-U(x; theta))``.

        Gibbs sweeps over the node lattice's four codings
        (:func:`mrfpe.brdf.simulate.simulate_labels`, whose module docstring
        states the joint: the image is fixed, the labels are drawn).

        Parameters
        ----------
        theta : (d,)
            BRDF parameters in the unit cube (the targets' sampling space).
        scene : mrfpe.brdf.scene.Scene
            The data: image, camera, light and label sets (``shape`` is not enough).
        n, seed, n_sweeps, thin, init, progress
            As :func:`~mrfpe.brdf.simulate.simulate_labels` (None: its defaults).
        shape : (H, W), optional
            Accepted for the Model contract; must be the scene's image shape.
        **options
            ``data_term``, ``sigma_b``, ``prior`` (``"none"``, ``"range"``,
            ``"beliefs"``), ``prior_weight``, ``temperature``.

        Returns
        -------
        (n, H+1, W+1) int64 label indices.
        """
        if scene is None:
            raise ValueError("scene must be given: the BRDF MRF draws the labels of a scene "
                             "(its image, camera, light and label sets)")
        if shape is not None and tuple(np.atleast_1d(shape)) != tuple(scene.shape):
            raise ValueError(f"shape must be the scene's image shape {tuple(scene.shape)} (or "
                             f"None); got {shape!r}")
        return simulate_labels(scene, theta, n, seed=seed, init=init, progress=progress,
                               n_sweeps=DEFAULT_SWEEPS if n_sweeps is None else n_sweeps,
                               thin=DEFAULT_THIN if thin is None else thin, **options)

    def n_codings(self, shape: Any) -> int:
        """4 (2 x 2 codings of the ``(H+1, W+1)`` node lattice of an ``(H, W)`` image)."""
        from mrfpe.brdf.lattice import Lattice

        H, W = (int(s) for s in shape)
        return len(Lattice(H, W).codings())
