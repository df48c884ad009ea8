"""The target of a hidden MRF: one image, the model, and which parameters are free.

:class:`HiddenTarget` is what ``hm.target("hidden", y, ...)`` returns and what the
``hidden`` sampler (:mod:`mrfpe.samplers.hidden`) and the point estimators
(:mod:`mrfpe.models.hidden.point`) work on. It holds the validated observations and
missing-data mask, the compiled MRF (its :class:`~mrfpe.models.design.Design` and
:class:`~mrfpe.models.hidden.field.LabelField`), the emission bound to the data (its
priors), the known (``fixed``) parameters and the free ones, whose ``bounds`` are
their flat priors (the MRF's) or the support of their stated priors (the emission's).

As a :class:`~mrfpe.targets.Target` over the free parameters, its ``log_prob`` is the
mean-field-like approximation of the log marginal likelihood ``log p(y | θ)`` of
Celeux, Forbes & Peyrard (2003) with every node's neighbours fixed at the reference
labelling (:mod:`mrfpe.models.hidden.meanfield`; by default the emission's starting
classification of the data, :meth:`with_reference` sets another), plus the emission
parameters' log prior: a cheap, deterministic approximation any sampler or
:func:`mrfpe.targets.maximise` can use. The ``hidden`` sampler does not use it: it
integrates over the labels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.models.design import ConditionalRows, Design, softmax_rows_log_prob
from mrfpe.models.emissions.base import BoundEmission
from mrfpe.models.hidden.field import LabelField
from mrfpe.models.hidden.meanfield import approx_log_lik, soft_design
from mrfpe.models.hidden.surrogate import check_surrogate
from mrfpe.targets.base import Target

__all__ = ["METHODS", "HiddenTarget"]

#: The ways of drawing the MRF's parameters given the labels
#: (:mod:`mrfpe.samplers.hidden_theta`).
METHODS = ("pl", "pl_adjusted", "exchange", "surrogate")


class HiddenTarget(Target):
    """One image of a hidden MRF, and its free parameters (see the module docstring).

    Attributes
    ----------
    model : the :class:`~mrfpe.models.hidden.model.HiddenModel`
    design : Design; field : LabelField; emission : BoundEmission
    y : (n,) observations (0 at missing nodes); observed : (n,) bool
    node_shape : ``(H, W)`` on a lattice, ``(n,)`` on a fixed graph
    all_names : every parameter, the MRF's then the emission's
    free : (D,) bool; fixed_values : (D,) the fixed values (NaN where free)
    n_mrf : how many of ``all_names`` are the MRF's
    method : how the sampler draws the MRF's parameters (:data:`METHODS`)
    surrogate : the pre-computed :class:`~mrfpe.models.hidden.surrogate.Surrogate` of
        ``method="surrogate"`` (``None``: the sampler builds one from its seed)
    """

    data_kind = "image"

    def __init__(self, *, model: Any, design: Design, emission: BoundEmission, y: np.ndarray,
                 observed: np.ndarray, node_shape: tuple[int, ...],
                 mrf_names: tuple[str, ...], mrf_bounds: np.ndarray, fixed: dict[str, float],
                 method: str, reference: np.ndarray | None = None,
                 surrogate: Any = None) -> None:
        self.model, self.design, self.emission = model, design, emission
        self.field = LabelField(design)
        self.y, self.observed = y, observed
        self.node_shape = tuple(node_shape)
        self.n_mrf = len(mrf_names)
        self.all_names = (*mrf_names, *emission.names)
        self.all_bounds = np.concatenate([np.asarray(mrf_bounds, float), emission.bounds])
        self.free = np.array([n not in fixed for n in self.all_names])
        self.fixed_values = np.array([fixed.get(n, np.nan) for n in self.all_names])
        self.fixed = dict(fixed)
        self.method = method
        self.surrogate = surrogate
        self.param_names = tuple(n for n, f in zip(self.all_names, self.free, strict=True) if f)
        self.bounds = self.all_bounds[self.free]
        self.name = f"{model.name}:hidden"
        self.reference = np.asarray(emission.start()[1] if reference is None else reference)
        self._soft: np.ndarray | None = None
        for a in (self.free, self.fixed_values, self.all_bounds, self.bounds, self.y,
                  self.observed):
            a.setflags(write=False)
        if surrogate is not None:
            check_surrogate(surrogate, self)

    # -- parameter vectors --------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return int(self.y.size)

    @property
    def q(self) -> int:
        return int(self.design.q)

    def full(self, theta: Any) -> np.ndarray:
        """Free parameter vectors (N, d) -> every parameter (N, D), the fixed ones filled in."""
        th = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        out = np.repeat(self.fixed_values[None], th.shape[0], axis=0)
        out[:, self.free] = th
        return out

    def split(self, full: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(MRF parameters (N, d_mrf), emission parameters (N, d_em))`` of full vectors."""
        full = np.atleast_2d(full)
        return full[:, : self.n_mrf], full[:, self.n_mrf:]

    def log_pl(self, x: np.ndarray, mrf_theta: np.ndarray) -> np.ndarray:
        """Besag's log pseudolikelihood of the labelling ``x`` (n,) at MRF parameter vectors
        (N, d_mrf): the MRF's ``"pl"`` estimator (:meth:`Design.conditional_rows
        <mrfpe.models.design.Design.conditional_rows>`), ``-inf`` outside their bounds."""
        return self.log_pl_rows(self.design.conditional_rows(np.asarray(x, np.int64)[None]),
                                mrf_theta)

    def log_pl_rows(self, rows: ConditionalRows, mrf_theta: np.ndarray) -> np.ndarray:
        """:meth:`log_pl` from a labelling's conditional rows, built once."""
        th = np.atleast_2d(mrf_theta)
        b = self.all_bounds[: self.n_mrf]
        inside = np.all((th >= b[:, 0]) & (th <= b[:, 1]), axis=1)
        out = np.full(th.shape[0], -np.inf)
        if inside.any():
            out[inside] = softmax_rows_log_prob([rows], self.design.psi(th[inside]))
        return out

    # -- the Target: the mean-field-like approximation ----------------------------------------
    def with_reference(self, labels_or_probs: np.ndarray) -> HiddenTarget:
        """This target with ``log_prob`` approximated at another reference field: labels
        (n,) or label probabilities (n, q)."""
        ref = np.asarray(labels_or_probs)
        if ref.shape not in ((self.n_nodes,), (self.n_nodes, self.q)):
            raise ValueError(f"the reference must be labels ({self.n_nodes},) or probabilities "
                             f"({self.n_nodes}, {self.q}); got shape {ref.shape}")
        out = object.__new__(HiddenTarget)
        out.__dict__.update(self.__dict__)
        out.reference, out._soft = ref, None
        return out

    def _reference_design(self) -> np.ndarray:
        if self._soft is None:  # a cache of a pure function of the (immutable) reference
            ref = self.reference
            P = ref if ref.ndim == 2 else np.eye(self.q)[np.asarray(ref, np.int64)]
            self._soft = soft_design(self.design, P)
        return self._soft

    def _row_bytes(self) -> float:
        return 8.0 * 4 * self.n_nodes * self.q

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        mrf, em = self.split(self.full(theta))
        lp = self.emission.log_prior(em)
        ok = np.isfinite(lp)
        out = np.full(theta.shape[0], -np.inf)
        if ok.any():
            ll = self.emission.log_lik(em[ok])
            out[ok] = lp[ok] + approx_log_lik(self._reference_design(),
                                              self.design.psi(mrf[ok]), ll, self.observed)
        return out

    def describe(self) -> dict:
        return {"name": self.name, "class": type(self).__name__, "model": self.model.name,
                "estimator": "hidden", "method": self.method,
                "param_names": list(self.param_names), "bounds": self.bounds.tolist(),
                "fixed": self.fixed, "n_states": self.q, "node_shape": list(self.node_shape),
                "n_nodes": self.n_nodes, "n_observed": int(self.observed.sum()),
                "graph": self.design.graph.describe(), "mrf": self.model.mrf.describe(),
                "emission": self.emission.emission.describe(),
                "priors": self.emission.describe_prior(),
                "mrf_prior": "flat on the bounds of every free MRF parameter",
                **({"surrogate": self.surrogate.describe()} if self.surrogate is not None
                   else {})}
