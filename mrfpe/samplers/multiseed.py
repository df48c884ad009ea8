"""Multiple-seed local optimisers: Levenberg–Marquardt (thesis 7.3.1–7.3.2) and NLopt.

Both start one local optimisation from each of ``n_seeds`` evenly spaced points
of the parameter box (512 by default, 7.3.2 step 1: "seeds ... distributed as
the samples in Fig. 7.15", i.e. the same grid as PMC's initial set,
:func:`mrfpe.samplers.kit.grid`; 8³ cell centres in 3-D). The optima are the
sample set, each weighted by its target value (``log_weight = log_target``), so
the posterior's MAP is the best optimum and the set can be compared with the
samplers' sets. The best-so-far trace runs over the seed index (step = seed),
which is what Figs. 7.3–7.6 plot against the number of seeds.

``seed_grid="even"`` (default) is the thesis's deterministic grid, so the
``seed`` argument changes nothing there except NLopt's stochastic algorithms;
``"shifted"`` moves the whole grid by one uniform random offset of at most half
a cell per axis (a randomised lattice — still evenly spaced) drawn from
``seed``, for studies of the spread due to seed placement.

These are optimisers, not samplers: the optima do not represent the
posterior's spread: the posterior is built with ``kind="optima"``, which the
conformance moment check, ``diagnose`` and the distances recognise.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import numpy as np

from mrfpe.samplers.base import Callback, Sampler, check_choice, check_positive_int, check_range
from mrfpe.samplers.kit import Run, check_seed, check_target, grid, map_batched

__all__ = ["LMMultiSeed", "NLoptMultiSeed", "seed_points"]

#: Stand-in for a non-finite residual (1/p with p = 0 in 7.10): large, but its
#: square summed over 10⁶ nodes stays far from overflow.
NONFINITE_RESIDUAL = 1e50
_FD_STEP = float(np.sqrt(np.finfo(np.float64).eps))
_GRIDS = ("even", "shifted")
_CONFORMANCE = {
    # The randomly shifted grid makes the seed matter, for the reproducibility check.
    "quick_config": {"n_seeds": 27, "seed_grid": "shifted"},
}


def seed_points(bounds: np.ndarray, n: int, kind: str = "even",
                rng: np.random.Generator | None = None) -> np.ndarray:
    """The ``n`` starting points (n, d): the evenly spaced grid of 7.3.2, optionally shifted.

    ``kind="shifted"`` adds one offset per axis, uniform within ± half the grid
    spacing on that axis, to every point (so the points stay inside the box).
    """
    pts = grid(bounds, n)
    if kind == "even":
        return pts
    if rng is None:
        raise ValueError("a shifted seed grid needs rng")
    width = bounds[:, 1] - bounds[:, 0]
    half = np.empty(bounds.shape[0])
    for j in range(bounds.shape[0]):
        gaps = np.diff(np.unique(pts[:, j]))
        half[j] = 0.5 * (gaps.min() if gaps.size else width[j])
    return np.clip(pts + rng.uniform(-half, half), bounds[:, 0], bounds[:, 1])


class _IterationBudget(Exception):
    """Raised from the Jacobian callback when ``max_iterations`` is used up (carries z)."""

    def __init__(self, z: np.ndarray):
        super().__init__("LM iteration budget used up")
        self.z = z


class _MultiSeed(Sampler):
    """Shared driver: one local optimisation per seed point, optima as the sample set."""

    conformance = _CONFORMANCE

    def _check_common(self, n_seeds: int, seed_grid: str) -> None:
        self.n_seeds = check_positive_int("n_seeds", n_seeds)
        self.seed_grid = check_choice("seed_grid", seed_grid, _GRIDS)

    def _optimise(self, target: Any, x0: np.ndarray, run: Run, bounds: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, dict[str, float]]:
        raise NotImplementedError  # pragma: no cover

    def _prepare(self, target: Any, bounds: np.ndarray) -> None:
        """Check target requirements before any evaluation (override)."""

    def _optimise_all(self, target: Any, starts: np.ndarray, run: Run, bounds: np.ndarray,
                      rng: np.random.Generator) -> Iterator[tuple[np.ndarray, dict[str, float]]]:
        """Each seed's ``(optimum, stats)`` in seed order (override to run them together)."""
        for x0 in starts:
            yield self._optimise(target, x0, run, bounds, rng)

    def run(self, target: Any, *, seed: int | None, progress: bool = False,
            callback: Callback | None = None):
        """Optimise from every seed point and return the posterior Dataset."""
        bounds = check_target(target)
        check_seed(seed)
        self._prepare(target, bounds)
        rng = np.random.default_rng(seed)
        starts = seed_points(bounds, self.n_seeds, self.seed_grid, rng)
        # the first step is one optimum: a small support may need several seeds to find
        run = Run(target, starts.shape[0], progress=progress, callback=callback, desc=self.name,
                  check_first_step=False)
        opt = np.empty_like(starts)
        lt = np.empty(starts.shape[0])
        info: dict[str, list[float]] = {}
        for i, (x, stats) in enumerate(self._optimise_all(target, starts, run, bounds, rng)):
            opt[i] = np.clip(x, bounds[:, 0], bounds[:, 1])
            lt[i] = run.evaluate(target, opt[i:i + 1])[0]
            run.offer(opt[i:i + 1], lt[i:i + 1])
            for k, v in stats.items():
                info.setdefault(k, []).append(v)
            run.step(i, np.nan, **{k: float(v) for k, v in stats.items()})
        extra = {"seed_theta": (("sample", "param"), starts)}
        extra.update({k: (("sample",), np.asarray(v, dtype=np.float64)) for k, v in info.items()})
        return run.finish(opt, lt, lt, sampler=self.name, config=self.get_config(), seed=seed,
                          extra_vars=extra, kind="optima")


class LMMultiSeed(_MultiSeed):
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
        same kernel pass as the residuals (:mod:`mrfpe.targets.jacobian`) where
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
        (:func:`mrfpe.targets.jacobian.residuals_and_jacobians`), so batching seeds
        changes no optimum.
        """
        from mrfpe.targets import jacobian as _jac

        r, jt = _jac.residuals_and_jacobians(target, self._to_theta(zs, lo, hi))
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

        from mrfpe.targets import jacobian as _jac
        from mrfpe.threads import limit_threads

        cost = float(getattr(target, "cost", 1.0))
        lo, hi = bounds[:, 0], bounds[:, 1]
        lock = threading.Lock()  # one kernel call at a time: the caller's between seeds too
        analytic = self.jacobian == "batched" and _jac.supports(target)
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


class NLoptMultiSeed(_MultiSeed):
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
