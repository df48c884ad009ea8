"""How well each posterior over Ising parameters matches the exact Bayesian posterior.

For every case θ = (coupling, field) and data set (one 10 x 10 Ising configuration simulated at
θ) this computes the exact posterior p(θ | x) ∝ p(x | θ) (flat prior on the target's bounds,
log Z by variable elimination) on a grid, and beside it:

* ``pl_grid``        exp(PL) on its own grid (the pseudo-posterior's exact moments);
* ``pl_pmc``         PMC (defaults) on the ``"pl"`` target;
* ``adj_grid``       the ``"pl_adjusted"`` target (default options) on a grid (target error alone);
* ``pl_adjusted``    PMC (defaults) on ``"pl_adjusted"`` (construction + sampling);
* ``adj_grid_mode``, ``pl_adjusted_mode``  the same with ``align="mode"`` (the mode at the MLE and
                     the Fisher curvature there: Bouranis, Friel & Maire 2017);
* ``exchange``       the exchange sampler with its defaults on ``"likelihood"``;
* ``bootstrap``      parametric bootstrap of the MPLE (100 refits), a frequentist interval.

Per method and parameter it records (mean - exact mean) / exact sd, sd / exact sd, the 5-95 %
interval and whether it covers the true θ, wall time, simulations (sweeps) where known, the
posterior's ``diag_reliable`` and any warnings. One JSON file per (case, data set) in
``trials/``; a file that exists is skipped, so an interrupted run resumes. Every random choice
flows from a seed derived from the case name and the data-set index.

    python docs/results/calibrated_posteriors/run.py --n-datasets 20
    python docs/results/calibrated_posteriors/run.py --refresh-adjusted   # after a library change
    python docs/results/calibrated_posteriors/run.py --refresh-exchange --shard 0 2  # and 1 2
    python docs/results/calibrated_posteriors/report.py
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import traceback
import warnings
import zlib
from pathlib import Path

import numpy as np

import mrfpe
from mrfpe import models
from mrfpe.models.bootstrap import parametric_bootstrap
from mrfpe.models.calibration import hessian
from mrfpe.targets import maximise

HERE = Path(__file__).resolve().parent
TRIALS = HERE / "trials"
SHAPE = (10, 10)
DATA_SWEEPS = 1000  # Swendsen-Wang sweeps from a random start (tau is a few sweeps here)
GRID = 61  # points per axis of the posterior grids
HALF_WIDTH = 6.0  # grid half-width in (approximate) posterior sd
N_BOOT = 100
STUDY = "calibrated_posteriors/v1"

CASES = {
    "J0.10_h0.00": (0.10, 0.00),
    "J0.30_h0.00": (0.30, 0.00),
    "J0.44_h0.00": (0.44, 0.00),  # the critical coupling of the square lattice, 0.4407
    "J0.30_h0.10": (0.30, 0.10),
}
METHODS = ("pl_grid", "pl_pmc", "adj_grid", "pl_adjusted", "adj_grid_mode", "pl_adjusted_mode",
           "exchange", "bootstrap")


def seeds(case: str, index: int, n: int = 8) -> list[int]:
    """Independent seeds for one trial, from the study name, the case and the data-set index."""
    key = zlib.crc32(f"{STUDY}/{case}".encode())
    return [int(s) for s in np.random.SeedSequence([key, index]).generate_state(n, np.uint64)
            >> np.uint64(1)]


def hessian_sd(target, theta: np.ndarray) -> np.ndarray:
    """Posterior sd from the central-difference Hessian of log_prob at its mode."""
    b = np.asarray(target.bounds, dtype=np.float64)
    H = hessian(target.log_prob, theta, 1e-3 * (b[:, 1] - b[:, 0]))
    return np.sqrt(np.diag(np.linalg.inv(-H)))


def grid_posterior(target, centre: np.ndarray, sd: np.ndarray, *, n: int = GRID,
                   half_width: float = HALF_WIDTH, max_expand: int = 4) -> dict:
    """Moments and quantiles of exp(log_prob) on an n x n grid over centre ± half_width sd.

    The box is clipped to the target's bounds; it is widened (x 1.5) while the density on an
    unclipped edge is above e^-12 of the peak.
    """
    b = np.asarray(target.bounds, dtype=np.float64)
    width = half_width * np.asarray(sd, dtype=np.float64)
    for _ in range(max_expand + 1):
        lo = np.maximum(centre - width, b[:, 0])
        hi = np.minimum(centre + width, b[:, 1])
        axes = [np.linspace(lo[i], hi[i], n) for i in range(2)]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
        lp = np.asarray(target.log_prob(G), dtype=np.float64).reshape(n, n)
        lp = np.where(np.isfinite(lp), lp, -np.inf)
        rel = lp - lp.max()
        edges = {(0, "lo"): rel[0, :], (0, "hi"): rel[-1, :],
                 (1, "lo"): rel[:, 0], (1, "hi"): rel[:, -1]}
        grow = np.zeros(2, bool)
        for (ax, side), e in edges.items():
            clipped = (lo[ax] <= b[ax, 0]) if side == "lo" else (hi[ax] >= b[ax, 1])
            if not clipped and e.max() > -12:
                grow[ax] = True
        if not grow.any():
            break
        width = np.where(grow, 1.5 * width, width)
    w = np.exp(rel)
    w /= w.sum()
    out = {"box": [lo.tolist(), hi.tolist()], "edge_log_density": float(max(
        rel[0].max(), rel[-1].max(), rel[:, 0].max(), rel[:, -1].max()))}
    mean, sd_, q05, q95, skew = [], [], [], [], []
    for ax in range(2):
        marg = w.sum(axis=1 - ax)
        x = axes[ax]
        m = float(marg @ x)
        s = float(np.sqrt(marg @ (x - m) ** 2))
        mean.append(m)
        sd_.append(s)
        skew.append(float(marg @ ((x - m) / s) ** 3))
        cdf = np.cumsum(marg) - 0.5 * marg  # midpoint rule
        q05.append(float(np.interp(0.05, cdf, x)))
        q95.append(float(np.interp(0.95, cdf, x)))
    out.update(mean=mean, sd=sd_, q05=q05, q95=q95, skewness=skew)
    return out


def weighted_quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    order = np.argsort(x)
    x, w = x[order], w[order]
    cdf = np.cumsum(w) - 0.5 * w
    return float(np.interp(q, cdf / w.sum(), x))


def draws_summary(post) -> dict:
    """Weighted mean, sd and 5-95 % quantiles of a posterior Dataset, with its diagnostics."""
    th = post["theta"].values
    if "log_weight" in post:
        lw = post["log_weight"].values
        w = np.exp(lw - lw.max())
    else:
        w = np.ones(th.shape[0])
    w = w / w.sum()
    mean = w @ th
    sd = np.sqrt(w @ (th - mean) ** 2)
    out = {"mean": mean.tolist(), "sd": sd.tolist(),
           "q05": [weighted_quantile(th[:, j], w, 0.05) for j in range(th.shape[1])],
           "q95": [weighted_quantile(th[:, j], w, 0.95) for j in range(th.shape[1])],
           "n_draws": int(th.shape[0]), "ess_kish": float(1.0 / np.sum(w ** 2))}
    for k in ("diag_reliable", "diag_ess", "diag_pareto_k", "diag_rhat", "n_target_evals",
              "wall_time_s", "aux_sweeps", "aux_tau_burn_in", "aux_tau_posterior_mean",
              "simulation_sweeps", "bias"):
        if k in post.attrs:
            v = post.attrs[k]
            out[k] = v.item() if hasattr(v, "item") else v
    msgs = post.attrs.get("diag_messages")
    if msgs is not None:
        out["diag_messages"] = [str(m) for m in np.atleast_1d(msgs)] if len(msgs) else []
    return out


class SweepCounter:
    """Counts the sweeps a likelihood target's simulator runs (wraps the instance's method)."""

    def __init__(self, lik) -> None:
        self.sweeps = 0
        self.calls = 0
        self._sim = lik.simulate
        lik.simulate = self

    def __call__(self, theta, n=None, *, seed=None, init="random", n_sweeps=None, thin=10):
        lik = self._sim.__self__
        sweeps = lik.n_sweeps if n_sweeps is None else n_sweeps
        if isinstance(init, str) and init == "data":
            self.sweeps += sweeps * lik.n_observations
        else:
            m = lik.n_observations if n is None else n
            self.sweeps += sweeps + thin * (m - 1)
        self.calls += 1
        return self._sim(theta, n, seed=seed, init=init, n_sweeps=n_sweeps, thin=thin)


def timed(fn):
    """(result, seconds, warnings) of fn(), or ({"error": ...}, seconds, warnings)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = fn()
        except Exception as exc:
            res = {"error": f"{type(exc).__name__}: {exc}",
                   "traceback": traceback.format_exc(limit=3)}
    msgs = sorted({f"{w.category.__name__}: {str(w.message)[:300]}" for w in caught})
    return res, time.perf_counter() - t0, msgs


