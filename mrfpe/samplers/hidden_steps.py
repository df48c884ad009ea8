"""The steps of the ``hidden`` sampler: one sweep of every block of a hidden MRF's chains.

A :class:`HiddenState` holds, for each of ``C`` chains, the labels ``x`` (n,) and every
parameter (the MRF's, then the emission's; fixed ones at their values). One step
(:func:`hidden_step`) updates, in turn,

1. the labels given the parameters and the data: a Swendsen-Wang sweep with the data as
   external field (Higdon 1998; ``labels="swendsen_wang"``), then a chequerboard Gibbs
   sweep with the data term (:meth:`LabelField.gibbs
   <mrfpe.models.hidden.field.LabelField.gibbs>`), whose conditional probabilities are
   added up for the label posterior (Rao-Blackwellised);
2. the emission's free parameters given the labels: the conditionally conjugate update
   of the emission (:meth:`BoundEmission.update
   <mrfpe.models.emissions.base.BoundEmission.update>`), or ``theta_steps`` random-walk
   Metropolis steps on ``sum_i log p(y_i | x_i, φ) + log prior(φ)`` where there is none;
3. the MRF's free parameters given the labels, by the target's ``method``
   (:mod:`mrfpe.samplers.hidden_theta`): random-walk Metropolis on the labels'
   pseudolikelihood (a pseudo-posterior, since ``exp(PL)`` is not ``p(x | θ)``), on the
   calibrated pseudolikelihood, by the exchange algorithm, or on the pre-computed
   surrogate.

Each block leaves its full conditional (or, for the MRF's parameters, the pseudo
conditional) invariant; their cycle is the sampler. The random walks are the kit's
(:class:`~mrfpe.samplers.kit.AdaptiveRandomWalk`), adapted during burn-in only. The
labels' conditional rows (:meth:`LabelField.conditional_rows
<mrfpe.models.hidden.field.LabelField.conditional_rows>`) are built once per step, after
the labels move, for both the pseudolikelihood of step 3 and the joint log density
(:func:`joint_log_target`, whose data term reads only the labels' states).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from mrfpe.models.design import ConditionalRows
from mrfpe.models.hidden.point import PointEstimate
from mrfpe.models.hidden.target import HiddenTarget
from mrfpe.samplers.kit import AdaptiveRandomWalk, metropolis_accept

__all__ = ["HiddenState", "Walks", "hidden_step", "joint_log_target", "make_walks",
           "start_state", "walk_block"]


class HiddenState(NamedTuple):
    """Every chain's labels and parameters."""

    labels: np.ndarray  # (C, n) int64
    params: np.ndarray  # (C, D) every parameter, the MRF's then the emission's
    log_target: np.ndarray  # (C,) the joint (pseudo) log density: joint_log_target


class Walks(NamedTuple):
    """The random walks of the MRF's and (without a conjugate update) the emission's free
    parameters; ``None`` where a block has no free parameter."""

    mrf: AdaptiveRandomWalk | None
    emission: AdaptiveRandomWalk | None


def joint_log_target(target: HiddenTarget, x: np.ndarray, params: np.ndarray,
                     rows: ConditionalRows | None = None) -> float:
    """``log PL(x | θ) + sum_i log p(y_i | x_i, φ) + log prior(φ)`` of one chain: the log
    density the sampler's draws are ranked by (its MAP trace), up to a constant. ``rows``:
    the labels' conditional rows, if already built (:meth:`LabelField.conditional_rows
    <mrfpe.models.hidden.field.LabelField.conditional_rows>`)."""
    mrf, em = target.split(params)
    rows = target.field.conditional_rows(x) if rows is None else rows
    return float(target.log_pl_rows(rows, mrf)[0] + target.emission.log_lik_at(em, x)[0]
                 + target.emission.log_prior(em)[0])


def start_state(target: HiddenTarget, point: PointEstimate, n_chains: int,
                rng: np.random.Generator) -> HiddenState:
    """Chains started from a point estimate: chain 0 at it, every other with labels drawn
    from its label probabilities, a conditionally conjugate draw of the emission's
    parameters given them (a jitter of 5 % of the bounds without one) and the MRF's free
    parameters jittered by 5 % of their bounds' widths, clipped into them."""
    n, D = target.n_nodes, len(target.all_names)
    labels, params = np.empty((n_chains, n), np.int64), np.empty((n_chains, D))
    width = target.all_bounds[:, 1] - target.all_bounds[:, 0]
    em_free = target.free[target.n_mrf:]
    cum = np.cumsum(point.prob, axis=1)
    for c in range(n_chains):
        if c == 0:
            labels[c], params[c] = point.labels, point.params
            continue
        u = rng.random((n, 1)) * cum[:, -1:]
        labels[c] = np.minimum((u >= cum).sum(axis=1), target.q - 1)
        p = point.params + 0.05 * width * rng.standard_normal(D)
        p = np.clip(p, target.all_bounds[:, 0], target.all_bounds[:, 1])
        mrf, em = p[: target.n_mrf], point.params[target.n_mrf:]
        drawn = target.emission.update(em, labels[c], rng, em_free)
        if drawn is None:
            drawn = p[target.n_mrf:]
            if not target.emission.in_support(drawn)[0]:
                drawn = em
        params[c] = np.where(target.free, np.concatenate([mrf, drawn]), target.fixed_values)
    lt = np.array([joint_log_target(target, labels[c], params[c]) for c in range(n_chains)])
    return HiddenState(labels, params, lt)


