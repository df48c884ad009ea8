"""Run the performance suites; append each suite's dated section to ``benchmarks/RESULTS.md``.

Usage (from the repository root)::

    python -m benchmarks                       # every suite at full size (~40 min)
    python -m benchmarks --only targets        # one suite
    python -m benchmarks --only kernel         # lean vs classic kernel, ratios in one run
    python -m benchmarks --quick --no-write    # small scenes: a smoke run in about a minute

Each suite's section is written the moment the suite finishes, so an
interrupted run keeps what it measured. Timings mean most on an otherwise idle
machine: every section records the load average at its start and end, and
``ns/eval cpu/thr`` (CPU time per thread) stays meaningful under load.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from benchmarks import bench_kernel, bench_models, bench_samplers, bench_stereo, bench_targets
from benchmarks._common import append_results, command_line, machine


def _targets(quick: bool) -> tuple[str, list[str]]:
    if quick:
        return "targets and PMC", bench_targets.run(["ward"], ["float64"], [5, 10], (30, 30), 1,
                                                    pmc=True)[1]
    _, body = bench_targets.run(["ward", "phong"], ["float64"], [10, 20, 30, 40], (100, 100), 3,
                                pmc=True)
    _, extra = bench_targets.run(["ward"], ["float32"], [10, 20, 30, 40], (100, 100), 3,
                                 pmc=True)
    return "targets and PMC", [*body, "", "float32 (`dtype=\"float32\"`, accuracy: "
                               "`tests/brdf/targets/test_pseudolikelihood.py::test_float32_accuracy`):"
                               "\n", *extra]


def _samplers(quick: bool) -> tuple[str, list[str]]:
    names = list(bench_samplers.SAMPLERS)
    if quick:
        cfg = {"pmc": {"n_samples": 200, "n_iterations": 5},
               "emcee": {"n_walkers": 8, "n_steps": 25, "burn_in": 5},
               "dw_r": {"n_steps": 200}, "lm_multiseed": {"n_seeds": 8}}
        return "sampler efficiency", bench_samplers.run(names, range(1), (20, 20), 10,
                                                        configs=cfg)[1]
    return "sampler efficiency", bench_samplers.run(names, range(2), (100, 100), 20)[1]


def _stereo(quick: bool) -> tuple[str, list[str]]:
    # the committed figure is the full run's; a quick run plots to a scratch file
    plot = (Path(tempfile.gettempdir()) / "mrfpe_stereo_energy_quick.png" if quick
            else bench_stereo.HERE / "stereo_energy.png")
    return ("stereo, Middlebury motorcycle, bad-1px",
            bench_stereo.run(["quarter"] if quick else ["quarter", "half"], plot))


def _kernel(quick: bool) -> tuple[str, list[str]]:
    return "lean vs classic kernel", bench_kernel.run(quick)


def _models(quick: bool) -> tuple[str, list[str]]:
    return "declared models: simulation and pseudolikelihood", bench_models.run(quick)


SUITE_RUNNERS = {"models": _models, "kernel": _kernel, "targets": _targets,
                 "samplers": _samplers, "stereo": _stereo}
SUITES = tuple(SUITE_RUNNERS)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__,
                                formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--only", nargs="+", choices=SUITES, default=list(SUITES))
    p.add_argument("--quick", action="store_true",
                   help="small scenes and budgets: checks that every suite runs")
    p.add_argument("--no-write", action="store_true", help="print only; do not append")
    args = p.parse_args(argv)

    print(" ".join(f"{k}={v}" for k, v in machine().items()), flush=True)
    for suite in args.only:
        info = machine()
        t0 = time.perf_counter()
        print(f"\n== {suite} ==", flush=True)
        title, body = SUITE_RUNNERS[suite](args.quick)
        body.append(f"\nSuite time: {time.perf_counter() - t0:.0f} s.")
        print("\n".join(body), flush=True)
        if not args.no_write:
            append_results(f"python -m benchmarks: {title}" + (" (quick)" if args.quick else ""),
                           command_line(argv, "benchmarks"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