def compare(res: dict, exact: dict, truth: np.ndarray) -> dict:
    if "error" in res:
        return res
    em, es = np.array(exact["mean"]), np.array(exact["sd"])
    res["z"] = ((np.array(res["mean"]) - em) / es).tolist()
    res["sd_ratio"] = (np.array(res["sd"]) / es).tolist()
    res["covers"] = [bool(lo <= t <= hi) for lo, hi, t in zip(res["q05"], res["q95"], truth,
                                                            strict=True)]
    return res


def adjusted_methods(m, x, exact: dict, theta: np.ndarray, s: list[int]) -> dict:
    """The adjusted PL: its default options (``adj_grid``, ``pl_adjusted``) and
    ``align="mode"`` (``adj_grid_mode``, ``pl_adjusted_mode``); each built, then on a grid
    (the target's own error) and sampled by PMC (defaults). Both use the same seeds."""
    out: dict = {}
    for suffix, options in (("", {}), ("_mode", {"align": "mode"})):
        box: dict = {}

        def build(options=options, box=box):
            box["t"] = m.target("pl_adjusted", x, seed=s[2], **options)
            return {}

        res, dt_build, w_build = timed(build)
        if "t" not in box:
            out["adj_grid" + suffix] = out["pl_adjusted" + suffix] = {
                **res, "wall_s": dt_build, "warnings": w_build, "options": options}
            continue
        adj = box["t"]
        info = {"theta_mode": adj.theta_ml.tolist(), "theta_mple": adj.theta_pl.tolist(),
                "simulation_sweeps": int(adj.n_simulation_sweeps), "build_s": dt_build,
                "align": getattr(adj, "align", "mode"), "options": options,
                "mcmc_mle_converged": None if adj.mle is None else bool(adj.mle.converged),
                "mcmc_mle_iterations": None if adj.mle is None else int(adj.mle.n_iterations),
                "mcmc_mle": None if adj.mle is None else adj.mle.theta.tolist()}
        sd_adj = np.sqrt(np.diag(np.linalg.inv(adj.fisher_information)))
        res, dt, w = timed(lambda adj=adj, sd_adj=sd_adj: grid_posterior(adj, adj.theta_ml,
                                                                          sd_adj))
        out["adj_grid" + suffix] = {**compare(res, exact, theta), **info,
                                    "wall_s": dt + dt_build, "warnings": w_build + w}
        res, dt, w = timed(lambda adj=adj: draws_summary(mrfpe.sample("pmc", adj, seed=s[3])))
        out["pl_adjusted" + suffix] = {**compare(res, exact, theta), **info,
                                       "wall_s": dt + dt_build, "sample_s": dt,
                                       "warnings": w_build + w}
    out["adjusted_commit"] = library_commit()
    return out


