"""A general emission from a batched log-density callable.

``emissions.general(log_density, params, simulate=None)`` declares ``p(y_i | x_i = a, φ)``
by a function ``log_density(y, phi) -> (N, n, q)`` of the observations ``y`` (n,) and a
batch of parameter vectors ``phi`` (N, d): the log-density of each node's observation
under each state. Its parameters ``params`` are ``[(name, (low, high)), ...]``, with the
flat prior on those bounds (a parameter's ``bounds`` option of the hidden target narrows
it). There is no conjugate update: the hidden sampler takes random-walk Metropolis
steps on them, and EM maximises the expected log-density numerically (L-BFGS-B).
The values must be finite or ``-inf`` (NaN and ``+inf`` are refused, naming the
parameters); the callable is checked once, on the data, when the emission is bound.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy.optimize import minimize

from mrfpe.models.emissions.base import BoundEmission, Emission, resolve_bounds

__all__ = ["General", "general"]


class General(Emission):
    """An emission given by a batched log-density (see the module docstring).

    Parameters
    ----------
    log_density : callable ``(y (n,), phi (N, d)) -> (N, n, q)``
    params : sequence of ``(name, (low, high))``
    simulate : callable ``(x (n,), phi (d,), rng) -> y (n,)``, optional
    name : str
    data_kind : ``"real"``, ``"count"`` or ``"label"``
    """

    ordered = False

    def __init__(self, log_density: Callable[[np.ndarray, np.ndarray], Any],
                 params: Sequence[tuple[str, tuple[float, float]]],
                 simulate: Callable[..., Any] | None = None, name: str = "general",
                 data_kind: str = "real") -> None:
        if not callable(log_density) or (simulate is not None and not callable(simulate)):
            raise ValueError("log_density (and simulate, if given) must be callables")
        try:
            pairs = [(str(n), (float(lo), float(hi))) for n, (lo, hi) in params]
        except (TypeError, ValueError):
            raise ValueError(f"params must be a sequence of (name, (low, high)); got "
                             f"{params!r:.80}") from None
        names = [n for n, _ in pairs]
        if not pairs or len(set(names)) != len(names):
            raise ValueError(f"params must name at least one parameter, each once; got {names}")
        for n, (lo, hi) in pairs:
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"params bounds of {n!r} must be finite with low < high (the "
                                 f"flat prior's support); got ({lo}, {hi})")
        if data_kind not in ("real", "count", "label"):
            raise ValueError(f"data_kind must be 'real', 'count' or 'label'; got {data_kind!r}")
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty string; got {name!r}")
        self.log_density, self.params, self._simulate = log_density, pairs, simulate
        self.name, self.data_kind = name, data_kind

    def param_names(self, q: int) -> tuple[str, ...]:
        return tuple(n for n, _ in self.params)

    def bind(self, q: int, y: np.ndarray, observed: np.ndarray,
             covariates: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]],
             ) -> BoundGeneral:
        names = self.param_names(q)
        default = np.array([b for _, b in self.params])
        b, _ = resolve_bounds(names, default, bounds, default)
        bound = BoundGeneral(self, q, y, observed, names, b, np.ones(len(names), bool))
        bound.log_lik(b.mean(axis=1))  # the callable checked once, on the data
        return bound

    def simulate(self, x: np.ndarray, params: np.ndarray, rng: np.random.Generator,
                 covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        if self._simulate is None:
            raise ValueError(f"the emission {self.name!r} has no simulator: pass simulate= "
                             f"to emissions.general")
        x = np.asarray(x, dtype=np.int64)
        out = np.asarray(self._simulate(x.reshape(-1), np.asarray(params, float), rng),
                         dtype=np.float64)
        if out.shape != (x.size,):
            raise ValueError(f"the emission {self.name!r}'s simulate returned shape "
                             f"{out.shape}; expected ({x.size},)")
        return out.reshape(x.shape)

    def describe(self) -> dict:
        return {**super().describe(), "params": [[n, list(b)] for n, b in self.params]}


class BoundGeneral(BoundEmission):
    """A general emission on one data set: flat priors, no conjugate update."""

    conjugate = False

    def _log_lik_observed(self, params: np.ndarray) -> np.ndarray:
        n = int(self.observed.sum())
        out = np.array(self.emission.log_density(self.y[self.observed], params),
                       dtype=np.float64)  # a copy: log_lik may hand it out
        if out.shape != (params.shape[0], n, self.q):
            raise ValueError(f"the emission {self.emission.name!r}'s log_density must return "
                             f"(N, n, q) = ({params.shape[0]}, {n}, {self.q}) for {n} "
                             f"observations; got {out.shape}")
        bad = np.isnan(out) | (out == np.inf)
        if bad.any():
            k = int(np.flatnonzero(bad.reshape(bad.shape[0], -1).any(axis=1))[0])
            at = ", ".join(f"{m}={v:.6g}" for m, v in zip(self.names, params[k], strict=True))
            raise ValueError(f"the emission {self.emission.name!r}'s log_density returned NaN "
                             f"or +inf at ({at}): log-densities must be finite or -inf")
        return out

    def log_prior(self, params: Any) -> np.ndarray:
        p = self.as_params(params)
        return np.where(self.in_support(p), 0.0, -np.inf)

    def map_update(self, params: np.ndarray, resp: np.ndarray, free: np.ndarray) -> np.ndarray:
        """The maximiser of ``sum_i sum_a resp[i, a] log p(y_i | a, φ)`` over the free
        parameters in their bounds (L-BFGS-B from ``params``)."""
        p = np.array(params, dtype=float)
        idx = np.flatnonzero(free)
        if not idx.size:
            return p
        r = np.asarray(resp, float)[self.observed]

        def negative(v: np.ndarray) -> float:
            full = p.copy()
            full[idx] = v
            ll = self._log_lik_observed(full[None])[0]
            with np.errstate(invalid="ignore"):
                val = float(np.sum(np.where(r > 0, r * ll, 0.0)))
            return -val if np.isfinite(val) else 1e300

        res = minimize(negative, p[idx], method="L-BFGS-B", bounds=self.bounds[idx])
        if res.fun < negative(p[idx]):
            p[idx] = res.x
        return p

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """The centre of the bounds; labels: the most likely state of each observation."""
        p = self.bounds.mean(axis=1)
        return p, np.argmax(self.log_lik(p)[0], axis=1).astype(np.int64)

    def prior_sample(self, rng: np.random.Generator) -> np.ndarray:
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        return lo + (hi - lo) * rng.random(self.d)

    def describe_prior(self) -> dict:
        return {n: f"flat on [{lo:.6g}, {hi:.6g}]" for n, (lo, hi) in zip(
            self.names, self.bounds, strict=True)}


def general(log_density: Callable[[np.ndarray, np.ndarray], Any],
            params: Sequence[tuple[str, tuple[float, float]]],
            simulate: Callable[..., Any] | None = None, name: str = "general",
            data_kind: str = "real") -> General:
    """An emission from a batched log-density (see :class:`General`)."""
    return General(log_density, params, simulate=simulate, name=name, data_kind=data_kind)
