"""A generic MRF that is not about BRDFs: the auto-logistic Ising / Potts model.

Sites of an H x W grid take one of ``q`` states; each site interacts with its
four (first-order, Ising) neighbours (6.2, Fig. 6.2). The Gibbs distribution
(4.3-4.5 with T = 1) is

    ``p(x | theta) = exp(J S_J(x) + sum_{a>=1} h_a S_a(x)) / Z(theta)``,

``S_J`` the number of neighbouring pairs in equal states, ``S_a`` the number
of sites in state ``a`` (state 0 is the reference, ``h_0 = 0``). Parameters
``theta = (J, h_1, ..., h_{q-1})``: ``("coupling", "field")`` for ``q = 2``
and ``("coupling", "field_1", ...)`` for ``q > 2``. For ``q = 2`` this is the
Ising model: with spins ``s = 2x - 1``, ``delta(x_i, x_j) = (1 + s_i s_j)/2``
and ``[x_i = 1] = (1 + s_i)/2``, so ``J S_J + h S_1`` equals
``J/2 sum_<ij> s_i s_j + h/2 sum_i s_i`` up to a constant (coupling ``J/2``
and field ``h/2`` in the spin convention; the critical coupling of the
infinite square lattice, ``log(1 + sqrt 2)/2 = 0.4407`` in spins, is
``J = 0.8814`` here).

* :class:`PottsPseudoLikelihood`: Besag's pseudolikelihood (4.23-4.24) of one
  or more observed configurations, ``sum_i log p(x_i | x_N_i)`` with
  ``p(x_i = a | x_N_i) ∝ exp(J n_i(a) + h_a)`` and ``n_i(a)`` the neighbours
  of ``i`` in state ``a``. The per-site terms depend only on
  ``(n_i(.), x_i)``, so the target keeps the distinct rows and their counts:
  its cost does not grow with the lattice.
* :class:`PottsExactLikelihood`: the exact log-likelihood, with ``log Z``
  by enumeration or variable elimination (narrow lattices).

Both are the short forms (``mrfpe.targets.get("potts", x)``) of the declared
model ``mrfpe.models.potts(q, 4)``'s ``"pl"`` and ``"exact"`` estimators; the
model also offers codings, block pseudolikelihood, other neighbourhoods and
covariates (:mod:`mrfpe.models`).

* :func:`gibbs_sample`: configurations drawn at known parameters by
  checkerboard Gibbs sweeps, reproducible from ``seed``.

A student can draw data at known parameters, then compare the PL maximiser
(:func:`mrfpe.targets.maximise`) or a sampler's PL posterior with exact ML.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from mrfpe.models.estimators import ConditionalTarget, ExactTarget
from mrfpe.targets.options import Option, optional
from mrfpe.validation import check_seed

__all__ = [
    "PottsExactLikelihood",
    "PottsPseudoLikelihood",
    "gibbs_sample",
    "param_names",
    "sufficient_statistics",
]

def param_names(n_states: int) -> tuple[str, ...]:
    """Parameter names of the q-state model."""
    if n_states == 2:
        return ("coupling", "field")
    return ("coupling", *(f"field_{a}" for a in range(1, n_states)))


def _default_bounds(n_states: int) -> np.ndarray:
    return np.array([[-2.0, 2.0]] + [[-3.0, 3.0]] * (n_states - 1))


#: Most states a Potts target takes: it has one parameter per state, and its per-site
#: one-hot counts grow with them (far beyond any model a sampler can explore).
MAX_STATES = 1024


def _check_states(n_states: Any) -> int:
    if isinstance(n_states, bool) or not isinstance(n_states, int | np.integer) \
            or not 2 <= n_states <= MAX_STATES:
        raise ValueError(f"n_states must be an integer in [2, {MAX_STATES}]; got {n_states!r}")
    return int(n_states)


def _configs(x: Any, n_states: int | None, name: str = "configurations") -> tuple[np.ndarray, int]:
    """Validate (H, W) or (M, H, W) integer states; return (M, H, W) int64 and q."""
    arr = np.asarray(x)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold integer states; got dtype {arr.dtype}")
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or min(arr.shape) < 1:
        raise ValueError(f"{name} must have shape (H, W) or (M, H, W); got {np.shape(x)}")
    # range first, in the data's own type: a cast of 1e19 to int64 wraps around
    lo, hi = arr.min(), arr.max()
    if arr.dtype.kind == "f" and not (np.all(np.isfinite(arr)) and np.all(arr == np.round(arr))):
        raise ValueError(f"{name} must hold integer states; got non-integer values of dtype "
                         f"{arr.dtype}")
    top = MAX_STATES - 1 if n_states is None else _check_states(n_states) - 1
    if lo < 0 or hi > top:
        limit = (f"n_states={top + 1}" if n_states is not None
                 else f"at most {MAX_STATES} states")
        raise ValueError(f"{name} must lie in [0, {top}] ({limit}); "
                         f"got values in [{lo.item()!r}, {hi.item()!r}]")
    arr = arr.astype(np.int64)
    q = max(2, int(hi) + 1) if n_states is None else top + 1
    return arr, q


def _bounds(bounds: Any, q: int) -> np.ndarray:
    if bounds is None:
        return _default_bounds(q)
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (q, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
        raise ValueError(f"bounds must be a finite ({q}, 2) array with lower < upper; "
                         f"got {np.asarray(bounds).tolist()}")
    return b


def _check_n_states(name: str, value: Any) -> int:
    return _check_states(value)


def _check_bounds_value(name: str, value: Any) -> np.ndarray:
    try:
        b = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite (q, 2) array; got {value!r}") from None
    if b.ndim != 2 or b.shape[1] != 2:
        raise ValueError(f"{name} must be a finite (q, 2) array; got shape {b.shape}")
    return b


#: Options of the Potts targets (the shape of ``bounds`` is checked against ``q`` later).
POTTS_OPTIONS: tuple[Option, ...] = (
    Option("n_states", "int >= 2 | None", None, optional(_check_n_states),
           "q; inferred as max(state) + 1 (at least 2) if None"),
    Option("bounds", "(q, 2) array | None", None, optional(_check_bounds_value),
           "sampling-space bounds of (coupling, fields); default [-2, 2] and [-3, 3]"),
)


def sufficient_statistics(x: Any, n_states: int) -> np.ndarray:
    """``(S_J, S_1, ..., S_{q-1})`` of each configuration, (M, q) float64."""
    x = np.asarray(x)
    if x.ndim == 2:
        x = x[None]
    sj = (x[:, 1:, :] == x[:, :-1, :]).sum(axis=(1, 2)) + (x[:, :, 1:] == x[:, :, :-1]).sum(
        axis=(1, 2))
    sa = [(x == a).sum(axis=(1, 2)) for a in range(1, n_states)]
    return np.stack([sj, *sa], axis=1).astype(np.float64)


def _check_configurations(cls: type, data: Any) -> None:
    """Refuse a scene-like object (one with ``observed_labels``), pointing at its labels."""
    if not isinstance(data, np.ndarray) and hasattr(data, "observed_labels"):
        raise ValueError(f"data must be observed (H, W) or (M, H, W) integer configurations "
                         f"for target {cls.name!r}, not a {type(data).__name__} "
                         f"(e.g. scene.observed_labels)")


def _model_target(self: Any, estimator: str, configurations: Any, n_states: int | None,
                  bounds: Any, **options: Any) -> None:
    """Build ``self`` as the 4-neighbour Potts model's ``estimator`` target (the model door)."""
    from mrfpe.models.library import potts

    x, q = _configs(configurations, n_states)
    built = potts(q, 4).target(estimator, x if x.shape[0] > 1 else x[0],
                               bounds=_bounds(bounds, q), **options)
    vars(self).update(vars(built))
    self.name = type(self).name
    self.n_states = q
    self.configurations = x


