"""The emission contract: how an observation ``y_i`` depends on its hidden label ``x_i``.

A hidden Markov random field (:mod:`mrfpe.models.hidden`) is a declared discrete MRF
over labels ``x`` seen through an *emission* ``p(y_i | x_i = a, φ)``, independent
across nodes given the labels. An :class:`Emission` is the declaration, independent of
the number of states ``q`` and of the data; :meth:`Emission.bind` ties it to ``q``
states and the observed data and returns a :class:`BoundEmission`, which is what the
samplers and point estimators use:

* ``names`` and ``bounds``: the parameters (``mean_0 .. mean_{q-1}``, ``sd`` ...) and
  the support of their prior (finite);
* ``log_lik(params)``: ``(N, d) -> (N, n, q)``, the log-density of each node's
  observation under each state, batched over parameter vectors, 0 at missing nodes;
* ``log_prior(params)``: ``(N, d) -> (N,)``, ``-inf`` outside the support (and, for
  ordered emissions, where ``mean_0 < mean_1 < ...`` fails);
* ``update(params, x, rng, free)``: one draw from the full conditional of the free
  parameters given the labels (a conditionally conjugate update), or ``None`` where
  no conjugate prior exists (the sampler then takes a random walk);
* ``map_update(params, resp, free)``: the mode of the conditional given soft label
  assignments ``resp`` (n, q) (the M-step of EM; one-hot for ICM);
* ``start()``: starting parameters and labels from the data alone;
* ``prior_sample(rng)``: one draw from the prior (for Geweke's (2004) check of the
  updates, :func:`mrfpe.testing.check_emission`).

Emissions register through the ``mrfpe.emissions`` entry-point group, as samplers and
models do (:mod:`mrfpe.models.emissions.registry`).
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["BoundEmission", "Emission", "check_prior_pair", "observed_values",
           "ordered_prior_draw", "resolve_bounds"]


def check_prior_pair(name: str, value: Any, what: str) -> tuple[float, float] | None:
    """``None`` or two finite numbers, the second > 0 (and the first > 0 for a gamma-like
    prior whose ``what`` says so): a proper prior, else a one-line ValueError."""
    if value is None:
        return None
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair of numbers ({what}); got {value!r}") from None
    positive_first = "shape" in what
    if not (np.isfinite(a) and np.isfinite(b) and b > 0 and (a > 0 or not positive_first)):
        raise ValueError(f"{name} must be a proper prior: {what}, finite"
                         f"{', both > 0' if positive_first else ', the second > 0'}; got "
                         f"{value!r}")
    return a, b


def observed_values(y: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """The observations at the observed nodes (float64)."""
    return np.asarray(y, dtype=np.float64)[observed]


class BoundEmission:
    """An emission tied to ``q`` states and one data set (see the module docstring).

    Attributes
    ----------
    emission : Emission
    q : int
    y : (n,) float64, the observations (anything at missing nodes)
    observed : (n,) bool, which nodes are observed
    names : tuple of str
    bounds : (d, 2) float64, the prior's support (finite)
    flat : (d,) bool, whose prior is flat on its bounds (set by the caller's ``bounds``)
    ordered : bool, whether the per-state locations are kept increasing
    """

    conjugate: bool = False

    def __init__(self, emission: Emission, q: int, y: np.ndarray, observed: np.ndarray,
                 names: tuple[str, ...], bounds: np.ndarray, flat: np.ndarray) -> None:
        self.emission, self.q = emission, int(q)
        self.y = np.asarray(y, dtype=np.float64)
        self.observed = np.asarray(observed, dtype=bool)
        self.names = tuple(names)
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.flat = np.asarray(flat, dtype=bool)
        self.ordered = bool(emission.ordered)
        for a in (self.y, self.observed, self.bounds, self.flat):
            a.setflags(write=False)

    def _cache(self) -> None:
        """Recompute what is derived from ``y`` (subclasses: their observed values)."""

    def with_data(self, y: Any) -> BoundEmission:
        """This emission, its priors and bounds unchanged, on other observations ``y`` (n,)
        at the same nodes (for checks of the updates, e.g. Geweke's)."""
        y = np.array(y, dtype=np.float64).reshape(-1)
        if y.shape != self.y.shape:
            raise ValueError(f"y must have {self.y.size} values; got {y.shape}")
        y.setflags(write=False)
        out = copy.copy(self)
        out.y = y
        out._cache()
        return out

    @property
    def d(self) -> int:
        return len(self.names)

    # -- to be provided ---------------------------------------------------------------------
    def _log_lik_observed(self, params: np.ndarray) -> np.ndarray:  # pragma: no cover
        """``(N, n_observed, q)`` log-densities at the observed nodes (a new array)."""
        raise NotImplementedError

    def log_prior(self, params: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def update(self, params: np.ndarray, x: np.ndarray, rng: np.random.Generator,
               free: np.ndarray) -> np.ndarray | None:
        """One conditionally conjugate draw of the free parameters; ``None``: no conjugate
        update (the sampler then takes a random-walk step)."""
        return None

    def map_update(self, params: np.ndarray, resp: np.ndarray,
                   free: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def start(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def prior_sample(self, rng: np.random.Generator) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def describe_prior(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- shared ------------------------------------------------------------------------------
    def log_lik(self, params: Any) -> np.ndarray:
        """``(N, n, q)``: ``log p(y_i | x_i = a, φ)`` per parameter vector, node and state;
        0 at missing nodes (integrated over: a density integrates to 1)."""
        params = self.as_params(params)
        if self.observed.all():  # nothing to scatter (_log_lik_observed gives a new array)
            return np.ascontiguousarray(self._log_lik_observed(params), dtype=np.float64)
        out = np.zeros((params.shape[0], self.y.size, self.q))
        if self.observed.any():
            out[:, self.observed] = self._log_lik_observed(params)
        return out

    def log_lik_at(self, params: Any, x: np.ndarray) -> np.ndarray:
        """``(N,)``: ``sum_i log p(y_i | x_i, φ)`` over the observed nodes at the labels
        ``x`` (n,), per parameter vector (subclasses may skip the states not taken)."""
        x = np.asarray(x, dtype=np.int64)
        ll = self.log_lik(params)
        return ll[:, np.arange(x.size), x][:, self.observed].sum(axis=1)

    def as_params(self, params: Any) -> np.ndarray:
        """``params`` as a float64 ``(N, d)`` batch (one vector gives ``(1, d)``)."""
        p = np.asarray(params, dtype=np.float64)
        p = p[None] if p.ndim == 1 else p
        if p.ndim != 2 or p.shape[1] != self.d:
            raise ValueError(f"emission parameters must be ({self.d},) or (N, {self.d}) "
                             f"{self.names}; got shape {np.shape(params)}")
        return p

    def in_support(self, params: Any) -> np.ndarray:
        """(N,) bool: inside the bounds (and ordered, for an ordered emission)."""
        p = self.as_params(params)
        inside = np.all((p >= self.bounds[:, 0]) & (p <= self.bounds[:, 1]), axis=1)
        if self.ordered:
            loc = p[:, : self.q]
            inside &= np.all(np.diff(loc, axis=1) > 0, axis=1)
        return inside

    def counts(self, x: np.ndarray) -> np.ndarray:
        """(q,) observed nodes per state of the labelling ``x`` (n,)."""
        return np.bincount(np.asarray(x)[self.observed], minlength=self.q).astype(np.float64)

    def one_hot(self, x: np.ndarray) -> np.ndarray:
        """(n, q) indicator of the labelling ``x``."""
        out = np.zeros((self.y.size, self.q))
        out[np.arange(self.y.size), np.asarray(x, dtype=np.int64)] = 1.0
        return out

    def check_fixed(self, values: Mapping[str, float]) -> None:
        """Refuse fixed values outside the parameters' support, naming them."""
        for name, v in values.items():
            k = self.names.index(name)
            lo, hi = self.bounds[k]
            if not lo <= v <= hi:
                raise ValueError(f"fixed[{name!r}] = {v:g} lies outside its support "
                                 f"[{lo:g}, {hi:g}]")
        loc = [(self.names.index(k), v) for k, v in values.items()
               if self.ordered and self.names.index(k) < self.q]
        loc.sort()
        for (k1, v1), (k2, v2) in itertools.pairwise(loc):
            if not v1 < v2:
                raise ValueError(f"fixed {self.names[k1]} = {v1:g} and {self.names[k2]} = "
                                 f"{v2:g} break the order {self.names[0]} < {self.names[1]} < "
                                 f"... that keeps the labels from switching")


class Emission:
    """Declaration of ``p(y_i | x_i, φ)`` (see the module docstring).

    Subclasses set ``name``, ``ordered`` (whether the first ``q`` parameters are
    per-state locations kept increasing) and ``data_kind`` (``"real"``, ``"count"`` or
    ``"label"``), and implement :meth:`param_names`, :meth:`bind` and
    :meth:`simulate`.
    """

    name: str = "emission"
    ordered: bool = False
    data_kind: str = "real"
    #: Node covariates the emission reads (e.g. a Poisson exposure), by name.
    covariate_names: tuple[str, ...] = ()

    def param_names(self, q: int) -> tuple[str, ...]:  # pragma: no cover - abstract
        raise NotImplementedError

    def check_y(self, y: np.ndarray, observed: np.ndarray) -> None:
        """Refuse observations of the wrong kind at observed nodes (a one-line error).

        Non-finite values are refused by the hidden target before this is called.
        """
        if self.data_kind in ("count", "label"):
            v = np.asarray(y, dtype=np.float64)[observed]
            bad = np.flatnonzero((v < 0) | (v != np.round(v)))
            if bad.size:
                raise ValueError(f"y must hold non-negative integer {self.data_kind}s for the "
                                 f"{self.name} emission; {bad.size} observed value(s) are not, "
                                 f"e.g. {v[bad[0]]:g}")

    def bind(self, q: int, y: np.ndarray, observed: np.ndarray,
             covariates: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]],
             ) -> BoundEmission:  # pragma: no cover - abstract
        raise NotImplementedError

    def simulate(self, x: np.ndarray, params: np.ndarray, rng: np.random.Generator,
                 covariates: Mapping[str, np.ndarray] | None = None,
                 ) -> np.ndarray:  # pragma: no cover - abstract
        """Observations (n,) at labels ``x`` (n,) and parameters ``params`` (d,)."""
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__, "ordered": self.ordered,
                "data_kind": self.data_kind}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


def resolve_bounds(names: tuple[str, ...], default: np.ndarray,
                   given: Mapping[str, tuple[float, float]], domain: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(bounds, flat)``: the caller's ``given`` bounds (a flat prior there) over the
    ``default`` support, each checked to lie in the parameter's ``domain``."""
    bounds, flat = np.array(default, dtype=float), np.zeros(len(names), dtype=bool)
    for name, (lo, hi) in given.items():
        k = names.index(name)
        dlo, dhi = domain[k]
        if not (dlo <= lo < hi <= dhi):
            raise ValueError(f"bounds[{name!r}] = ({lo:g}, {hi:g}) must lie in the "
                             f"parameter's domain [{dlo:g}, {dhi:g}] with low < high")
        bounds[k], flat[k] = (lo, hi), True
    return bounds, flat


def ordered_prior_draw(draw: Callable[[int, float], float], bound: BoundEmission,
                       rng: np.random.Generator, tries: int = 10000) -> np.ndarray:
    """A prior draw of the ``q`` locations restricted to increasing order (``v_0 < v_1 < …``).

    ``draw(k, u)`` is location ``k``'s prior inverse CDF at ``u``. Where the ``q``
    priors are the same (equal bounds, all flat or none) the restricted prior is that of
    the order statistics: ``q`` i.i.d. draws, sorted. Otherwise by rejection (all ``q``
    redrawn until ordered), refusing after ``tries``.
    """
    q = bound.q
    if not bound.ordered:
        return np.array([draw(k, rng.random()) for k in range(q)])
    b, flat = bound.bounds[:q], bound.flat[:q]
    if np.all(b == b[0]) and np.all(flat == flat[0]):
        return np.sort([draw(k, rng.random()) for k in range(q)])
    for _ in range(tries):
        v = np.array([draw(k, rng.random()) for k in range(q)])
        if np.all(np.diff(v) > 0):
            return v
    raise ValueError("could not draw ordered locations from the prior: their bounds leave "
                     "almost no ordered configuration")
