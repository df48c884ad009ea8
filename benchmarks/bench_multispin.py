"""Multi-spin coded heat-bath sweeps (:mod:`mrfpe.models.multispin`) against the scalar kernel.

Spin updates per nanosecond on one thread: 64 replicas of an Ising/autologistic
lattice packed in one word per site (:func:`~mrfpe.models.multispin.multispin_gibbs`)
against the scalar colour-class Gibbs kernel (:func:`mrfpe.models.simulate.simulate`,
``method="gibbs"``) on the same lattice. Every comparison is a **ratio in one run**:
the two sides alternate and the medians of several repeats are compared, so a shared,
noisy machine slows both alike. Sweep cost is ``(t(K sweeps) - t(0 sweeps)) / K``
(setup excluded: tables, start, unpacking).

Rows: the 4-neighbour lattice at 256² and 1024² with all replicas at one parameter
vector, 64 different parameter vectors (per-replica tables), and the 8-neighbour
lattice.

Usage (from the repository root)::

    python -m benchmarks.bench_multispin             # appended to RESULTS.md
    python -m benchmarks.bench_multispin --no-write
    python -m benchmarks.bench_multispin --quick --no-write
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import append_results, command_line, machine

R = 64  # replicas: one word per site


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _design(side: int, neighbourhood: int):
    from mrfpe.models.discrete import MRF
    from mrfpe.models.graph import lattice
    from mrfpe.models.terms import Coupling, Field

    design, _, _ = MRF(lattice(neighbourhood), 2, [Coupling(), Field()]).compile((side, side))
    return design


def _sides(design, psi: np.ndarray, k: int, neighbourhood: int):
    """``(multispin(k sweeps), scalar(k sweeps))`` callables at the rows of ``psi``."""
    from mrfpe.models.multispin import lattice_parameters, multispin_gibbs
    from mrfpe.models.simulate import simulate

    args = lattice_parameters(design, psi).arguments()

    def ms(k=k):
        return multispin_gibbs(**args, n_sweeps=k, seed=0)

    def sc(k=k):
        return simulate(design, psi[0], 1, seed=0, method="gibbs", n_sweeps=k)

    return ms, sc


def rate_rows(quick: bool = False) -> list[str]:
    """Updates/ns of both kernels, one thread, alternated; the ratio per case."""
    from mrfpe.threads import limit_threads

    rng = np.random.default_rng(0)
    cases = [(256, 4, "one θ"), (256, 4, "64 θ"), (256, 8, "one θ")] if not quick else \
        [(64, 4, "one θ"), (64, 4, "64 θ")]
    if not quick:
        cases.append((1024, 4, "one θ"))
    repeat = 3 if quick else 5
    rows = [f"Heat-bath sweeps, binary lattice (coupling 0.4, field 0.1 in the 0/1 "
            f"coding), one thread: {R} replicas multi-spin coded against the scalar "
            f"kernel's one chain; medians of {repeat} alternated repeats, setup excluded.\n",
            "| lattice | neighbours | parameters | multispin updates/ns | scalar updates/ns "
            "| multispin ns/site-word | ratio (per-site rate) |", "|---|---|---|---|---|---|---|"]
    for side, nb, what in cases:
        design = _design(side, nb)
        theta = np.tile([0.4, 0.1], (R, 1)) if what == "one θ" else \
            np.column_stack([rng.uniform(0.0, 0.8, R), rng.uniform(-0.3, 0.3, R)])
        psi = design.psi(theta)
        k_ms = max(2, int(4e6 // side**2)) if not quick else 10
        k_sc = max(2, int(4e6 // side**2)) if not quick else 10
        ms, sc = _sides(design, psi, k_ms, nb)
        times = {"ms0": [], "ms": [], "sc0": [], "sc": []}
        with limit_threads(1):
            ms(1), sc(1)  # load or compile the kernels
            for _ in range(repeat):
                times["ms0"].append(_timed(lambda ms=ms: ms(0)))
                times["ms"].append(_timed(lambda ms=ms, k=k_ms: ms(k)))
                times["sc0"].append(_timed(lambda sc=sc: sc(0)))
                times["sc"].append(_timed(lambda sc=sc, k=k_sc: sc(k)))
        med = {k: float(np.median(v)) for k, v in times.items()}
        ms_sweep = max(med["ms"] - med["ms0"], 1e-12) / k_ms
        sc_sweep = max(med["sc"] - med["sc0"], 1e-12) / k_sc
        n = side * side
        ms_rate, sc_rate = R * n / ms_sweep / 1e9, n / sc_sweep / 1e9
        rows.append(f"| {side}² | {nb} | {what} | {ms_rate:.2f} | {sc_rate:.3f} | "
                    f"{ms_sweep / n * 1e9:.1f} | {ms_rate / sc_rate:.0f}× |")
        print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--no-write", action="store_true", help="do not append to RESULTS.md")
    args = p.parse_args(argv)
    info = machine()
    body = rate_rows(args.quick)
    if not args.no_write:
        append_results("Multi-spin coded heat-bath sweeps (bench_multispin)",
                       command_line(argv, "benchmarks.bench_multispin"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
