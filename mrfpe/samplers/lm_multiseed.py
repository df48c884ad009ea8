"""Multiple-seed Levenberg–Marquardt on the target's error vector (thesis 7.3.1–7.3.2).

One MINPACK run per seed point (:mod:`mrfpe.samplers.multistart`), on the
per-node error vector of 7.10; see :class:`LMMultiSeed` and
:mod:`mrfpe.samplers.multiseed`.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import numpy as np

from mrfpe.samplers.base import check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import Run, map_batched
from mrfpe.samplers.multistart import MultiSeedOptimiser
from mrfpe.targets.base import has_residual_jacobian

__all__ = ["NONFINITE_RESIDUAL", "LMMultiSeed"]

#: Stand-in for a non-finite residual (1/p with p = 0 in 7.10): large, but its
#: square summed over 10⁶ nodes stays far from overflow.
NONFINITE_RESIDUAL = 1e50
_FD_STEP = float(np.sqrt(np.finfo(np.float64).eps))


class _IterationBudget(Exception):
    """Raised from the Jacobian callback when ``max_iterations`` is used up (carries z)."""

    def __init__(self, z: np.ndarray):
        super().__init__("LM iteration budget used up")
        self.z = z


class LMMultiSeed(MultiSeedOptimiser):
    """Multiple-seed Levenberg–Marquardt on the target's error vector (7.10–7.12, 7.3.2).

    Each seed runs ``scipy.optimize.least_squares(method="lm")`` (MINPACK) on
    ``target.residuals(θ)`` — the per-node error vector ε(i) = 1/p(x_i | x_N_i, θ)
    of 7.10 for the pseudolikelihood targets — returning [θ_min, err] as 7.12.
    LM is unbounded, so it works on unconstrained z with

    * ``transform="sine"`` (default): θ = lo + (hi − lo)(1 + sin z)/2 — smooth,
      every z maps into the box, the seed maps back by arcsin (MINUIT's
      bounded-parameter transform);
    * ``transform="clip"``: θ = clip(z, lo, hi) — the residuals are flat outside
      the box, so LM can stall on a face.

    Non-finite residuals (a node with p = 0) are replaced by
    ``NONFINITE_RESIDUAL`` so MINPACK keeps finite arithmetic. Every residual
    evaluation, including MINPACK's finite-difference Jacobian columns, counts
    as one target evaluation (``target.cost``), plus one ``log_prob`` per optimum
    (``n_evals`` per seed counts the residual evaluations).
    The optimum's 7.12 ``err`` is kept per seed as ``lm_cost`` (½‖ε‖²): 7.3.2
    step 13 ranks seeds by it, while ``map_theta`` ranks them by the target.

    Parameters
    ----------
    n_seeds : int
        Number of seed points (512, 7.3.2).
    seed_grid : ``"even"`` | ``"shifted"``
        The thesis's grid, or the grid shifted by a random offset (module docs).
    transform : ``"sine"`` | ``"clip"``
        How the bounded box is mapped for the unbounded LM.
    jacobian : ``"batched"`` | ``"minpack"``
        ``"batched"`` (default): the analytic Jacobian of the residuals from the
        same kernel pass as the residuals (the target's ``residuals_and_jacobians``, e.g.
        :mod:`mrfpe.brdf.targets.jacobian`) where
        the target supports it (the BRDF pseudolikelihood family; that pass
        counts as one evaluation), else MINPACK lmdif's forward-difference Jacobian
        (step √eps·|z_j|) computed in one batched ``residuals`` call of d rows;
        ``"minpack"``: the same differences column by column, d single calls (as
        lmdif makes them) — the same derivative estimate, about twice the time on
        a pseudolikelihood target, whose batched evaluation is cheaper per row.
        Either way scipy runs MINPACK's lmder with this Jacobian function.
    ftol, xtol, gtol : float
        MINPACK's tolerances (scipy's defaults, 1e-8).
    max_nfev : int
        Residual evaluations per seed, not counting the Jacobian's (0: scipy's
        default, 100·d); not an iteration budget, since a rejected trial step costs
        an evaluation too.
    max_iterations : int
        LM iterations per seed (0: no limit), the thesis's budget (Table 8.12: 10
        iterations): an iteration is one Jacobian evaluation (MINPACK's ``njev``) and
        the trial steps that follow it; the seed's optimum is the iterate at which
        the next Jacobian is asked for (``status`` 0 then, scipy's code for a spent
        budget).
    concurrent_seeds : int
        Seeds optimised at once, each MINPACK run in a thread of its own, their
        residual-and-Jacobian points evaluated together in one kernel pass
        (:func:`mrfpe.samplers.kit.map_batched`) -- with the analytic Jacobian only.
        K points in one pass share its reads of the tables (Ward 100×100, 20 labels,
        float64, one core: 3.1 ms per point alone, 1.9 ms from K = 8 on). Every seed
        sees the numbers it would see alone, so the optima are the same, bit for bit,
        as with 1 (one seed at a time).
    """

    name = "lm_multiseed"

    def __init__(self, n_seeds: int = 512, seed_grid: str = "even", transform: str = "sine",
                 jacobian: str = "batched", ftol: float = 1e-8, xtol: float = 1e-8,
                 gtol: float = 1e-8, max_nfev: int = 0, max_iterations: int = 0,
                 concurrent_seeds: int = 32):
        self._check_common(n_seeds, seed_grid)
        self.concurrent_seeds = check_positive_int("concurrent_seeds", concurrent_seeds)
        self.transform = check_choice("transform", transform, ("sine", "clip"))
        self.jacobian = check_choice("jacobian", jacobian, ("batched", "minpack"))
        self.ftol = check_range("ftol", ftol, 0.0, 1.0, high_open=True)
        self.xtol = check_range("xtol", xtol, 0.0, 1.0, high_open=True)
        self.gtol = check_range("gtol", gtol, 0.0, 1.0, high_open=True)
        if self.ftol == self.xtol == self.gtol == 0.0:
            raise ValueError("at least one of ftol, xtol, gtol must be > 0")
        self.max_nfev = check_positive_int("max_nfev", max_nfev, minimum=0)
        self.max_iterations = check_positive_int("max_iterations", max_iterations, minimum=0)

    def _prepare(self, target: Any, bounds: np.ndarray) -> None:
        if not callable(getattr(target, "residuals", None)):
            raise ValueError(f"lm_multiseed needs a target with residuals(theta) (the error "
                             f"vector of 7.10); {type(target).__name__} has none — use a "
                             f"pseudolikelihood target or nlopt_multiseed")

    def _to_theta(self, z: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        if self.transform == "sine":
            return lo + (hi - lo) * 0.5 * (1.0 + np.sin(z))
        return np.clip(z, lo, hi)

    def _to_z(self, x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        if self.transform == "sine":
            return np.arcsin(np.clip(2.0 * (x - lo) / (hi - lo) - 1.0, -1.0, 1.0))
        return x.copy()

    def _analytic_rows(self, target: Any, zs: np.ndarray, lo: np.ndarray,
                       hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Residuals and their Jacobian in z at each row of ``zs`` (K, d), in one kernel pass.

        Row by row the numbers are those of a single-point call
        (the target's ``residuals_and_jacobians``), so batching seeds changes no optimum.
        """
        r, jt = target.residuals_and_jacobians(self._to_theta(zs, lo, hi))
        rows = []
        for q, z in enumerate(zs):
            dth = (0.5 * (hi - lo) * np.cos(z) if self.transform == "sine"
                   else ((z >= lo) & (z <= hi)).astype(float))
            ok = np.isfinite(r[q])
            rows.append((np.where(ok, r[q], NONFINITE_RESIDUAL),
                         np.where(ok[:, None], jt[q] * dth[None, :], 0.0)))
        return rows

    def _optimise_all(self, target: Any, starts: np.ndarray, run: Run, bounds: np.ndarray,
                      rng: np.random.Generator) -> Iterator[tuple[np.ndarray, dict[str, float]]]:
        """The seeds one at a time, or ``concurrent_seeds`` at a time with their
        residual-and-Jacobian passes batched (:func:`mrfpe.samplers.kit.map_batched`)."""
        import numba

        from mrfpe.threads import limit_threads

        cost = float(getattr(target, "cost", 1.0))
        lo, hi = bounds[:, 0], bounds[:, 1]
        lock = threading.Lock()  # one kernel call at a time: the caller's between seeds too
        analytic = self.jacobian == "batched" and has_residual_jacobian(target)
        if analytic and self.concurrent_seeds > 1:
            threads = numba.get_num_threads()  # numba's setting is per thread: carry it over

            def batch(zs: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
                with lock, limit_threads(threads):
                    return self._analytic_rows(target, zs, lo, hi)

            results = map_batched(
                lambda x0, rows: self._optimise(target, x0, run, bounds, rng, rows),
                starts, batch, self.concurrent_seeds)
        else:
            def one(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                return self._analytic_rows(target, z[None, :], lo, hi)[0]

            results = (self._optimise(target, x0, run, bounds, rng, one if analytic else None)
                       for x0 in starts)
        for x, stats in results:
            run.n_evals += cost * stats["n_evals"]
            with lock:  # held while the caller evaluates this optimum
                yield x, stats

    def _optimise(self, target: Any, x0: np.ndarray, run: Run, bounds: np.ndarray,
                  rng: np.random.Generator, rows: Any = None,
                  ) -> tuple[np.ndarray, dict[str, float]]:
        """One seed's LM. ``rows(z)``: the residuals and their analytic Jacobian at z
        (None: forward differences of ``target.residuals``). Counts its residual
        evaluations in ``stats["n_evals"]``; the caller adds them to ``run``, so that
        concurrent seeds do not race on the count."""
        from scipy.optimize import least_squares

        lo, hi = bounds[:, 0], bounds[:, 1]
        count = [0]
        last: dict[str, np.ndarray] = {}

        def residuals(zs: np.ndarray) -> np.ndarray:  # (k, d) -> (k, m), one batched call
            count[0] += zs.shape[0]
            r = np.asarray(target.residuals(self._to_theta(zs, lo, hi)), dtype=np.float64)
            r = r.reshape(zs.shape[0], -1)
            return np.where(np.isfinite(r), r, NONFINITE_RESIDUAL)

        analytic = rows is not None

        def fun(z: np.ndarray) -> np.ndarray:
            if analytic:  # residuals and their analytic Jacobian in one kernel pass
                count[0] += 1
                last["z"] = z.copy()
                last["r"], last["J"] = rows(z)
                return last["r"]
            last["z"], last["r"] = z.copy(), residuals(z[None, :])[0]
            return last["r"]

        def jac(z: np.ndarray) -> np.ndarray:
            if self.max_iterations and n_jac[0] >= self.max_iterations:
                raise _IterationBudget(z.copy())
            n_jac[0] += 1
            if analytic:
                if not ("J" in last and np.array_equal(last["z"], z)):
                    fun(z)
                return last["J"]
            # lmdif's forward differences (step sqrt(eps)·|z_j|), all d columns in one
            # batched call or column by column; MINPACK evaluated r(z) just before J(z).
            r0 = last["r"] if "z" in last and np.array_equal(last["z"], z) else fun(z)
            h = _FD_STEP * np.where(z == 0.0, 1.0, np.abs(z))
            zs = z[None, :] + np.diag(h)
            rows_fd = (residuals(zs) if self.jacobian == "batched"
                       else np.vstack([residuals(zs[j:j + 1]) for j in range(z.size)]))
            return ((rows_fd - r0) / h[:, None]).T

        n_jac = [0]
        z0 = self._to_z(x0, lo, hi)
        m = fun(z0).size
        if m < x0.size:
            raise ValueError(f"target.residuals returned {m} values for {x0.size} parameters; "
                             "Levenberg–Marquardt needs at least as many residuals as parameters")
        try:
            res = least_squares(fun, z0, jac=jac, method="lm", ftol=self.ftol or None,
                                xtol=self.xtol or None, gtol=self.gtol or None,
                                max_nfev=self.max_nfev or None)
            z, lm_cost, status = res.x, float(res.cost), float(res.status)
        except _IterationBudget as stop:  # MINPACK evaluated r at the iterate just before
            z = stop.z
            r = last["r"] if np.array_equal(last["z"], z) else fun(z)
            lm_cost, status = 0.5 * float(r @ r), 0.0  # 0: the budget ran out (scipy's code)
        return self._to_theta(z, lo, hi), {"lm_cost": lm_cost, "n_evals": float(count[0]),
                                           "status": status}
