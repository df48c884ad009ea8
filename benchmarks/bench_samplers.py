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

    python benchmarks/bench_samplers.py --scenes 2
    python benchmarks/bench_samplers.py --scenes 1 --shape 40 40 --samplers dw_r emcee

The first ``log_prob`` calls include numba compilation: a warm-up evaluation
runs before the timed runs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

SAMPLERS = ("pmc", "emcee", "dw_r", "lm_multiseed")


def scene_and_target(i: int, shape: tuple[int, int], n_labels: int):
    """Scene ``i``: random true parameters (unit cube) and its ``pls`` target."""
    import mrfpe
    from mrfpe.brdf import get as brdf
    from mrfpe.synthetic import make_scene

    u = np.random.default_rng(1000 + i).uniform(0.05, 0.95, 3)
    theta = np.asarray(brdf("ward").to_natural(u)).reshape(-1)
    scene = make_scene(brdf="ward", theta=theta, shape=shape, n_labels=n_labels, seed=i)
    return u, mrfpe.targets.get("pls", scene)


def maximiser(i: int, target, cache: Path, tag: str) -> np.ndarray:
    """The target's global maximiser (dense grid + local search), cached on disk."""
    import mrfpe

    path = cache / f"max_{tag}_{i}.json"
    if path.exists():
        return np.array(json.loads(path.read_text())["x"])
    x, f = mrfpe.targets.maximise(target)
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"x": np.asarray(x).tolist(), "f": float(f)}))
    return np.asarray(x)


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
                   help="override a sampler setting, e.g. dw_r.n_steps=5000")
    p.add_argument("--cache", type=Path, default=Path("benchmarks/.cache"))
    p.add_argument("--out", type=Path, default=None, help="JSON-lines results file")
    args = p.parse_args(argv)

    configs: dict[str, dict] = {s: {} for s in args.samplers}
    for item in args.set:
        key, raw = item.split("=", 1)
        sampler, setting = key.split(".", 1)
        try:
            configs[sampler][setting] = json.loads(raw)
        except json.JSONDecodeError:
            configs[sampler][setting] = raw

    tag = f"{args.shape[0]}x{args.shape[1]}_{args.n_labels}"
    rows = []
    for i in range(args.first, args.first + args.scenes):
        u, target = scene_and_target(i, tuple(args.shape), args.n_labels)
        target.log_prob(np.full((1, 3), 0.5))  # compile the kernels outside the timings
        xm = maximiser(i, target, args.cache, tag)
        print(f"scene {i}: truth {u.round(3)}  PL maximiser {xm.round(3)} "
              f"(|max - truth| {np.linalg.norm(xm - u):.3f})", flush=True)
        for name in args.samplers:
            trace, post = run_one(name, target, args.seed, configs[name])
            m = post["map_theta"].values[-1]
            e_true, s_true = first_within(trace, u, args.tol)
            e_max, s_max = first_within(trace, xm, args.tol)
            row = {"scene": i, "sampler": name, "evals@tol": e_true, "s@tol": s_true,
                   "evals@tol_max": e_max, "s@tol_max": s_max,
                   "d_true": float(np.linalg.norm(m - u)), "d_max": float(np.linalg.norm(m - xm)),
                   "evals": float(post.attrs["n_target_evals"]),
                   "time_s": float(post.attrs["wall_time_s"])}
            rows.append(row)
            print("  " + "  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                   for k, v in row.items() if k != "scene"), flush=True)
            if args.out:
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")

    print(f"\nsummary over {args.scenes} scene(s), tol {args.tol} (means over the scenes that "
          "reached it; 'hit' = how many did):")
    print(f"{'sampler':<13} {'hit':>4} {'evals@tol':>10} {'s@tol':>7} {'hit_max':>7} "
          f"{'evals@max':>10} {'d_true':>7} {'d_max':>7} {'evals':>8} {'time s':>7}")
    for name in args.samplers:
        sel = [r for r in rows if r["sampler"] == name]

        def mean(key: str, sel=sel) -> float:
            v = np.array([r[key] for r in sel], dtype=float)
            return float(np.nanmean(v)) if np.isfinite(v).any() else np.nan

        hit = sum(np.isfinite(r["evals@tol"]) for r in sel)
        hit_max = sum(np.isfinite(r["evals@tol_max"]) for r in sel)
        print(f"{name:<13} {hit:>4} {mean('evals@tol'):>10.0f} {mean('s@tol'):>7.1f} "
              f"{hit_max:>7} {mean('evals@tol_max'):>10.0f} {mean('d_true'):>7.4f} "
              f"{mean('d_max'):>7.4f} {mean('evals'):>8.0f} {mean('time_s'):>7.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
