"""The distance contract shared by built-ins and plugins.

A distance is a plain class, constructible with no arguments, whose instances
are called as ``d(a, b, **params) -> float`` on two posterior Datasets
(``theta(sample, param)``, ``log_weight(sample)``; DESIGN.md). The returned
value is always in *distance form*: lower = more alike. Class attributes
describe it:

``kind``
    ``"distance"`` or ``"similarity"``. Similarities (AGMMP, correlation,
    inner product) also provide ``similarity(a, b)`` and ``log_similarity(a, b)``;
    their distance form is a strictly decreasing function of the similarity,
    so nearest-neighbour rankings are the same under either.
``symmetric``
    whether ``d(a, b) == d(b, a)`` for every pair.
``params``
    the keyword parameters and their defaults.
``nonnegative``
    whether the distance form is never negative (False only for AGMMP, whose
    ``-log`` of a probability *density* can be negative).
``min_samples``
    smallest sample count accepted (2 for the covariance-based distances).
``requires_grid``
    whether both sets must sit on one shared grid (correlation, inner product).

Subclassing :class:`Distance` is optional for plugins (the registry checks the
attributes structurally) but gives input validation, parameter checking and a
:meth:`Distance.pairwise` matrix that precomputes per-posterior features once.

Input validation (:func:`as_sample_sets`) at the public boundary:

* both posteriors must be ``xarray.Dataset`` s with ``theta(sample, param)`` and
  ``log_weight(sample)``; otherwise ``ValueError``;
* their ``param`` coordinates must hold the same names. The same names in a
  different order are aligned to the first posterior's order (xarray-style);
  different names raise ``ValueError``;
* ``theta`` must be finite (NaN or infinite samples raise ``ValueError``;
  drop them before comparing), at most :data:`THETA_LIMIT` in magnitude, and
  have at least one parameter;
* NaN log weights count as ``-inf`` (as in :func:`mrfpe.posterior.normalise_log_weights`);
  a set whose every log weight is ``-inf``/NaN has zero total weight and
  raises ``ValueError`` (there is no distribution to compare);
* fewer than ``min_samples`` samples raises ``ValueError``;
* a posterior of ``kind="optima"`` (a multi-start optimiser's optima, not
  posterior draws) is accepted — the distance still computes — but one
  :class:`mrfpe.PosteriorWarning` per call names every such posterior: the number
  then compares sets of optima, not posteriors.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import xarray as xr

from mrfpe._caller import stacklevel_outside_mrfpe
from mrfpe.distances.registry import NEGATIVE_TOLERANCE
from mrfpe.resampling import check_log_weights, normalise_log_weights
from mrfpe.validation import check_bool, check_n_jobs

__all__ = ["THETA_LIMIT", "Distance", "SampleSet", "Similarity", "as_sample_sets", "check_bool"]

#: Largest |theta| a distance accepts: squared differences, covariances and their
#: determinants stay finite in float64 well beyond it (1e100² = 1e200).
THETA_LIMIT = 1e100


@dataclass(frozen=True)
class SampleSet:
    """A validated weighted sample set (what a distance sees of a posterior).

    Attributes
    ----------
    theta : (S, d) float64, finite.
    log_weight : (S,) normalised log weights (logsumexp = 0), NaN replaced by -inf.
    params : the parameter names, in the column order of ``theta``.
    source : the posterior Dataset with its ``param`` axis in that same order.
    """

    theta: np.ndarray
    log_weight: np.ndarray
    params: tuple[str, ...]
    source: xr.Dataset

    def __post_init__(self) -> None:
        # a SampleSet built directly (not through as_sample_sets) must not be degenerate
        check_log_weights(self.log_weight, f"SampleSet of {list(self.params)}")

    @property
    def weight(self) -> np.ndarray:
        """Normalised linear weights (S,), summing to 1."""
        return np.exp(self.log_weight)

    @property
    def n_samples(self) -> int:
        return int(self.theta.shape[0])


def _param_names(post: xr.Dataset, name: str) -> tuple[str, ...]:
    if "param" in post.coords:
        names = tuple(str(p) for p in post["param"].values)
    else:
        names = tuple(str(i) for i in range(post.sizes["param"]))
    if len(set(names)) != len(names):
        raise ValueError(f"{name} has repeated parameter names in its param coordinate: {names}")
    return names


def _sample_set(post: Any, name: str, min_samples: int,
                order: tuple[str, ...] | None) -> SampleSet:
    if not isinstance(post, xr.Dataset):
        raise ValueError(f"{name} must be a posterior xarray.Dataset with theta(sample, param) "
                         f"and log_weight(sample); got {type(post).__name__}")
    for var, dims in (("theta", ("sample", "param")), ("log_weight", ("sample",))):
        if var not in post:
            raise ValueError(f"{name} lacks the variable {var!r}")
        if post[var].dims != dims:
            raise ValueError(f"{name}.{var} must have dims {dims}; got {post[var].dims}")
    names = _param_names(post, name)
    if order is not None and names != order:
        if set(names) != set(order) or "param" not in post.coords:
            raise ValueError(f"posteriors have different param coordinates: the first has "
                             f"{list(order)}, {name} has {list(names)}")
        post = post.sel(param=list(order))  # same names, other order: align
        names = order
    theta = np.asarray(post["theta"].values, dtype=np.float64)
    S = theta.shape[0]
    if theta.shape[1] == 0:
        raise ValueError(f"{name} has no parameters (param has length 0); there is nothing "
                         "to compare")
    if S < max(1, min_samples):
        raise ValueError(f"{name} has {S} sample(s); this distance needs at least "
                         f"{max(1, min_samples)}")
    bad = ~np.isfinite(theta).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ValueError(f"{name}.theta has {rows.size} non-finite (NaN/inf) sample(s), "
                         f"e.g. rows {rows[:5].tolist()}; drop them before comparing")
    big = float(np.abs(theta).max()) if theta.size else 0.0
    if big > THETA_LIMIT:
        raise ValueError(f"{name}.theta has values up to {big:.3g} in magnitude; distances need "
                         f"|theta| <= {THETA_LIMIT:.0e} (their squares and covariances would "
                         "overflow): rescale the parameters")
    lw = check_log_weights(post["log_weight"].values, f"{name}.log_weight")
    return SampleSet(theta, normalise_log_weights(lw), names, post)


def as_sample_sets(posteriors: Sequence[Any], names: Sequence[str] | None = None, *,
                   min_samples: int = 1) -> list[SampleSet]:
    """Validate posteriors and align their ``param`` axes to the first one's order.

    Parameters
    ----------
    posteriors : posterior Datasets.
    names : how to call each in error messages (default ``posteriors[i]``).
    min_samples : smallest accepted sample count.

    Raises
    ------
    ValueError
        For any of the bad inputs listed in this module's docstring.
    """
    names = [f"posteriors[{i}]" for i in range(len(posteriors))] if names is None else names
    out: list[SampleSet] = []
    for post, name in zip(posteriors, names, strict=True):
        out.append(_sample_set(post, name, min_samples, out[0].params if out else None))
    optima = [n for s, n in zip(out, names, strict=True)
              if s.source.attrs.get("kind", "draws") == "optima"]
    if optima:
        import warnings

        from mrfpe.posterior.diagnostics import PosteriorWarning

        warnings.warn(f"{', '.join(optima)} {'is' if len(optima) == 1 else 'are'} of "
                      "kind='optima' (a multi-start optimiser's optima, not posterior draws): "
                      "the distance compares sets of optima, not posteriors",
                      PosteriorWarning, stacklevel=stacklevel_outside_mrfpe())
    return out


class Distance:
    """Base class of a distance between two posteriors (distance form: lower = more alike).

    Subclasses set the class attributes, implement :meth:`features` (everything
    that depends on one posterior only) and :meth:`compare` (two feature
    objects -> distance), and may override :meth:`pairwise_features` with a
    vectorised all-pairs computation.
    """

    name: ClassVar[str] = ""
    kind: ClassVar[str] = "distance"
    symmetric: ClassVar[bool] = True
    nonnegative: ClassVar[bool] = True
    params: ClassVar[Mapping[str, Any]] = {}
    min_samples: ClassVar[int] = 1
    requires_grid: ClassVar[bool] = False

    # -- parameters ------------------------------------------------------
    def resolve_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """Defaults merged with ``params``, validated (ValueError on unknown or bad values)."""
        unknown = sorted(set(params) - set(self.params))
        if unknown:
            accepted = ", ".join(self.params) or "(none)"
            raise ValueError(f"{self._label()}: unknown parameter(s) {', '.join(unknown)}; "
                             f"accepted: {accepted}")
        return self.check_params({**self.params, **params})

    def check_params(self, p: dict[str, Any]) -> dict[str, Any]:
        """Validate parameter values (override); return the dict to use."""
        return p

    def _label(self) -> str:
        return self.name or type(self).__name__

    # -- the two hooks ---------------------------------------------------
    def features(self, s: SampleSet, p: dict[str, Any]) -> Any:
        """Everything that depends on one posterior only (default: the sample set)."""
        return s

    def compare(self, fa: Any, fb: Any, p: dict[str, Any]) -> float:  # pragma: no cover
        """Distance form between two feature objects."""
        raise NotImplementedError

    def check_features(self, feats: Sequence[Any], p: dict[str, Any],
                       names: Sequence[str]) -> None:
        """Cross-posterior checks (e.g. a shared grid); raise ValueError. Default: none."""

    # -- public ----------------------------------------------------------
    def prepare(self, posteriors: Sequence[Any], names: Sequence[str] | None = None,
                **params: Any) -> tuple[list[Any], dict[str, Any]]:
        """Validate posteriors and parameters; return (features per posterior, parameters)."""
        p = self.resolve_params(params)
        names = [f"posteriors[{i}]" for i in range(len(posteriors))] if names is None else names
        sets = as_sample_sets(posteriors, names, min_samples=self.min_samples)
        feats = [self.features(s, p) for s in sets]
        self.check_features(feats, p, names)
        return feats, p

    def __call__(self, a: Any, b: Any, **params: Any) -> float:
        """Distance form between posteriors ``a`` and ``b`` (lower = more alike).

        Raises ``ValueError`` for bad inputs (module docstring), and when the
        computation breaks down (a singular matrix, a NaN result, a negative one
        beyond rounding while ``nonnegative``) rather than return a number that
        means nothing.
        """
        (fa, fb), p = self.prepare([a, b], ("a", "b"), **params)
        try:
            value = float(self.compare(fa, fb, p))
        except np.linalg.LinAlgError as exc:
            raise ValueError(f"{self._label()}: the linear algebra failed on these "
                             f"posteriors ({exc}); are their samples degenerate?") from None
        if np.isnan(value):
            raise ValueError(f"{self._label()}: the distance is NaN for these posteriors "
                             "(an overflow or a degenerate covariance)")
        if self.nonnegative and value < -NEGATIVE_TOLERANCE:
            raise ValueError(f"{self._label()}: the distance is {value!r}, negative, though "
                             f"{type(self).__name__}.nonnegative is True")
        return value

    def pairwise(self, posteriors: Sequence[Any], *, n_jobs: int = 1, progress: bool = False,
                 **params: Any) -> np.ndarray:
        """All-pairs matrix ``D[i, j] = d(posteriors[i], posteriors[j])``, diagonal included.

        Features are computed once per posterior. ``n_jobs`` and ``progress``
        apply to the generic pair loop (joblib, thread-preferring; use
        ``joblib.parallel_config(backend="loky")`` for processes); vectorised
        subclasses ignore them.
        """
        if isinstance(posteriors, xr.Dataset | str) or not hasattr(posteriors, "__iter__"):
            raise ValueError(f"posteriors must be a sequence of posterior Datasets; got "
                             f"{type(posteriors).__name__}")
        n_jobs = check_n_jobs("n_jobs", n_jobs)
        check_bool("progress", progress)
        feats, p = self.prepare(list(posteriors), **params)
        return self.pairwise_features(feats, p, n_jobs=n_jobs, progress=progress)

    def pairwise_features(self, feats: Sequence[Any], p: dict[str, Any], *, n_jobs: int = 1,
                          progress: bool = False) -> np.ndarray:
        """Generic all-pairs loop over :meth:`compare` (override to vectorise)."""
        return pair_loop(lambda i, j: self.compare(feats[i], feats[j], p), len(feats),
                         symmetric=self.symmetric, n_jobs=n_jobs, progress=progress,
                         desc=self._label())

    def score(self, d: Any) -> Any:
        """Similarity-matrix entry for distance form ``d``: ``-d`` (higher = more alike).

        Used by :func:`mrfpe.classify.similarity_matrix`. Similarities override it
        to give the similarity itself (AGMMP: its logarithm).
        """
        return -np.asarray(d, dtype=np.float64)


class Similarity(Distance):
    """Base class of a similarity (higher = more alike) that also has a distance form.

    Subclasses implement :meth:`compare` in distance form and
    :meth:`similarity_from_distance`, its strictly decreasing inverse.
    """

    kind: ClassVar[str] = "similarity"

    def similarity_from_distance(self, d: Any) -> Any:  # pragma: no cover - abstract
        """The similarity whose distance form is ``d``."""
        raise NotImplementedError

    def log_similarity_from_distance(self, d: Any) -> Any:
        """``log`` of :meth:`similarity_from_distance` (ValueError where it is negative)."""
        s = np.asarray(self.similarity_from_distance(d), dtype=np.float64)
        if np.any(s < 0):
            raise ValueError(f"{self._label()} similarity is negative ({s.min():.6g}); "
                             "its logarithm is undefined")
        with np.errstate(divide="ignore"):
            return np.log(s)

    def score(self, d: Any) -> Any:
        """Similarity-matrix entry: the similarity itself."""
        return self.similarity_from_distance(d)

    def similarity(self, a: Any, b: Any, **params: Any) -> float:
        """The similarity of ``a`` and ``b`` (higher = more alike)."""
        return float(self.similarity_from_distance(self(a, b, **params)))

    def log_similarity(self, a: Any, b: Any, **params: Any) -> float:
        """``log`` of :meth:`similarity`."""
        return float(self.log_similarity_from_distance(self(a, b, **params)))


def pair_loop(fn: Callable[[int, int], float], n: int, *, symmetric: bool, n_jobs: int = 1,
              progress: bool = False, desc: str = "") -> np.ndarray:
    """Fill an (n, n) matrix with ``fn(i, j)``; only ``i <= j`` when ``symmetric``.

    Runs serially for ``n_jobs == 1``, else through joblib (threads preferred:
    the heavy parts of the built-ins -- POT's network simplex, numpy, scipy's
    cdist -- release the GIL, and nothing is pickled). Shows a tqdm bar when
    ``progress``.
    """
    from tqdm.auto import tqdm

    pairs = [(i, j) for i in range(n) for j in range(i if symmetric else 0, n)]
    out = np.full((n, n), np.nan)
    bar = tqdm(total=len(pairs), desc=desc or "pairs", disable=not progress, leave=False)
    try:
        if n_jobs == 1 or len(pairs) <= 1:
            for i, j in pairs:
                out[i, j] = fn(i, j)
                bar.update(1)
        else:
            from joblib import Parallel, delayed, effective_n_jobs

            workers = effective_n_jobs(n_jobs)
            size = max(1, math.ceil(len(pairs) / (4 * workers)))
            chunks = [pairs[k:k + size] for k in range(0, len(pairs), size)]

            def run(chunk: list[tuple[int, int]]) -> list[tuple[int, int, float]]:
                return [(i, j, fn(i, j)) for i, j in chunk]

            results = Parallel(n_jobs=n_jobs, prefer="threads", return_as="generator_unordered")(
                delayed(run)(c) for c in chunks)
            for res in results:
                for i, j, v in res:
                    out[i, j] = v
                bar.update(len(res))
    finally:
        bar.close()
    if symmetric:
        iu = np.triu_indices(n, 1)
        out[iu[1], iu[0]] = out[iu]
    return out