def library_commit() -> str:
    """The repository's HEAD commit, with "+dirty" when mrfpe/ has uncommitted changes."""
    import subprocess

    root = HERE.parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "mrfpe"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def regenerate(path: Path) -> tuple[dict, object, np.ndarray, np.ndarray, list[int]]:
    """A trial file's record, model, data set (regenerated from its seed and checked), θ, seeds."""
    rec = json.loads(path.read_text())
    theta = np.array(rec["theta_true"])
    s = rec["seeds"]
    m = models.ising()
    x = m.simulate(theta, shape=tuple(rec["shape"]), seed=s[0], n_sweeps=rec["data_sweeps"])
    if not math.isclose(float((2 * x - 1).mean()), rec["magnetisation"]):
        raise RuntimeError(f"{path.name}: the data set no longer reproduces from its seed")
    return rec, m, x, theta, s


def write_trial(rec: dict, path: Path) -> None:
    """Write a trial record atomically (a temporary file, then a rename)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(rec, indent=1, default=_json_default))
    os.replace(tmp, path)


def refresh_adjusted(path: Path) -> bool:
    """Recompute the adjusted-PL entries of a trial file with the library as it is now."""
    rec, m, x, theta, s = regenerate(path)
    new = adjusted_methods(m, x, rec["exact"], theta, s)
    rec["adjusted_commit"] = new.pop("adjusted_commit")
    rec["methods"].update(new)
    write_trial(rec, path)
    return True


def exchange_method(m, x, exact: dict, theta: np.ndarray, s: list[int]) -> dict:
    """The exchange sampler with its defaults on the ``"likelihood"`` target."""
    lik = m.target("likelihood", x)
    counter = SweepCounter(lik)
    res, dt, w = timed(lambda: draws_summary(mrfpe.sample("exchange", lik, seed=s[4])))
    return {**compare(res, exact, theta), "wall_s": dt, "warnings": w,
            "simulation_sweeps": counter.sweeps, "simulator_calls": counter.calls}


def refresh_exchange(path: Path) -> bool:
    """Recompute the exchange entry of a trial file with the library as it is now."""
    rec, m, x, theta, s = regenerate(path)
    rec["methods"]["exchange"] = exchange_method(m, x, rec["exact"], theta, s)
    rec["exchange_commit"] = library_commit()
    write_trial(rec, path)
    return True


def run_trial(case: str, index: int) -> dict:
    theta = np.array(CASES[case])
    s = seeds(case, index)
    m = models.ising()
    t_start = time.perf_counter()
    x = m.simulate(theta, shape=SHAPE, seed=s[0], n_sweeps=DATA_SWEEPS)
    rec: dict = {"case": case, "index": index, "theta_true": theta.tolist(),
                 "shape": list(SHAPE), "seeds": s, "data_sweeps": DATA_SWEEPS,
                 "magnetisation": float((2 * x - 1).mean()),
                 "mrfpe_version": mrfpe.__version__, "library_commit": library_commit()}
    # exact posterior
    exact_t = m.target("exact", x)
    t0 = time.perf_counter()
    mle, _ = maximise(exact_t)
    sd0 = hessian_sd(exact_t, mle)
    exact = grid_posterior(exact_t, mle, sd0)
    exact.update(mle=mle.tolist(), hessian_sd=sd0.tolist(), wall_s=time.perf_counter() - t0)
    exact["covers"] = [bool(lo <= t <= hi) for lo, hi, t in
                       zip(exact["q05"], exact["q95"], theta, strict=True)]
    rec["exact"] = exact
    rec["param_names"] = list(exact_t.param_names)
    meth: dict = {}
    pl = m.target("pl", x)

    # (i) exp(PL): on a grid around the MPLE, and by PMC
    def pl_grid():
        mple, _ = maximise(pl)
        g = grid_posterior(pl, mple, hessian_sd(pl, mple))
        g["mple"] = mple.tolist()
        return g

    res, dt, w = timed(pl_grid)
    meth["pl_grid"] = {**compare(res, exact, theta), "wall_s": dt, "warnings": w}
    res, dt, w = timed(lambda: draws_summary(mrfpe.sample("pmc", pl, seed=s[1])))
    meth["pl_pmc"] = {**compare(res, exact, theta), "wall_s": dt, "warnings": w,
                      "simulation_sweeps": 0}

    # (ii) the adjusted pseudolikelihood, default options and align="mode"
    adjusted = adjusted_methods(m, x, exact, theta, s)
    rec["adjusted_commit"] = adjusted.pop("adjusted_commit")
    meth.update(adjusted)

    # (iii) exchange, defaults
    meth["exchange"] = exchange_method(m, x, exact, theta, s)
    rec["exchange_commit"] = library_commit()

    # (iv) parametric bootstrap of the MPLE
    def boot():
        post = parametric_bootstrap(m, x, n_boot=N_BOOT, seed=s[5])
        out = draws_summary(post)
        out["mple"] = np.asarray(post["map_theta"].values).reshape(-1).tolist()
        return out

    res, dt, w = timed(boot)
    meth["bootstrap"] = {**compare(res, exact, theta), "wall_s": dt, "warnings": w}
    rec["methods"] = meth
    rec["wall_s"] = time.perf_counter() - t_start
    return rec


def trial_path(case: str, index: int) -> Path:
    return TRIALS / f"{case}__{index:03d}.json"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n-datasets", type=int, default=20)
    ap.add_argument("--start", type=int, default=0, help="first data-set index")
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--refresh-adjusted", action="store_true",
                    help="recompute the adjusted-PL entries of existing trial files whose "
                         "adjusted_commit differs from the library's HEAD, then stop")
    ap.add_argument("--refresh-exchange", action="store_true",
                    help="recompute the exchange entries of existing trial files whose "
                         "exchange_commit differs from the library's HEAD, then stop")
    ap.add_argument("--shard", type=int, nargs=2, default=(0, 1), metavar=("K", "N"),
                    help="with --refresh-exchange: only files K, K+N, K+2N, ... (one per core)")
    args = ap.parse_args(argv)
    TRIALS.mkdir(parents=True, exist_ok=True)
    if args.refresh_exchange:
        head = library_commit()
        k, n = args.shard
        for path in sorted(TRIALS.glob("*.json"))[k::n]:
            if json.loads(path.read_text()).get("exchange_commit") == head:
                continue
            t0 = time.perf_counter()
            refresh_exchange(path)
            print(f"{path.name}: exchange refreshed at {head} in "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
        return 0
    if args.refresh_adjusted:
        head = library_commit()
        for path in sorted(TRIALS.glob("*.json")):
            if json.loads(path.read_text()).get("adjusted_commit") == head:
                continue
            t0 = time.perf_counter()
            refresh_adjusted(path)
            print(f"{path.name}: adjusted PL refreshed at {head} in "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
        return 0
    # data sets in the outer loop: the first 4k trials hold k data sets of every case
    for index in range(args.start, args.n_datasets):
        for case in args.cases:
            path = trial_path(case, index)
            if path.exists():
                continue
            rec = run_trial(case, index)
            write_trial(rec, path)
            ex = rec["methods"]["exchange"]
            print(f"{case} #{index}: {rec['wall_s']:.1f} s; exchange z "
                  f"{np.round(ex.get('z', [math.nan] * 2), 2).tolist()} ratio "
                  f"{np.round(ex.get('sd_ratio', [math.nan] * 2), 2).tolist()}", flush=True)
    return 0


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


if __name__ == "__main__":
    sys.exit(main())