class PottsPseudoLikelihood(ConditionalTarget):
    """Pseudolikelihood of observed Potts/Ising configurations (4.23-4.24).

    The short form of ``mrfpe.models.potts(q, 4).target("pl", x)``: the same
    distinct-row evaluation (:mod:`mrfpe.models.design`).

    Parameters
    ----------
    configurations : (H, W) or (M, H, W) int
        Observed configuration(s) (independent draws; their PLs add up).
    n_states : int, optional
        ``q``; inferred as ``max(state) + 1`` (at least 2) if omitted.
    bounds : (q, 2), optional
        Sampling-space bounds of (coupling, fields); default coupling in [-2, 2],
        fields in [-3, 3]. The sampling space is the natural one (``to_natural``
        is the identity).
    """

    name = "potts"
    #: The options this target accepts (:mod:`mrfpe.targets.options`).
    option_specs: ClassVar[tuple[Option, ...]] = POTTS_OPTIONS
    #: What :func:`mrfpe.targets.get` passes as the first argument.
    data_kind: ClassVar[str] = "configurations"
    check_data = classmethod(_check_configurations)

    def __init__(self, configurations: Any, n_states: int | None = None,
                 bounds: Any = None) -> None:
        _model_target(self, "pl", configurations, n_states, bounds)


