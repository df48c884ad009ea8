"""Categorical emission: observed labels with misclassification.

``p(y_i = c | x_i = a) = prob_a_c``: each hidden state ``a`` has a row of
probabilities over the ``K`` observed categories (``K = q`` by default), a
misclassification matrix. Prior: each row ``~ Dirichlet(alpha_a)``, by default
``alpha_a[c] = 2 + [a == c]`` (weakly informative: state ``a`` is a little more often
observed as category ``a``, which is what names the states -- the rows are not otherwise
ordered --, and no probability's conditional mode is 0, which would let no label ever
differ from its observation in ICM or EM). Update: each row from its Dirichlet full
conditional ``Dirichlet(alpha_a + n_a)``, ``n_a[c]`` the observed nodes in state ``a``
with category ``c`` (the Dirichlet-multinomial conjugate pair); fixed entries of a
row are kept and its free entries are the conditional Dirichlet of the rest of the row
(aggregation property), scaled to ``1 - sum(fixed)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from mrfpe.models.emissions.base import BoundEmission, Emission, observed_values
from mrfpe.validation import check_positive_int

__all__ = ["Categorical", "categorical"]


class Categorical(Emission):
    """Observed categories ``y_i`` in ``[0, K)`` given the state (see the module docstring).

    Parameters
    ----------
    n_categories : int or None
        ``K`` (default: the number of states).
    concentration : float or (q, K) array or None
        Dirichlet prior of the rows: one number for every entry, or the full matrix
        (default ``2 + [a == c]``); every entry > 0.
    """

    name = "categorical"
    ordered = False
    data_kind = "label"

    def __init__(self, n_categories: int | None = None, concentration: Any = None) -> None:
        self.n_categories = None if n_categories is None else check_positive_int(
            "n_categories", n_categories, minimum=2)
        if concentration is not None:
            c = np.asarray(concentration, dtype=np.float64)
            if c.ndim > 2 or not np.all(np.isfinite(c)) or np.any(c <= 0):
                raise ValueError("concentration must be a proper Dirichlet prior: a number or "
                                 "a (q, K) matrix of finite values > 0; got "
                                 f"{np.asarray(concentration).tolist()!r:.80}")
            concentration = c
        self.concentration = concentration

    def categories(self, q: int) -> int:
        return self.n_categories or q

    def param_names(self, q: int) -> tuple[str, ...]:
        return tuple(f"prob_{a}_{c}" for a in range(q) for c in range(self.categories(q)))

    def alpha(self, q: int) -> np.ndarray:
        """(q, K) Dirichlet concentrations of the rows."""
        K = self.categories(q)
        if self.concentration is None:
            return 2.0 + np.eye(q, K)
        c = np.broadcast_to(self.concentration, (q, K)) if self.concentration.ndim < 2 \
            else self.concentration
        if c.shape != (q, K):
            raise ValueError(f"concentration must be a number or a ({q}, {K}) matrix for "
                             f"{q} states and {K} categories; got shape {c.shape}")
        return np.array(c, dtype=float)

    def check_y(self, y: np.ndarray, observed: np.ndarray) -> None:
        super().check_y(y, observed)
        v = np.asarray(y, dtype=np.float64)[observed]
        K = self.n_categories
        if K is not None and v.size and v.max() >= K:
            raise ValueError(f"y must hold categories 0 .. {K - 1} (n_categories={K}); got "
                             f"values up to {v.max():g}")

    def bind(self, q: int, y: np.ndarray, observed: np.ndarray,
             covariates: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]],
             ) -> BoundCategorical:
        if bounds:
            raise ValueError(f"bounds cannot be set for the categorical emission's "
                             f"probabilities ({', '.join(bounds)}): their prior is the "
                             f"Dirichlet (set concentration= instead)")
        K = self.categories(q)
        v = observed_values(y, observed)
        if v.size and v.max() >= K:
            raise ValueError(f"y must hold categories 0 .. {K - 1} ({K} categories: "
                             f"n_categories, by default the number of states); got values up "
                             f"to {v.max():g}")
        names = self.param_names(q)
        b = np.array([(0.0, 1.0)] * len(names))
        return BoundCategorical(self, q, y, observed, names, b, np.zeros(len(names), bool),
                                self.alpha(q))

    def simulate(self, x: np.ndarray, params: np.ndarray, rng: np.random.Generator,
                 covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=np.int64)
        K = self.n_categories or round(np.sqrt(len(params)))  # K = q by default
        prob = np.asarray(params, float).reshape(-1, K)
        cum = np.cumsum(prob[x.reshape(-1)], axis=1)
        u = rng.random(x.size)[:, None] * cum[:, -1:]
        return (u >= cum).sum(axis=1).reshape(x.shape).astype(np.float64)

    def describe(self) -> dict:
        conc = None if self.concentration is None else self.concentration.tolist()
        return {**super().describe(), "n_categories": self.n_categories, "concentration": conc}


class BoundCategorical(BoundEmission):
    """The categorical emission on one data set (see :class:`Categorical`)."""

    conjugate = True

    def __init__(self, emission: Categorical, q: int, y: np.ndarray, observed: np.ndarray,
                 names: tuple[str, ...], bounds: np.ndarray, flat: np.ndarray,
                 alpha: np.ndarray) -> None:
        super().__init__(emission, q, y, observed, names, bounds, flat)
        self.alpha = np.asarray(alpha, dtype=np.float64)
        self.K = self.alpha.shape[1]
        self._cache()

    def _cache(self) -> None:
        self.yo = observed_values(self.y, self.observed).astype(np.int64)

    def _log_lik_observed(self, params: np.ndarray) -> np.ndarray:
        prob = params.reshape(params.shape[0], self.q, self.K)
        with np.errstate(divide="ignore"):
            lp = np.log(prob)  # (N, q, K)
        return np.transpose(lp[:, :, self.yo], (0, 2, 1))

    def in_support(self, params: Any) -> np.ndarray:
        p = self.as_params(params)
        rows = p.reshape(p.shape[0], self.q, self.K)
        return super().in_support(p) & np.all(np.abs(rows.sum(axis=2) - 1.0) < 1e-9, axis=1)

    def log_prior(self, params: Any) -> np.ndarray:
        p = self.as_params(params)
        with np.errstate(divide="ignore", invalid="ignore"):
            lp = np.where(self.alpha.reshape(-1) == 1.0, 0.0,
                          (self.alpha.reshape(-1) - 1.0) * np.log(p)).sum(axis=1)
        return np.where(self.in_support(p), lp, -np.inf)

    def _counts(self, weights: np.ndarray) -> np.ndarray:
        """(q, K): ``sum_i weights[i, a] [y_i = c]`` over the observed nodes."""
        out = np.zeros((self.q, self.K))
        for c in range(self.K):
            out[:, c] = weights[self.yo == c].sum(axis=0)
        return out

    def update(self, params: np.ndarray, x: np.ndarray, rng: np.random.Generator,
               free: np.ndarray) -> np.ndarray:
        p = np.array(params, dtype=float).reshape(self.q, self.K)
        xo = np.asarray(x)[self.observed]
        n = np.zeros((self.q, self.K))
        np.add.at(n, (xo, self.yo), 1.0)
        fr = np.asarray(free, bool).reshape(self.q, self.K)
        for a in range(self.q):
            if fr[a].any():
                g = rng.dirichlet(self.alpha[a, fr[a]] + n[a, fr[a]])
                p[a, fr[a]] = (1.0 - p[a, ~fr[a]].sum()) * g
        return p.reshape(-1)

    def map_update(self, params: np.ndarray, resp: np.ndarray, free: np.ndarray) -> np.ndarray:
        p = np.array(params, dtype=float).reshape(self.q, self.K)
        n = self._counts(np.asarray(resp, float)[self.observed])
        fr = np.asarray(free, bool).reshape(self.q, self.K)
        for a in range(self.q):
            if fr[a].any():
                m = np.maximum(self.alpha[a, fr[a]] - 1.0 + n[a, fr[a]], 0.0) + 1e-12
                p[a, fr[a]] = (1.0 - p[a, ~fr[a]].sum()) * m / m.sum()
        return p.reshape(-1)

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows with 0.8 (or the prior's mean where ``K != q``) on the diagonal; labels:
        the observed category (clipped to the states)."""
        prob = np.full((self.q, self.K), 0.2 / max(self.K - 1, 1))
        for a in range(min(self.q, self.K)):
            prob[a, a] = 0.8
        prob /= prob.sum(axis=1, keepdims=True)
        labels = np.clip(np.where(self.observed, self.y, 0), 0, self.q - 1).astype(np.int64)
        return prob.reshape(-1), labels

    def prior_sample(self, rng: np.random.Generator) -> np.ndarray:
        return np.concatenate([rng.dirichlet(self.alpha[a]) for a in range(self.q)])

    def check_fixed(self, values: Mapping[str, float]) -> None:
        super().check_fixed(values)
        for a in range(self.q):
            row = [f"prob_{a}_{c}" for c in range(self.K)]
            fixed = [values[n] for n in row if n in values]
            if sum(fixed) > 1 + 1e-9 or (len(fixed) == self.K and abs(sum(fixed) - 1) > 1e-9):
                raise ValueError(f"fixed probabilities of row {a} ({', '.join(row)}) must sum "
                                 f"to 1 when all are fixed, and to at most 1 otherwise; got "
                                 f"{sum(fixed):g}")

    def describe_prior(self) -> dict:
        return {f"prob_{a}_*": f"Dirichlet({', '.join(f'{v:.6g}' for v in self.alpha[a])})"
                for a in range(self.q)}


def categorical(n_categories: int | None = None, concentration: Any = None) -> Categorical:
    """The categorical (misclassification) emission (see :class:`Categorical`)."""
    return Categorical(n_categories=n_categories, concentration=concentration)
