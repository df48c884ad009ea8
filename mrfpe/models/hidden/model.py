"""A hidden Markov random field: a declared discrete MRF over labels, seen through an emission.

``models.hidden(mrf, emission)`` declares the joint

    ``p(x, y | θ, φ) = p(x | θ) prod_i p(y_i | x_i, φ)``

of labels ``x`` from any declared discrete MRF (:class:`~mrfpe.models.discrete.MRF`:
lattices of any neighbourhood, general graphs, covariates) and observations ``y``
independent given the labels (:mod:`mrfpe.models.emissions`): the hidden Potts model
of image segmentation (Besag 1986; Marin & Robert 2014, ch. 8; Moores et al. 2015,
2020). Its parameters are the MRF's (``coupling``, ``field_1``, ...) then the
emission's (``mean_0`` ... ``sd``). :meth:`HiddenModel.simulate` draws ``(x, y)``;
:meth:`HiddenModel.target` builds the :class:`~mrfpe.models.hidden.target.HiddenTarget`
of one image, which the ``hidden`` sampler turns into a posterior over every free
parameter and the labels.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from mrfpe.models.base import Model
from mrfpe.models.discrete import MRF
from mrfpe.models.emissions.base import Emission
from mrfpe.models.graph import LatticeSpec
from mrfpe.models.hidden.checks import (
    check_fixed,
    check_names,
    check_observations,
    check_support,
    split_covariates,
)
from mrfpe.models.hidden.target import METHODS, HiddenTarget
from mrfpe.models.options import bounds_option
from mrfpe.targets.options import Option, choice_check, optional
from mrfpe.validation import check_seed

__all__ = ["HiddenModel", "hidden"]


def _mapping(name: str, value: Any) -> Any:
    if value is not None and not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a mapping parameter name -> value; got "
                         f"{type(value).__name__}")
    return None if value is None else dict(value)


HIDDEN_OPTIONS: tuple[Option, ...] = (
    Option("method", " | ".join(repr(m) for m in METHODS), "pl", choice_check(*METHODS),
           "how the sampler draws the MRF's parameters given the labels: pl (Besag's "
           "pseudolikelihood; a pseudo-posterior), pl_adjusted (calibrated), exchange "
           "(auxiliary labels by the MRF's simulator), surrogate (pre-computed Gaussian "
           "synthetic likelihood of the sufficient statistics)"),
    Option("fixed", "mapping name -> value | None", None, _mapping,
           "known parameters, held at these values"),
    Option("bounds", "mapping name -> (low, high) | None", None, _mapping,
           "a parameter's flat prior (default: the MRF's bounds; the emission's stated prior)"),
    Option("mask", "bool array of y's shape | None", None, lambda n, v: v,
           "True where the observation is missing (integrated over)"),
    Option("covariates", "mapping name -> array | None", None, optional(_mapping),
           "the MRF's node/edge covariates and the emission's (e.g. a Poisson exposure)"),
    Option("surrogate", "Surrogate | None", None, lambda n, v: v,
           "method='surrogate': a pre-computed surrogate (mrfpe.models.hidden."
           "build_surrogate; reusable for every image of the same shape); None: the "
           "sampler builds one from its seed"),
)


class HiddenModel(Model):
    """A discrete MRF over hidden labels and an emission for the data (module docstring).

    Parameters
    ----------
    mrf : MRF
        Any declared discrete MRF (:class:`mrfpe.models.MRF`, e.g. ``models.potts(3)``).
    emission : Emission
        ``p(y_i | x_i)`` (:mod:`mrfpe.models.emissions`).
    """

    estimators = ("hidden",)
    estimator_options: ClassVar[dict] = {"hidden": HIDDEN_OPTIONS}

    def __init__(self, mrf: MRF, emission: Emission) -> None:
        if not isinstance(mrf, MRF):
            raise ValueError(f"mrf must be a declared discrete MRF (mrfpe.models.MRF, e.g. "
                             f"models.potts(3)); got {type(mrf).__name__}")
        if not isinstance(emission, Emission):
            raise ValueError(f"emission must be an mrfpe.models.emissions Emission (e.g. "
                             f"models.emissions.gaussian()); got {type(emission).__name__}")
        self.mrf, self.emission = mrf, emission
        self.name = f"hidden({mrf.name}, {emission.name})"

    @property
    def n_states(self) -> int:
        return self.mrf.n_states

    def param_names(self, covariates: Mapping[str, Any] | None = None,
                    shape: Any = None) -> tuple[str, ...]:
        """The MRF's parameter names, then the emission's."""
        mrf_cov, _ = split_covariates(covariates, self.emission.covariate_names)
        return (*self.mrf.param_names(mrf_cov or None, shape),
                *self.emission.param_names(self.n_states))

    def n_codings(self, shape: Any = None) -> int:
        return self.mrf.n_codings(shape)

    def simulate(self, theta: Any, shape: Any = None, *, seed: int | None = None,
                 covariates: Mapping[str, Any] | None = None, method: str = "auto",
                 n_sweeps: int = 200) -> tuple[np.ndarray, np.ndarray]:
        """Draw labels ``x`` from the MRF and observations ``y`` from the emission.

        Parameters
        ----------
        theta : every parameter, the MRF's then the emission's (:meth:`param_names`)
        shape : ``(H, W)`` on a lattice (ignored on a fixed graph)
        seed : every random number derives from it
        covariates : the MRF's and the emission's
        method, n_sweeps : the MRF simulator's (:meth:`mrfpe.models.MRF.simulate`)

        Returns
        -------
        ``(x, y)``: int64 labels and float64 observations, each ``(H, W)`` on a lattice,
        ``(n_nodes,)`` on a fixed graph.
        """
        rng = np.random.default_rng(check_seed(seed))
        mrf_cov, em_cov = split_covariates(covariates, self.emission.covariate_names)
        names = self.param_names(covariates, shape)
        th = np.asarray(theta, dtype=np.float64).reshape(-1)
        if th.shape != (len(names),) or not np.all(np.isfinite(th)):
            raise ValueError(f"theta must be {len(names)} finite numbers {names}; got "
                             f"{np.asarray(theta).tolist()}")
        d = len(names) - len(self.emission.param_names(self.n_states))
        x = self.mrf.simulate(th[:d], shape, seed=int(rng.integers(2**63)),
                              covariates=mrf_cov or None, method=method, n_sweeps=n_sweeps)[0]
        y = self.emission.simulate(x.reshape(-1), th[d:], rng, em_cov).reshape(x.shape)
        return x, y

    def _build(self, estimator: str, data: Any, options: dict[str, Any]) -> HiddenTarget:
        mrf_cov, em_cov = split_covariates(options["covariates"],
                                           self.emission.covariate_names)
        shape = np.shape(data)[-2:] if isinstance(self.mrf.graph_spec, LatticeSpec) else None
        if shape is not None and np.ndim(data) != 2:
            raise ValueError(f"y must be an image (H, W) for the hidden model {self.name!r} on "
                             f"a lattice; got shape {np.shape(data)}")
        design, mrf_names, mrf_bounds = self.mrf.compile(shape, mrf_cov or None)
        g = design.graph
        node_shape = g.shape if g.shape is not None else (g.n_nodes,)
        y, observed = check_observations(data, node_shape, options["mask"], self.name)
        self.emission.check_y(y, observed)
        check_support(y, observed, self.n_states, self.emission.data_kind)
        names = (*mrf_names, *self.emission.param_names(self.n_states))
        bounds = check_names("bounds", options["bounds"], names)
        mrf_bounds = np.array(mrf_bounds, dtype=np.float64)
        em_bounds = {}
        for key, value in bounds.items():
            lo, hi = bounds_option(f"bounds[{key!r}]", [value])[0]
            if key in mrf_names:
                mrf_bounds[mrf_names.index(key)] = (lo, hi)
            else:
                em_bounds[key] = (float(lo), float(hi))
        bound = self.emission.bind(self.n_states, y, observed, em_cov, em_bounds)
        fixed = check_fixed(options["fixed"], names)
        for key, v in fixed.items():
            if key in mrf_names:
                lo, hi = mrf_bounds[mrf_names.index(key)]
                if not lo <= v <= hi:
                    raise ValueError(f"fixed[{key!r}] = {v:g} lies outside its bounds "
                                     f"[{lo:g}, {hi:g}]")
        bound.check_fixed({k: v for k, v in fixed.items() if k not in mrf_names})
        return HiddenTarget(model=self, design=design, emission=bound, y=y, observed=observed,
                            node_shape=tuple(node_shape), mrf_names=tuple(mrf_names),
                            mrf_bounds=mrf_bounds, fixed=fixed, method=options["method"],
                            surrogate=options["surrogate"])

    def describe(self) -> dict:
        return {**super().describe(), "mrf": self.mrf.describe(),
                "emission": self.emission.describe()}

    def __repr__(self) -> str:
        return f"HiddenModel(mrf={self.mrf!r}, emission={self.emission!r})"


def hidden(mrf: MRF, emission: Emission) -> HiddenModel:
    """A hidden MRF: labels from ``mrf``, observations from ``emission`` (:class:`HiddenModel`)."""
    return HiddenModel(mrf, emission)