class PottsExactLikelihood(ExactTarget):
    """Exact log-likelihood ``sum_m log p(x_m | theta)``, ``log Z`` by enumeration or elimination.

    The short form of ``mrfpe.models.potts(q, 4).target("exact", x)``
    (:mod:`mrfpe.models.exact`). Parameters as :class:`PottsPseudoLikelihood`.
    """

    name = "potts_exact"
    option_specs: ClassVar[tuple[Option, ...]] = POTTS_OPTIONS
    data_kind: ClassVar[str] = "configurations"
    check_data = classmethod(_check_configurations)

    def __init__(self, configurations: Any, n_states: int | None = None,
                 bounds: Any = None) -> None:
        _model_target(self, "exact", configurations, n_states, bounds)


def gibbs_sample(theta: Any, shape: tuple[int, int], n_states: int = 2, *, n_samples: int = 1,
                 n_sweeps: int = 200, thin: int = 10, seed: int | None = None,
                 init: Any = "random") -> np.ndarray:
    """Draw Potts/Ising configurations at known parameters by Gibbs sampling.

    The short form of ``mrfpe.models.potts(n_states, 4).simulate(theta, shape,
    n=n_samples, method="gibbs", ...)``: checkerboard sweeps in numba (the
    sites of one colour are conditionally independent given the other colour),
    each drawing ``p(x_i = a | x_N_i) ∝ exp(J n_i(a) + h_a)``.

    Parameters
    ----------
    theta : (q,)
        ``(coupling, field_1, ..., field_{q-1})``.
    shape : (H, W)
    n_states : int
    n_samples : int
        Configurations returned: the state after ``n_sweeps`` burn-in sweeps,
        then every ``thin`` sweeps.
    n_sweeps, thin : int
    seed : int or None
        Every random draw comes from ``numpy.random.default_rng(seed)``.
    init : "random" | (H, W) int
        Starting configuration.

    Returns
    -------
    (n_samples, H, W) int64
    """
    from mrfpe.models.library import potts

    q = _check_states(n_states)
    th = np.asarray(theta, dtype=np.float64).reshape(-1)
    if th.shape != (q,) or not np.all(np.isfinite(th)):
        raise ValueError(f"theta must be {q} finite numbers {param_names(q)}; got "
                         f"{np.asarray(theta).tolist()}")
    for name, val, low in (("n_samples", n_samples, 1), ("n_sweeps", n_sweeps, 0),
                           ("thin", thin, 1)):
        if isinstance(val, bool) or not isinstance(val, int | np.integer) or val < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {val!r}")
    return potts(q, 4).simulate(th, shape, n=int(n_samples), seed=check_seed(seed),
                                method="gibbs", n_sweeps=int(n_sweeps), thin=int(thin), init=init)
