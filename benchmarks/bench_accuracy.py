"""Accuracy of every sampler's *default* configuration on Gaussians in the unit cube.

A measurement script (run from the repository root; the table goes to
stdout). Targets: :func:`mrfpe.testing.box_gaussian`.

    python benchmarks/bench_accuracy.py                 # every sampler, 3-D, 3 seeds
    python benchmarks/bench_accuracy.py --dim 10 pmc smc mh
    python benchmarks/bench_accuracy.py --seeds 5 --set pmc.variant=thesis2 pmc

Targets (truth known exactly, no partition offered):

* ``--dim 3``: an independent correlated Gaussian, sd (0.05, 0.065, 0.08),
  correlations (−0.5, 0.3, 0.4), mean near the centre;
* ``--dim 10``: AR(1) correlation ρ = 0.7, sd 0.04, mean 0.5.

Columns: worst |weighted mean − truth| / sd over parameters, worst and best
weighted-sd / true-sd, ESS (``mrfpe.posterior.diagnose``: Kish for weighted sets,
ArviZ's bulk/tail ESS pooled over chains for MCMC), each as the median over seeds
(min–max in brackets); reliable = how many seeds ``diagnose`` calls reliable;
|log Z| = |log_evidence − 0| (the Gaussian's mass in the cube is 1 to 1e-6) with
the median reported SE, for samplers that report an evidence; and pass = median
mean error ≤ 0.25 and median sd ratio in [0.85, 1.15] (``--dim 10``: [0.8, 1.2]).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np

import mrfpe
from mrfpe import posterior as P
from mrfpe.testing.targets import BoxGaussian, box_gaussian

SAMPLERS = ["pmc", "sir", "ppf", "mh", "emcee", "dw_q", "dw_r", "smc"]


def measure(name: str, target: BoxGaussian, seed: int, config: dict) -> tuple[float, ...]:
    post = mrfpe.sample(name, target, seed=seed, **config)
    m, sd = P.weighted_mean(post), np.sqrt(np.diag(P.weighted_cov(post)))
    err = np.abs(m - target.mean) / target.sd
    ratio = sd / target.sd
    diag = P.diagnose(post)
    lz = post.attrs.get("log_evidence", np.nan)  # the truth is log 1 = 0 (mass in the cube)
    return (float(err.max()), float(ratio.min()), float(ratio.max()), diag["ess"],
            float(diag["reliable"]), abs(lz), post.attrs.get("log_evidence_se", np.nan))


def parse_sets(items: list[str]) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for item in items:
        key, value = item.split("=", 1)
        sampler, opt = key.split(".", 1)
        try:
            value = json.loads(value)
        except json.JSONDecodeError:
            pass
        out.setdefault(sampler, {})[opt] = value
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("samplers", nargs="*", default=SAMPLERS)
    ap.add_argument("--dim", type=int, default=3, choices=(3, 10))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="SAMPLER.KEY=VALUE")
    args = ap.parse_args(argv)
    target, sets = box_gaussian(args.dim), parse_sets(args.set)
    lo, hi = (0.85, 1.15) if args.dim == 3 else (0.8, 1.2)
    print(f"{args.dim}-D Gaussian, default configurations, seeds 0..{args.seeds - 1}")
    print("| sampler | config | mean error (sd) | sd ratio | ESS | reliable | |log Z| (se) "
          "| pass |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.samplers:
        cfg = sets.get(name, {})
        with warnings.catch_warnings():  # the reliable column says it
            warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
            rows = np.array([measure(name, target, s, cfg) for s in range(args.seeds)])
        med = np.median(rows, axis=0)
        ok = med[0] <= 0.25 and med[1] >= lo and med[2] <= hi

        def rng(j: int, fmt: str = ".2f", med=med, rows=rows) -> str:
            return f"{med[j]:{fmt}} [{rows[:, j].min():{fmt}}–{rows[:, j].max():{fmt}}]"

        ev = ("—" if np.isnan(med[5]) else
              f"{med[5]:.3f} [{rows[:, 5].min():.3f}–{rows[:, 5].max():.3f}] ({med[6]:.3f})")
        sd_txt = (f"{med[1]:.2f}–{med[2]:.2f} "
                  f"[{rows[:, 1].min():.2f}–{rows[:, 2].max():.2f}]")
        print(f"| {name} | {json.dumps(cfg) if cfg else 'default'} | {rng(0)} | {sd_txt} | "
              f"{rng(3, '.0f')} | {int(rows[:, 4].sum())}/{len(rows)} | {ev} | "
              f"{'yes' if ok else 'NO'} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
