"""Run the performance suites and append one dated section to ``benchmarks/RESULTS.md``.

Usage (from the repository root)::

    python -m benchmarks                       # every suite at the issue's sizes (~20 min)
    python -m benchmarks --only targets        # one suite
    python -m benchmarks --quick --no-write    # small scenes: a smoke run in about a minute

Timings mean most on an otherwise idle machine: the section records the load
average at its start and end, and ``ns/eval cpu/thr`` (CPU time per thread)
stays meaningful under load.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from benchmarks import bench_samplers, bench_stereo, bench_targets
from benchmarks._common import append_results, command_line, machine

SUITES = ("targets", "samplers", "stereo")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__,
                                formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--only", nargs="+", choices=SUITES, default=list(SUITES))
    p.add_argument("--quick", action="store_true",
                   help="small scenes and budgets: checks that every suite runs")
    p.add_argument("--no-write", action="store_true", help="print only; do not append")
    args = p.parse_args(argv)

    info = machine()
    print(" ".join(f"{k}={v}" for k, v in info.items()), flush=True)
    body: list[str] = []
    timings = []
    for suite in args.only:
        t0 = time.perf_counter()
        print(f"\n== {suite} ==", flush=True)
        if suite == "targets":
            if args.quick:
                _, part = bench_targets.run(["ward"], ["float64"], [5, 10], (30, 30), 1, True)
            else:
                _, part = bench_targets.run(["ward", "phong"], ["float64"], [10, 20, 30, 40],
                                            (100, 100), 3, pmc=True)
                _, extra = bench_targets.run(["ward"], ["float32"], [10, 20, 30, 40],
                                             (100, 100), 3, pmc=True)
                part += ["", "float32 (`dtype=\"float32\"`, accuracy: "
                         "`tests/targets/test_pseudolikelihood.py::test_float32_accuracy`):\n",
                         *extra]
            body += ["### Targets and PMC\n", *part, ""]
        elif suite == "samplers":
            if args.quick:
                cfg = {"pmc": {"n_samples": 200, "n_iterations": 5},
                       "emcee": {"n_walkers": 8, "n_steps": 25, "burn_in": 5},
                       "dw_r": {"n_steps": 200}, "lm_multiseed": {"n_seeds": 8}}
                _, part = bench_samplers.run(list(bench_samplers.SAMPLERS), range(1), (20, 20),
                                             10, configs=cfg)
            else:
                _, part = bench_samplers.run(list(bench_samplers.SAMPLERS), range(2),
                                             (100, 100), 20)
            body += ["### Sampler efficiency\n", *part, ""]
        else:
            # the committed figure is the full run's; a quick run plots to a scratch file
            plot = (Path(tempfile.gettempdir()) / "mrfpe_stereo_energy_quick.png" if args.quick
                    else bench_stereo.HERE / "stereo_energy.png")
            part = bench_stereo.run(["quarter"] if args.quick else ["quarter", "half"], plot)
            body += ["### Stereo: Middlebury motorcycle, bad-1px\n", *part, ""]
        timings.append(f"{suite} {time.perf_counter() - t0:.0f} s")
    body.append("Suite times: " + ", ".join(timings) + ".")
    print("\n".join(body))
    if not args.no_write:
        append_results("python -m benchmarks" + (" (quick)" if args.quick else ""),
                       command_line(argv, "benchmarks"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
