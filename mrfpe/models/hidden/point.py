"""Point estimates of a hidden MRF: ICM and mean-field EM, as ``kind="optima"`` posteriors.

* :func:`icm` -- Besag's (1986) iterated conditional modes with
  parameter estimation: alternately every label takes its most probable state given
  its neighbours and its observation (:func:`~mrfpe.models.hidden.kernels.icm_sweep`,
  until no label changes), the emission's parameters their conditional mode given the
  labels, and the MRF's parameters the maximiser of the labels' pseudolikelihood.
* :func:`mean_field_em` -- the mean-field EM of Celeux, Forbes & Peyrard (2003, their
  "mean field" algorithm among the mean field-like ones): the mean-field fixed point
  ``P̃`` of the label probabilities at the current parameters (updated sequentially),
  the E-step's factorised posterior ``t_i(a) ∝ p(y_i | a) p(x_i = a | P̃_N_i)``, and the
  M-step: the emission's conditional mode given ``t`` and the MRF parameters
  maximising the ``t``-weighted pseudolikelihood with mean-field neighbours.

Both maximise *posterior* modes for the emission (its stated prior,
:mod:`mrfpe.models.emissions`) and flat priors on the MRF's bounds; they start from the
emission's classification of the data with the MRF's parameters at 0 (clipped into
their bounds), and the ``hidden`` sampler starts its chains from EM's result. Each
returns a posterior of one sample, ``kind="optima"``, carrying the label summaries
(:mod:`mrfpe.models.hidden.labels`) and ``n_iterations``, ``converged``.
"""

from __future__ import annotations

import time
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import minimize

from mrfpe.models.design import softmax_rows_log_prob
from mrfpe.models.hidden.labels import label_variables
from mrfpe.models.hidden.meanfield import (
    approx_log_lik,
    log_conditionals,
    soft_design,
    weighted_pl,
)
from mrfpe.models.hidden.target import HiddenTarget
from mrfpe.posterior import build
from mrfpe.validation import check_positive_int, check_range

__all__ = ["PointEstimate", "em_estimate", "icm", "icm_estimate", "maximise_mrf",
           "mean_field_em", "start_point"]


class PointEstimate(NamedTuple):
    """What ICM and EM find: every parameter, the labels or their probabilities."""

    params: np.ndarray  # (D,) every parameter, fixed ones included
    labels: np.ndarray  # (n,) int64
    prob: np.ndarray  # (n, q)
    log_target: float
    n_iterations: int
    converged: bool


def start_point(target: HiddenTarget) -> tuple[np.ndarray, np.ndarray]:
    """``(every parameter (D,), labels (n,))``: the emission's start and the MRF's
    parameters at 0 clipped into their bounds; the fixed values where given."""
    em, labels = target.emission.start()
    b = target.all_bounds[: target.n_mrf]
    mrf = np.clip(np.zeros(target.n_mrf), b[:, 0], b[:, 1])
    full = np.concatenate([mrf, em])
    full = np.where(target.free, full, target.fixed_values)
    return full, np.asarray(labels, dtype=np.int64)


def maximise_mrf(target: HiddenTarget, objective: Any, mrf: np.ndarray) -> np.ndarray:
    """The free MRF parameters maximising ``objective(psi (N, P)) -> (N,)`` in their bounds
    (L-BFGS-B with finite differences, from ``mrf``; kept if it finds nothing better)."""
    free = target.free[: target.n_mrf]
    idx = np.flatnonzero(free)
    if not idx.size:
        return mrf
    b = target.all_bounds[: target.n_mrf][idx]

    def negative(v: np.ndarray) -> float:
        full = mrf.copy()
        full[idx] = v
        val = float(objective(target.design.psi(full[None]))[0])
        return -val if np.isfinite(val) else 1e300

    res = minimize(negative, np.clip(mrf[idx], b[:, 0], b[:, 1]), method="L-BFGS-B", bounds=b)
    out = mrf.copy()
    if res.fun <= negative(mrf[idx]):
        out[idx] = res.x
    return out


def _finish(target: HiddenTarget, est: PointEstimate, sampler: str, config: dict,
            t0: float) -> Any:
    """The ``kind="optima"`` posterior of one point estimate."""
    theta = est.params[target.free][None]
    return build(theta, [est.log_target], param_names=target.param_names, kind="optima",
                 sampler=sampler, config=config, seed=None, target=target,
                 n_target_evals=0.0, wall_time_s=time.perf_counter() - t0,
                 extra_vars=label_variables(target, est.prob),
                 extra_attrs={"n_iterations": int(est.n_iterations),
                              "converged": int(est.converged),
                              "log_target_is": _LOG_TARGET_IS[sampler]})


_LOG_TARGET_IS = {
    "hidden_icm": "log PL(x | MRF parameters) + sum_i log p(y_i | x_i) + log prior of the "
                  "emission, at the ICM labelling",
    "hidden_em": "the mean-field-like approximation of log p(y | parameters) (Celeux et al. "
                 "2003) + log prior of the emission",
}


def icm(target: HiddenTarget, *, max_iterations: int = 50, tol: float = 1e-6) -> Any:
    """Besag's (1986) ICM with parameter estimation; a ``kind="optima"`` posterior.

    Parameters
    ----------
    target : the hidden target (``hm.target("hidden", y, ...)``)
    max_iterations : rounds of (labels, emission, MRF) updates
    tol : stop when no label changes and no parameter moves by more than ``tol`` times
        its bounds' width
    """
    t0 = time.perf_counter()
    est = icm_estimate(target, max_iterations=max_iterations, tol=tol)
    return _finish(target, est, "hidden_icm",
                   {"max_iterations": max_iterations, "tol": tol}, t0)


