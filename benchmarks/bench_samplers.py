"""Sampler efficiency: evaluations and seconds until the MAP is within ``--tol`` of the truth.

On synthetic Ward scenes (``make_scene(brdf="ward", shape=(100, 100), n_labels=20)``
with random true parameters in [0.05, 0.95]^3 of the unit cube, the ``pls``
target, 7.5-7.7) each sampler runs with its default, thesis-sized budget
(``pmc`` 1000 x 20, ``emcee`` 32 x 625, ``dw_r`` 20000 steps, ``lm_multiseed``
512 seeds). A ``callback`` records, after every step, the full-lattice-equivalent
evaluations so far, the wall time and the best-so-far parameters, from which the
script reports

* ``evals@tol`` / ``s@tol``: evaluations and seconds until the MAP first comes
  within ``--tol`` (unit-cube distance) of the true parameters (``-`` if never);
* the same against the PL maximiser (:func:`mrfpe.targets.maximise`, cached), since
  a pseudolikelihood's maximum need not sit on the truth;
* the final MAP's distances to both, the total evaluations and time.

Usage::

    python -m benchmarks.bench_samplers --scenes 2
    python -m benchmarks.bench_samplers --scenes 1 --shape 40 40 --samplers dw_r emcee

The first ``log_prob`` calls include numba compilation: a warm-up evaluation
runs before the timed runs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks._common import (
    append_results,
    cached_maximiser,
    command_line,
    machine,
    markdown_table,
    ward_scene_target,
)

SAMPLERS = ("pmc", "emcee", "dw_r", "lm_multiseed")


def first_within(trace: list[tuple[float, float, np.ndarray]], point: np.ndarray,
                 tol: float) -> tuple[float, float]:
    """(evaluations, seconds) at the first step whose MAP is within ``tol`` of ``point``."""
    for evals, secs, m in trace:
        if m is not None and np.all(np.isfinite(m)) and np.linalg.norm(m - point) <= tol:
            return evals, secs
    return np.nan, np.nan


def run_one(name: str, target, seed: int, config: dict) -> tuple[list, object]:
    """Run sampler ``name``; return the per-step (evals, seconds, MAP) trace and the posterior."""
    import mrfpe

    trace: list[tuple[float, float, np.ndarray]] = []
    t0 = time.perf_counter()

    def callback(step: int, info: dict) -> None:
        m = info.get("map_theta")
        trace.append((float(info.get("n_target_evals", np.nan)), time.perf_counter() - t0,
                      None if m is None else np.array(m, dtype=float)))

    post = mrfpe.sample(name, target, seed=seed, callback=callback, **config)
    return trace, post


def run(samplers: list[str], scenes: range, shape: tuple[int, int], n_labels: int,
        tol: float = 0.05, seed: int = 0, configs: dict | None = None,
        out: Path | None = None) -> tuple[list[dict], list[str]]:
    """Run every sampler on every scene; the rows and a markdown body with ratios to PMC."""
    configs = configs or {}
    tag = f"{shape[0]}x{shape[1]}_{n_labels}"
    rows = []
    for i in scenes:
        u, target = ward_scene_target(i, shape, n_labels)
        target.log_prob(np.full((1, 3), 0.5))  # compile the kernels outside the timings
        xm = cached_maximiser(i, target, tag)[0]
        print(f"scene {i}: truth {u.round(3)}  PL maximiser {xm.round(3)} "
              f"(|max - truth| {np.linalg.norm(xm - u):.3f})", flush=True)
        for name in samplers:
            trace, post = run_one(name, target, seed, configs.get(name, {}))
            m = post["map_theta"].values[-1]
            e_true, s_true = first_within(trace, u, tol)
            e_max, s_max = first_within(trace, xm, tol)
            row = {"scene": i, "sampler": name, "evals@tol": e_true, "s@tol": s_true,
                   "evals@tol_max": e_max, "s@tol_max": s_max,
                   "d_true": float(np.linalg.norm(m - u)), "d_max": float(np.linalg.norm(m - xm)),
                   "d_max_true": float(np.linalg.norm(xm - u)),
                   "evals": float(post.attrs["n_target_evals"]),
                   "time_s": float(post.attrs["wall_time_s"])}
            rows.append(row)
            print("  " + "  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                   for k, v in row.items() if k != "scene"), flush=True)
            if out:
                with out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    return rows, summary(rows, samplers, tol, shape, n_labels)


def summary(rows: list[dict], samplers: list[str], tol: float, shape: tuple[int, int],
            n_labels: int) -> list[str]:
    """Markdown: per sampler, means over scenes, and evals / seconds as ratios to ``pmc``."""
    def mean(sel: list[dict], key: str) -> float:
        v = np.array([r[key] for r in sel], dtype=float)
        return float(np.nanmean(v)) if np.isfinite(v).any() else np.nan

    stats = {}
    for name in samplers:
        sel = [r for r in rows if r["sampler"] == name]
        stats[name] = {k: mean(sel, k) for k in ("evals@tol", "s@tol", "evals@tol_max",
                                                 "s@tol_max", "d_true", "d_max", "evals",
                                                 "time_s")}
        stats[name]["hit"] = sum(np.isfinite(r["evals@tol"]) for r in sel)
        stats[name]["hit_max"] = sum(np.isfinite(r["evals@tol_max"]) for r in sel)
    ref = stats.get("pmc")

    def ratio(st: dict, k: str) -> float:
        return st[k] / ref[k] if ref and np.isfinite(ref[k]) and ref[k] else np.nan

    n_scenes = len(rows) // max(1, len(samplers))
    table_rows = []
    for name, st in stats.items():
        table_rows.append([name, f"{st['hit']}/{n_scenes}", st["evals@tol"],
                           st["s@tol"], ratio(st, "evals@tol"), ratio(st, "s@tol"),
                           f"{st['hit_max']}", st["evals@tol_max"], ratio(st, "evals@tol_max"),
                           st["d_true"], st["d_max"], st["evals"], st["time_s"]])
    d_mt = float(np.mean([r["d_max_true"] for r in rows])) if rows else np.nan
    return [
        f"Ward `pls`, {shape[0]}x{shape[1]}, {n_labels} labels, {n_scenes} scene(s), each "
        f"sampler at its default (thesis-sized) budget. `@truth`: first step whose MAP is "
        f"within {tol} (unit cube) of the true parameters; `@max`: of the PL maximiser "
        f"(which lies {d_mt:.3f} from the truth on average). Evaluations are "
        f"full-lattice equivalents; ratios are to `pmc` in the same run (means over the "
        f"scenes that reached the tolerance; `-` where none did).\n",
        markdown_table(["sampler", "hit", "evals@truth", "s@truth", "evals ÷ pmc",
                        "s ÷ pmc", "hit max", "evals@max", "evals@max ÷ pmc", "final d_true",
                        "final d_max", "evals", "time s"], table_rows)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--scenes", type=int, default=2)
    p.add_argument("--first", type=int, default=0, help="index of the first scene")
    p.add_argument("--samplers", nargs="+", default=list(SAMPLERS))
    p.add_argument("--tol", type=float, default=0.05)
    p.add_argument("--shape", type=int, nargs=2, default=[100, 100])
    p.add_argument("--n-labels", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", nargs="*", default=[], metavar="SAMPLER.KEY=VALUE",
                   help="sampler setting, value as JSON, e.g. dw_r.n_steps=5000")
    p.add_argument("--out", type=Path, default=None, help="JSON-lines results file")
    p.add_argument("--write", action="store_true", help="append the summary to RESULTS.md")
    args = p.parse_args(argv)

    configs: dict[str, dict] = {s: {} for s in args.samplers}
    for item in args.set:
        key, raw = item.split("=", 1)
        sampler, setting = key.split(".", 1)
        try:
            configs[sampler][setting] = json.loads(raw)
        except json.JSONDecodeError:
            configs[sampler][setting] = raw
    info = machine()
    _, body = run(args.samplers, range(args.first, args.first + args.scenes),
                  tuple(args.shape), args.n_labels, args.tol, args.seed, configs, args.out)
    print("\n".join(body))
    if args.write:
        append_results("bench_samplers: sampler efficiency",
                       command_line(argv, "benchmarks.bench_samplers"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
