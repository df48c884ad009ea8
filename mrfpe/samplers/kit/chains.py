"""What only chains need: chain-length checks, the run's start and the kept states.

:func:`start_chains` is the common opening of an MCMC sampler's ``run``:
validate the target and the seed, open the run log, draw the chains' starting
states in the support and prepare the record of the kept (post-burn-in,
thinned) states, :class:`KeptStates`. ``KeptStates(..., ensemble=True)`` marks the
chains as the walkers of one ensemble (walkers that move using each other, as emcee's):
its ``ess`` trace and the posterior's diagnostics then follow the ensemble's integrated
autocorrelation time (Goodman & Weare 2010) instead of treating the walkers as
independent chains (:func:`mrfpe.posterior.diagnose`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from mrfpe.samplers.kit.draws import draw_in_support
from mrfpe.samplers.kit.runlog import Run
from mrfpe.validation import check_positive_int, check_seed, check_target

__all__ = ["ESS_CHECKPOINTS", "ChainStart", "KeptStates", "check_chain_length", "start_chains"]

#: How many evenly spaced kept steps (the last included) get an ESS in the MCMC
#: ``ess`` trace (:meth:`KeptStates.trace_ess`); ArviZ's ESS over the whole run so far
#: at every step would cost O(steps²).
ESS_CHECKPOINTS = 20


def check_chain_length(n_steps: Any, burn_in: Any, thin: Any) -> tuple[int, int, int]:
    """Validate ``n_steps`` >= 1, 0 <= ``burn_in`` < ``n_steps`` and ``thin`` >= 1."""
    n_steps = check_positive_int("n_steps", n_steps)
    burn_in_ = check_positive_int("burn_in", burn_in, minimum=0)
    if burn_in_ >= n_steps:
        raise ValueError(f"burn_in must be < n_steps ({n_steps}); got {burn_in}")
    return n_steps, burn_in_, check_positive_int("thin", thin)


class KeptStates:
    """The sample set of an MCMC run: every ``thin``-th state after ``burn_in``, all chains.

    >>> kept = KeptStates(n_steps, burn_in, thin, n_chains, d)      # doctest: +SKIP
    >>> for t in range(n_steps):                                    # doctest: +SKIP
    ...     ...
    ...     kept.record(t, x, lp)            # no-op on steps that are not kept
    >>> theta, log_target, log_weight = kept.flat()                 # doctest: +SKIP

    Parameters
    ----------
    n_steps, burn_in, thin : int
        The run's length, the leading steps dropped and the thinning of the rest.
    n_chains, d : int
        Chains (or walkers) and parameters.
    weighted : bool
        Keep a ``log_weight`` per state (dynamic weighting).
    ensemble : bool
        The chains are the walkers of one ensemble sampler (emcee's affine-invariant
        ensemble, or any whose walkers move using each other), not independent chains.
        :meth:`trace_ess` is then ``n_walkers × n_kept / τ`` with τ the ensemble's
        integrated autocorrelation time (:func:`mrfpe.posterior.diagnostics.ensemble_ess`),
        and :meth:`build_kwargs` marks the posterior ``chain_type="ensemble"``, which
        :func:`mrfpe.posterior.diagnose` judges by τ (Goodman & Weare 2010; emcee's
        documentation, Foreman-Mackey et al. 2013, asks for a chain of about 50 τ)
        rather than by R̂ across the walkers.

    Attributes
    ----------
    steps : (K,) the kept step indices.
    theta : (K, C, d); log_target, log_weight : (K, C) — filled by :meth:`record`
        (``log_weight`` only when ``weighted``).
    """

    def __init__(self, n_steps: int, burn_in: int, thin: int, n_chains: int, d: int, *,
                 weighted: bool = False, ensemble: bool = False):
        self.ensemble = bool(ensemble)
        self.steps = np.arange(burn_in, n_steps, thin)
        k = self.steps.size
        self.theta = np.empty((k, n_chains, d))
        self.log_target = np.empty((k, n_chains))
        self.log_weight = np.empty((k, n_chains)) if weighted else None
        self._k = 0
        m = min(ESS_CHECKPOINTS, k)  # evenly spaced, ending at the last kept step
        marks = (np.arange(1, m + 1) * k) // max(m, 1) - 1
        self.checkpoints = set(self.steps[marks].tolist()) if k else set()

    def record(self, t: int, theta: np.ndarray, log_target: np.ndarray,
               log_weight: np.ndarray | None = None) -> bool:
        """Store the chains' states if step ``t`` is kept; return whether it was."""
        k = self._k
        if k >= self.steps.size or t != self.steps[k]:
            return False
        self.theta[k], self.log_target[k] = theta, log_target
        if self.log_weight is not None:
            self.log_weight[k] = log_weight
        self._k += 1
        return True

    def trace_ess(self, t: int) -> float:
        """The ``ess`` trace entry of step ``t``: at a checkpoint (:data:`ESS_CHECKPOINTS`
        evenly spaced kept steps), the autocorrelation-based ESS of the states kept so
        far — :func:`mrfpe.posterior.diagnostics.chain_ess` pooled over the chains (for
        an ``ensemble``, :func:`~mrfpe.posterior.diagnostics.ensemble_ess`, ``n_walkers ×
        n_kept / τ``, where τ can be estimated), times Kish's efficiency of the kept
        weights when ``weighted`` (as :func:`mrfpe.posterior.diagnose` does) —; NaN
        elsewhere and during burn-in. Never the draw count. Call it after
        :meth:`record` of step ``t``."""
        if t not in self.checkpoints or self._k < 4:
            return float("nan")
        from mrfpe.posterior.diagnostics import chain_ess, ensemble_ess
        from mrfpe.resampling import ess

        x = self.theta[: self._k].transpose(1, 0, 2)  # (chain, draw, param)
        e = ensemble_ess(x) if self.ensemble else math.nan
        e = e if math.isfinite(e) else chain_ess(x)
        if self.log_weight is not None:
            lw = self.log_weight[: self._k].reshape(-1)
            e = max(e * ess(lw) / lw.size, 1.0)
        # antithetic short chains give an autocorrelation ESS above the draw count; the
        # trace reports at most the draws it has (the posterior's check holds it to that)
        return float(min(e, x.shape[0] * x.shape[1]))

    def flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(theta (S, d), log_target (S,), log_weight (S,) or None)``, S = K·C, step-major."""
        d = self.theta.shape[-1]
        lw = None if self.log_weight is None else self.log_weight.reshape(-1)
        return self.theta.reshape(-1, d), self.log_target.reshape(-1), lw

    def chain(self) -> np.ndarray:
        """(S,) chain index of each flattened sample (for per-chain diagnostics)."""
        return np.tile(np.arange(self.theta.shape[1]), self.steps.size)

    def build_kwargs(self, extra_attrs: dict[str, Any] | None = None) -> dict[str, Any]:
        """The keyword arguments :meth:`Run.finish` (:func:`mrfpe.posterior.build`) needs
        for these chains: ``chain`` (:meth:`chain`) and, for an ``ensemble``,
        ``extra_attrs`` with ``chain_type="ensemble"`` (merged into ``extra_attrs``).

        >>> run.finish(theta, lp, None, sampler=..., config=..., seed=seed,
        ...            **kept.build_kwargs())                          # doctest: +SKIP
        """
        attrs = dict(extra_attrs or {})
        if self.ensemble:
            attrs["chain_type"] = "ensemble"
        return {"chain": self.chain(), **({"extra_attrs": attrs} if attrs else {})}


class ChainStart(NamedTuple):
    """The opening of an MCMC run (:func:`start_chains`)."""

    bounds: np.ndarray  # (d, 2), validated
    rng: np.random.Generator  # every random choice of the run, from ``seed``
    run: Run  # the run log (evaluation count, MAP trace, progress, callback)
    x: np.ndarray  # (C, d) the chains' starting states, in the support
    log_target: np.ndarray  # (C,) their log densities
    kept: KeptStates  # the record of the kept states


def start_chains(target: Any, seed: int | None, *, n_steps: int, n_chains: int, burn_in: int,
                 thin: int, desc: str, progress: bool = False,
                 callback: Callable[[int, dict], Any] | None = None,
                 weighted: bool = False, ensemble: bool = False) -> ChainStart:
    """Open an MCMC run of ``n_chains`` chains of ``n_steps`` steps on ``target``.

    Validates the target (:func:`check_target`) and ``seed``, seeds the random
    stream, opens the :class:`Run` (its memory check counts the kept states and the
    burn-in), draws the starting states uniformly in the support
    (:func:`draw_in_support`, counted) and prepares :class:`KeptStates` (with
    weights when ``weighted``; of one ensemble's walkers when ``ensemble``). ``desc``
    names the progress bar.
    """
    bounds = check_target(target)
    check_seed(seed)
    rng = np.random.default_rng(seed)
    run = Run(target, n_steps, progress=progress, callback=callback, desc=desc,
              rows=n_steps + n_chains * (n_steps // thin + burn_in + 4))
    x, lp = draw_in_support(run, target, rng, n_chains, bounds)
    kept = KeptStates(n_steps, burn_in, thin, n_chains, bounds.shape[0], weighted=weighted,
                      ensemble=ensemble)
    return ChainStart(bounds, rng, run, x, lp, kept)
