"""Multiple-seed NLopt maximisation of ``log_prob`` (any NLopt algorithm; thesis 7.3.2's seeds).

One NLopt run per seed point (:mod:`mrfpe.samplers.multistart`); see
:class:`NLoptMultiSeed` and :mod:`mrfpe.samplers.multiseed`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.samplers.base import check_positive_int, check_range
from mrfpe.samplers.kit import Run
from mrfpe.samplers.multistart import MultiSeedOptimiser

__all__ = ["NLoptMultiSeed"]


class NLoptMultiSeed(MultiSeedOptimiser):
    """Multiple-seed NLopt maximisation of ``log_prob`` (any algorithm; default LN_BOBYQA).

    The same seed points as ``lm_multiseed`` (7.3.2), with the box passed to
    NLopt as bounds. NLopt needs finite objective values, so ``-inf`` (outside
    the support) is replaced by ``neg_inf_value`` (default −1e30: far below any
    log density, and squares stay finite inside BOBYQA's quadratic models).
    Gradient-based algorithms (``LD_*``, ``GD_*``) get central differences with
    step ``fd_step`` × range (one batched ``log_prob`` call of 2·d rows,
    one-sided at the faces); algorithms that need a subsidiary local optimiser
    (``*MLSL*``, ``AUGLAG*``) get LN_BOBYQA with the same tolerances.
    Stochastic algorithms are seeded per seed point from ``seed``
    (``nlopt.srand``). Each optimum is the best point the objective saw.

    Parameters
    ----------
    algorithm : str
        NLopt algorithm name, e.g. ``"LN_BOBYQA"``, ``"LN_NELDERMEAD"``,
        ``"LD_LBFGS"``, ``"GN_DIRECT_L"``.
    n_seeds : int
        Number of seed points (512, 7.3.2).
    seed_grid : ``"even"`` | ``"shifted"``
        The thesis's grid, or the grid shifted by a random offset (module docs).
    xtol_rel, ftol_abs : float
        NLopt stopping tolerances (0 disables one).
    max_evals : int
        Objective evaluations per seed.
    initial_step : float
        Initial step of derivative-free algorithms, as a fraction of each range.
    fd_step : float
        Finite-difference step for gradient-based algorithms (fraction of range).
    neg_inf_value : float
        Finite stand-in for ``-inf``.
    """

    name = "nlopt_multiseed"

    def __init__(self, algorithm: str = "LN_BOBYQA", n_seeds: int = 512,
                 seed_grid: str = "even", xtol_rel: float = 1e-6, ftol_abs: float = 1e-9,
                 max_evals: int = 500, initial_step: float = 0.05, fd_step: float = 1e-6,
                 neg_inf_value: float = -1e30):
        if not isinstance(algorithm, str) or not algorithm.isidentifier():
            raise ValueError(f"algorithm must be an NLopt algorithm name such as 'LN_BOBYQA'; "
                             f"got {algorithm!r}")
        import nlopt

        family = algorithm.split("_")[0]
        if not isinstance(getattr(nlopt, algorithm, None), int) or not (
                (family in ("LN", "LD", "GN", "GD", "G") and "_" in algorithm)
                or algorithm.startswith("AUGLAG")):
            raise ValueError(f"algorithm must be an NLopt algorithm name such as 'LN_BOBYQA'; "
                             f"got {algorithm!r}")
        self.algorithm = algorithm
        self._check_common(n_seeds, seed_grid)
        self.xtol_rel = check_range("xtol_rel", xtol_rel, 0.0, 1.0, high_open=True)
        self.ftol_abs = check_range("ftol_abs", ftol_abs, 0.0, np.inf, high_open=True)
        self.max_evals = check_positive_int("max_evals", max_evals)
        self.initial_step = check_range("initial_step", initial_step, 0.0, 1.0, low_open=True)
        self.fd_step = check_range("fd_step", fd_step, 0.0, 0.1, low_open=True)
        self.neg_inf_value = check_range("neg_inf_value", neg_inf_value, -1e300, 0.0,
                                         high_open=True)

    def _gradient(self, target: Any, x: np.ndarray, f0: float, run: Run,
                  bounds: np.ndarray) -> np.ndarray:
        """Central differences of log_prob at x in one batched call (one-sided at faces)."""
        d = x.size
        h = self.fd_step * (bounds[:, 1] - bounds[:, 0])
        up = np.minimum(x + h, bounds[:, 1])
        dn = np.maximum(x - h, bounds[:, 0])
        pts = np.repeat(x[None, :], 2 * d, axis=0)
        pts[np.arange(d), np.arange(d)] = up
        pts[d + np.arange(d), np.arange(d)] = dn
        f = run.evaluate(target, pts)
        f = np.where(np.isfinite(f), f, self.neg_inf_value)
        return (f[:d] - f[d:]) / (up - dn)

    def _optimise(self, target: Any, x0: np.ndarray, run: Run, bounds: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, dict[str, float]]:
        import nlopt

        d = x0.size
        alg = getattr(nlopt, self.algorithm)
        best = {"x": x0.copy(), "f": -np.inf, "n": 0}

        def objective(x: np.ndarray, grad: np.ndarray) -> float:
            f = float(run.evaluate(target, x[None, :])[0])
            best["n"] += 1
            if f > best["f"]:
                best["x"], best["f"] = x.copy(), f
            f = f if np.isfinite(f) else self.neg_inf_value
            if grad.size:
                grad[:] = self._gradient(target, x, f, run, bounds)
            return f

        def configure(o: Any) -> None:
            o.set_lower_bounds(bounds[:, 0])
            o.set_upper_bounds(bounds[:, 1])
            o.set_xtol_rel(self.xtol_rel)
            o.set_ftol_abs(self.ftol_abs)
            o.set_maxeval(self.max_evals)
            o.set_initial_step(self.initial_step * (bounds[:, 1] - bounds[:, 0]))

        nlopt.srand(int(rng.integers(2**31 - 1)))
        opt = nlopt.opt(alg, d)
        configure(opt)
        if "MLSL" in self.algorithm or self.algorithm.startswith("AUGLAG"):
            local = nlopt.opt(nlopt.LN_BOBYQA, d)
            configure(local)
            opt.set_local_optimizer(local)
        opt.set_max_objective(objective)
        try:
            opt.optimize(x0.copy())
            status = float(opt.last_optimize_result())
        except (nlopt.RoundoffLimited, RuntimeError):  # keep the best point seen
            status = -4.0
        return best["x"], {"n_fev": float(best["n"]), "status": status}
