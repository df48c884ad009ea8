"""PMC on synthetic Ward scenes: MAP distance to the PL maximiser and to the truth.

The acceptance measurement of PMC. For each of ``--scenes`` scenes
``make_scene(brdf="ward", shape=(100, 100), n_labels=20)`` with random true
parameters (unit cube, uniform in [0.05, 0.95]^3), build the ``pls`` target,
find its global maximiser with :func:`mrfpe.targets.maximise`, run PMC
(1000 samples x 20 iterations) for each ``--variants`` and report

* ``d_max``: distance (unit cube) from the PMC MAP to the PL maximiser (goal: mean <= 0.02),
* ``d_true``: distance from the PMC MAP to the true parameters, beside the
  thesis's Table 7.1 (Ward, 20 labels, 1000 samples, iteration 20: 0.104),
* ``gap``: log PL at the maximiser minus log PL at the PMC MAP,
* evaluations per particle (full-lattice equivalents), final ESS and wall time.

Usage::

    python -m benchmarks.bench_pmc --scenes 5 --variants mixture thesis2 thesis1
    python -m benchmarks.bench_pmc --scenes 1 --variants mixture --power 0.01 0.02 0.05

Maximisers are cached in ``--cache`` (default: a directory under the system's temp
dir; they cost ~1 min per scene).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import cached_maximiser, ward_scene_target

THESIS_TABLE_7_1 = 0.1043  # Ward, 20 labels, 1000 samples, MAP dist after 20 iterations


def _power(text: str) -> float | str:
    return text if text == "auto" else float(text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--scenes", type=int, default=5)
    p.add_argument("--first", type=int, default=0, help="index of the first scene")
    p.add_argument("--variants", nargs="+", default=["mixture", "thesis2", "thesis1"])
    p.add_argument("--power", nargs="+", type=_power, default=[None],
                   help="softening powers (floats or 'auto'); default: PMC's default")
    p.add_argument("--auto-ess", type=float, default=None)
    p.add_argument("--n-samples", type=int, default=1000)
    p.add_argument("--n-iterations", type=int, default=20)
    p.add_argument("--shape", type=int, nargs=2, default=[100, 100])
    p.add_argument("--n-labels", type=int, default=20)
    p.add_argument("--seeds", type=int, default=1, help="PMC seeds 0..S-1 per scene")
    p.add_argument("--cache", type=Path,
                   default=Path(tempfile.gettempdir()) / "mrfpe-bench-pmc-cache")
    p.add_argument("--out", type=Path, default=None, help="JSON-lines results file")
    args = p.parse_args(argv)

    from mrfpe.samplers.pmc import PMC

    tag = f"{args.shape[0]}x{args.shape[1]}_{args.n_labels}"
    rows = []
    for i in range(args.first, args.first + args.scenes):
        u, target = ward_scene_target(i, tuple(args.shape), args.n_labels)
        xm, fm, tm = cached_maximiser(i, target, tag, args.cache)
        print(f"scene {i}: truth {u.round(3)}  PL maximiser {xm.round(3)} (log PL {fm:.6g}, "
              f"|max - truth| {np.linalg.norm(xm - u):.3f}, {tm:.0f} s)", flush=True)
        for variant in args.variants:
            for power, seed in ((p_, s_) for p_ in args.power for s_ in range(args.seeds)):
                cfg = {"n_samples": args.n_samples, "n_iterations": args.n_iterations,
                       "variant": variant}
                if power is not None:
                    cfg["power"] = power
                if args.auto_ess is not None:
                    cfg["auto_ess"] = args.auto_ess
                sampler = PMC(**cfg)
                post = sampler.run(target, seed=seed)
                m = post["map_theta"].values[-1]
                row = {"scene": i, "seed": seed, "variant": variant, "power": str(sampler.power),
                       "d_max": float(np.linalg.norm(m - xm)),
                       "d_true": float(np.linalg.norm(m - u)),
                       "d_max_true": float(np.linalg.norm(xm - u)),
                       "gap": float(fm - post["map_log_target"].values[-1]),
                       "evals_per_particle": post.attrs["n_target_evals"] / args.n_samples,
                       "ess": float(post["ess"].values[-1]),
                       "time_s": post.attrs["wall_time_s"]}
                rows.append(row)
                print("  " + "  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                       for k, v in row.items() if k != "scene"), flush=True)
                if args.out:
                    with args.out.open("a") as f:
                        f.write(json.dumps(row) + "\n")
    print(f"\nmeans over {args.scenes} scenes x {args.seeds} seeds "
          f"(thesis Table 7.1, MAP to truth after 20 iterations: {THESIS_TABLE_7_1}):")
    print(f"{'variant':<9} {'power':>7} {'d_max':>7} {'d_true':>7} {'gap':>9} "
          f"{'evals/p':>8} {'ESS':>7} {'time s':>7}")
    for variant in args.variants:
        for power in sorted({r["power"] for r in rows if r["variant"] == variant}):
            sel = [r for r in rows if r["variant"] == variant and r["power"] == power]
            mean = {k: float(np.mean([r[k] for r in sel])) for k in sel[0] if k not in
                    ("scene", "seed", "variant", "power")}
            print(f"{variant:<9} {power:>7} {mean['d_max']:>7.4f} {mean['d_true']:>7.4f} "
                  f"{mean['gap']:>9.4g} {mean['evals_per_particle']:>8.3g} {mean['ess']:>7.1f} "
                  f"{mean['time_s']:>7.1f}")
    print(f"(PL maximiser to truth, mean: "
          f"{np.mean([r['d_max_true'] for r in rows]):.4f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