def icm_estimate(target: HiddenTarget, *, max_iterations: int = 50,
                 tol: float = 1e-6) -> PointEstimate:
    """The computation of :func:`icm`, returned as a :class:`PointEstimate`."""
    max_iterations = check_positive_int("max_iterations", max_iterations)
    tol = check_range("tol", tol, 0.0, 1.0)
    full, x = start_point(target)
    em_free = target.free[target.n_mrf:]
    width = target.all_bounds[:, 1] - target.all_bounds[:, 0]
    converged, it = False, 0
    while it < max_iterations:
        it += 1
        mrf, em = full[: target.n_mrf], full[target.n_mrf:]
        tables = target.field.tables(target.design.psi(mrf[None])[0])
        loglik = target.emission.log_lik(em)[0]
        changed = 0
        for _ in range(100):  # sweeps until no label changes
            c = target.field.icm(x, tables, loglik)
            changed += c
            if c == 0:
                break
        em = target.emission.map_update(em, target.emission.one_hot(x), em_free)
        rows = target.design.conditional_rows(x[None])
        mrf = maximise_mrf(target, partial(_pl_of_rows, rows), mrf)
        new = np.concatenate([mrf, em])
        moved = np.max(np.abs(new - full) / width)
        full = new
        if changed == 0 and moved <= tol:
            converged = True
            break
    mrf, em = full[: target.n_mrf], full[target.n_mrf:]
    tables = target.field.tables(target.design.psi(mrf[None])[0])
    loglik = target.emission.log_lik(em)[0]
    prob = target.field.conditionals(x, tables, loglik)
    lt = float(target.log_pl(x, mrf[None])[0]
               + loglik[np.arange(x.size), x][target.observed].sum()
               + target.emission.log_prior(em)[0])
    return PointEstimate(full, x, prob, lt, it, converged)


def _pl_of_rows(rows: Any, psi: np.ndarray) -> np.ndarray:
    return softmax_rows_log_prob([rows], psi)


def mean_field_em(target: HiddenTarget, *, max_iterations: int = 200, tol: float = 1e-6,
                  mean_field_sweeps: int = 10) -> Any:
    """Mean-field EM (Celeux, Forbes & Peyrard 2003); a ``kind="optima"`` posterior.

    Parameters
    ----------
    target : the hidden target
    max_iterations : EM iterations
    tol : stop when no parameter moves by more than ``tol`` times its bounds' width and
        no label probability by more than ``tol``
    mean_field_sweeps : most sweeps of the mean-field fixed point per iteration
    """
    t0 = time.perf_counter()
    est = em_estimate(target, max_iterations=max_iterations, tol=tol,
                      mean_field_sweeps=mean_field_sweeps)
    return _finish(target, est, "hidden_em", {"max_iterations": max_iterations, "tol": tol,
                                              "mean_field_sweeps": mean_field_sweeps}, t0)


def em_estimate(target: HiddenTarget, *, max_iterations: int = 200, tol: float = 1e-6,
                mean_field_sweeps: int = 10) -> PointEstimate:
    """The computation of :func:`mean_field_em`, returned as a :class:`PointEstimate`."""
    max_iterations = check_positive_int("max_iterations", max_iterations)
    tol = check_range("tol", tol, 0.0, 1.0)
    sweeps = check_positive_int("mean_field_sweeps", mean_field_sweeps)
    full, x = start_point(target)
    em_free = target.free[target.n_mrf:]
    width = target.all_bounds[:, 1] - target.all_bounds[:, 0]
    P = target.emission.one_hot(x)
    resp, converged, it = P, False, 0
    while it < max_iterations:
        it += 1
        mrf, em = full[: target.n_mrf], full[target.n_mrf:]
        psi = target.design.psi(mrf[None])
        tables = target.field.tables(psi[0])
        loglik = target.emission.log_lik(em)[0]
        for _ in range(sweeps):
            if target.field.mean_field(P, tables, loglik) < tol:
                break
        G = soft_design(target.design, P)
        new_resp = _responsibilities(G, psi, loglik)
        em = target.emission.map_update(em, new_resp, em_free)
        mrf = maximise_mrf(target, partial(_weighted_pl, G, new_resp), mrf)
        new = np.concatenate([mrf, em])
        moved = max(np.max(np.abs(new - full) / width), np.max(np.abs(new_resp - resp)))
        full, resp = new, new_resp
        if moved <= tol:
            converged = True
            break
    mrf, em = full[: target.n_mrf], full[target.n_mrf:]
    G = soft_design(target.design, P)
    lt = float(approx_log_lik(G, target.design.psi(mrf[None]), target.emission.log_lik(em),
                              target.observed)[0] + target.emission.log_prior(em)[0])
    return PointEstimate(full, np.argmax(resp, axis=1).astype(np.int64), resp, lt, it,
                         converged)


def _weighted_pl(G: np.ndarray, resp: np.ndarray, psi: np.ndarray) -> np.ndarray:
    return weighted_pl(G, psi, resp)


def _responsibilities(G: np.ndarray, psi: np.ndarray, loglik: np.ndarray) -> np.ndarray:
    """``t_i(a) ∝ p(y_i | a) p(x_i = a | P̃_N_i)`` (n, q): the E-step of Celeux et al. (2003)."""
    w = log_conditionals(G, psi)[0] + loglik
    m = w.max(axis=1, keepdims=True)
    p = np.exp(w - np.where(np.isfinite(m), m, 0.0))
    return p / p.sum(axis=1, keepdims=True)