def make_walks(target: HiddenTarget, n_chains: int, proposal_sd: float, burn_in: int,
               adapt: bool, target_acceptance: float) -> Walks:
    """The random walks over each block's free parameters (their bounds)."""
    def walk(block: np.ndarray) -> AdaptiveRandomWalk | None:
        idx = np.flatnonzero(block & target.free)
        if not idx.size:
            return None
        return AdaptiveRandomWalk(target.all_bounds[idx], n_chains, proposal_sd, burn_in,
                                  adapt, target_acceptance)

    D = len(target.all_names)
    is_mrf = np.arange(D) < target.n_mrf
    return Walks(walk(is_mrf), None if target.emission.conjugate else walk(~is_mrf))


def _tables(target: HiddenTarget, params: np.ndarray, swendsen_wang: bool = False) -> list:
    """Every chain's MRF tables (computed once per distinct parameter vector)."""
    mrf = target.split(params)[0]
    psi = target.design.psi(mrf)
    seen: dict[bytes, Any] = {}
    out = []
    for c in range(mrf.shape[0]):
        key = mrf[c].tobytes()
        if key not in seen:
            seen[key] = target.field.tables(psi[c], swendsen_wang=swendsen_wang)
        out.append(seen[key])
    return out


def _label_sweeps(target: HiddenTarget, state: HiddenState, rng: np.random.Generator,
                  acc: np.ndarray | None, swendsen_wang: bool) -> None:
    """Every chain's labels, in place: (Swendsen-Wang and) a Gibbs sweep."""
    loglik = target.emission.log_lik(target.split(state.params)[1])  # (C, n, q), batched
    for c, tables in enumerate(_tables(target, state.params, swendsen_wang)):
        x = state.labels[c]
        if swendsen_wang and tables.sw_field is not None:  # not at antiferromagnetic θ
            target.field.swendsen_wang(x, tables, loglik[c], rng)
        target.field.gibbs(x, tables, loglik[c], rng.random(target.n_nodes),
                           None if acc is None else acc[c])


def walk_block(walk: AdaptiveRandomWalk, idx: np.ndarray, params: np.ndarray,
                log_density: Any, rng: np.random.Generator) -> float:
    """One random-walk Metropolis step of the parameters ``idx`` of every chain, in place;
    ``log_density(c, vectors (k, D)) -> (k,)``. Returns the acceptance rate."""
    cur = params[:, idx]
    prop, inside = walk.propose(cur, rng)
    log_u = np.log(rng.random(params.shape[0]))
    accepted = np.zeros(params.shape[0], dtype=bool)
    for c in range(params.shape[0]):
        if not inside[c]:
            continue
        trial = np.stack([params[c], params[c]])
        trial[1, idx] = prop[c]
        lp = log_density(c, trial)
        accepted[c] = bool(metropolis_accept(log_u[c:c + 1], lp[:1], lp[1:])[0])
        if accepted[c]:
            params[c, idx] = prop[c]
    return float(accepted.mean())


def _emission_block(target: HiddenTarget, state: HiddenState, walk: AdaptiveRandomWalk | None,
                    rng: np.random.Generator, theta_steps: int) -> float:
    """The emission's free parameters of every chain, in place; the acceptance rate of the
    random walk (1 for conjugate updates, NaN with nothing free)."""
    n_mrf, free = target.n_mrf, target.free[target.n_mrf:]
    if not free.any():
        return float("nan")
    if target.emission.conjugate:
        for c in range(state.params.shape[0]):
            em = state.params[c, n_mrf:]
            state.params[c, n_mrf:] = target.emission.update(em, state.labels[c], rng, free)
        return 1.0

    def log_density(c: int, trial: np.ndarray) -> np.ndarray:
        em = trial[:, n_mrf:]
        return target.emission.log_lik_at(em, state.labels[c]) + target.emission.log_prior(em)

    idx = n_mrf + np.flatnonzero(free)
    return float(np.mean([walk_block(walk, idx, state.params, log_density, rng)
                          for _ in range(theta_steps)]))


def hidden_step(target: HiddenTarget, state: HiddenState, walks: Walks,
                rng: np.random.Generator, *, theta_update: Any, theta_steps: int,
                swendsen_wang: bool, acc: np.ndarray | None = None
                ) -> tuple[HiddenState, dict]:
    """One step of every chain (labels, emission, MRF; see the module docstring).

    ``acc`` (C, n, q), when given, receives each chain's Gibbs conditional probabilities.
    Returns the new state (its arrays updated in place) and the blocks' acceptance rates.
    """
    _label_sweeps(target, state, rng, acc, swendsen_wang)
    em_acc = _emission_block(target, state, walks.emission, rng, theta_steps)
    rows = [target.field.conditional_rows(x) for x in state.labels]  # for PL, built once
    mrf_acc = theta_update.step(state, walks.mrf, rng, theta_steps, rows)
    lt = np.array([joint_log_target(target, x, p, r)
                   for x, p, r in zip(state.labels, state.params, rows, strict=True)])
    return HiddenState(state.labels, state.params, lt), {"mrf_acceptance": mrf_acc,
                                                         "emission_acceptance": em_acc}
