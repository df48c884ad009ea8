"""Lean against classic kernel in one process: ns/eval, speed of light, PMC, LM, growth.

Everything is a **ratio in one run**: each comparison alternates the two
kernels (a target built with each ``kernel`` option on one scene, sharing its tables)
and takes medians of several
repeats, so a shared, noisy machine slows both alike.

* ``ns/eval`` at N = 1000 (Ward and Phong, float32 and float64, 100 x 100, 20 labels)
  for the classic and the lean kernel, wall and CPU per thread, and the lean
  kernel's distance to the **speed of light**. The lean Ward code per 16 particles and
  one label, counted in its float32 AVX-512 code (``inspect_asm``, Dec 2026), runs 101
  vector arithmetic ops per 6.2 evaluations: the label loop's 86 (6 exp2 of 10 ops --
  the argument's FMA with log2 wF1, max, cvtps2dq, cvtdq2ps, subtraction, 5 FMAs,
  vscalefps -- and 26 for the four slot terms and the FMA with ``1/sigma_b``), ~14 for
  the label log-sum-exp and ~1 for the node's two fixed triangles. That is 16.3 ops per
  evaluation (:data:`OPS_PER_EVAL`), 8.2 of them multiplies or FMAs
  (:data:`FMA_OPS_PER_EVAL`); without AVX-512 each exp2 takes one op more.
  Intel's AVX-512 cores issue every 512-bit op on the same two ports, so the floor is
  all ops at the FMA rate; AMD Zen 4 has two FADD pipes beside its two FMA pipes, so
  the floor is the larger of the FMA-class ops at the FMA rate and all ops at twice it.
  The other columns time the same kernels for one particle (``N=1``: an MCMC step),
  where the lean family runs its nodes-as-SIMD kernel.
  The rate is measured (a numba loop of independent FMAs, per core, in the kernel's
  own precision and vector width) and also given from nominal figures: vector width
  from the ``avx512f`` flag in ``/proc/cpuinfo`` and LLVM's 256-bit preference
  (:func:`mrfpe.threads.vector_width`), 2 FMA ports (Intel with AVX-512: 2 x 512
  bit; AMD Zen 4: 2 x 256 bit, i.e. 512-bit ops at half rate), the clock from
  ``cpu MHz``;
* PMC 1000 x 20 on 100 x 100, 10 labels: today's code (classic kernel, NumPy
  mixture density, BLAS threads left to OpenBLAS) against lean kernel + numba mixture
  density + single-threaded BLAS (:func:`mrfpe.threads.blas_threads`), in float32 and
  float64, the MAP of both (same float type) and the run's peak memory;
* ``lm_multiseed`` (50 x 50, 20 labels, 27 seeds): today's (classic kernel,
  forward-difference Jacobian) against the lean kernel with the analytic Jacobian;
* growth of the lean kernel's ns/eval over labels (10-40) and lattice size (50²-400²).

Usage::

    python -m benchmarks --only kernel
    python -m benchmarks.bench_kernel --quick --no-write
"""

from __future__ import annotations

import argparse
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from benchmarks._common import append_results, command_line, machine, peak_memory

#: Vector arithmetic ops per evaluation of the lean Ward loop, and how many are multiplies/FMAs.
OPS_PER_EVAL, FMA_OPS_PER_EVAL = 16.3, 8.2


def _fma_kernel():
    from numba import njit

    from mrfpe.fastmath import FASTMATH

    @njit(fastmath=FASTMATH, error_model="numpy")
    def fma_rate(x, n, m, c):
        # 16 dependent FMAs per element between one load and one store: the loop over
        # elements vectorises (one array, no alias checks) and out-of-order execution
        # overlaps the independent chains of successive vectors, so FMA throughput binds
        for _ in range(n):
            for p in range(x.shape[0]):
                v = x[p]
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                v = v * m + c
                x[p] = v
        return x[0]

    return fma_rate


def speed_of_light(dtype: str) -> dict:
    """Measured and nominal vector-op rates per core, and the resulting ns/eval floor."""
    import os

    from mrfpe.threads import vector_width

    width = vector_width()
    lanes = width // (8 * np.dtype(dtype).itemsize)
    cpu = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    mhz = [float(line.split(":")[1]) for line in cpu.splitlines() if line.startswith("cpu MHz")]
    ghz = (np.median(mhz) / 1000) if mhz else float("nan")
    amd = "AuthenticAMD" in cpu or "AMD" in cpu.split("model name", 1)[-1][:80]
    # FMA ports: 2; Zen 4 executes a 512-bit op as two 256-bit halves. The nominal
    # clock is /proc/cpuinfo's (base under a hypervisor; boost clocks run faster, which
    # the measured rate sees)
    lane_ops_cycle = 2 * (lanes // 2 if (amd and width == 512) else lanes)
    nominal = lane_ops_cycle * ghz  # lane-ops per ns per core
    f = _fma_kernel()
    x = np.ones(64 * lanes, dtype=dtype)
    m, c = np.dtype(dtype).type(0.999), np.dtype(dtype).type(0.001)  # typed: no promotion
    f(x, 10, m, c)
    reps = 5000
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        f(x, reps, m, c)
        ts.append(time.perf_counter() - t0)
    measured = 16 * x.size * reps / min(ts) / 1e9  # FMAs (lane-ops) per ns, one core
    cores = os.cpu_count() or 1
    # ops per evaluation in units of FMA slots: Zen 4's FADD pipes take the other ops
    slots = max(FMA_OPS_PER_EVAL, OPS_PER_EVAL / 2) if amd else OPS_PER_EVAL
    return {"dtype": dtype, "vector_bits": width, "lanes": lanes, "ghz_nominal": ghz,
            "lane_ops_ns_nominal": nominal, "lane_ops_ns_measured": measured, "cores": cores,
            "fma_slots_per_eval": slots, "sol_ns_eval_nominal": slots / (nominal * cores),
            "sol_ns_eval_measured": slots / (measured * cores)}


def _scene(brdf: str, shape, n_labels: int):
    from mrfpe.brdf.synthetic import make_scene

    theta = {"ward": [0.7, 0.4, 0.225], "phong": [0.5, 0.4, 7.5]}[brdf]
    return make_scene(brdf=brdf, theta=theta, shape=shape, n_labels=n_labels,
                      surface="smooth" if brdf == "ward" else "jagged", seed=0)


def _targets(scene, kernels=("classic", "lean"), **options) -> dict:
    """``pls`` on ``scene`` once per kernel family (the ``kernel`` option); one set of tables."""
    import mrfpe

    return {k: mrfpe.targets.get("pls", scene, kernel=k, **options) for k in kernels}


def ns_per_eval(targets: dict, n: int, repeat: int) -> dict:
    """Median wall and CPU ns per BRDF evaluation of each kernel's target, alternated."""
    import numba

    kernels = tuple(targets)
    first = targets[kernels[0]]
    x = np.random.default_rng(0).random((n, first.ndim))
    ev = first._tables.brdf_evals_per_particle * n
    for k in kernels:
        targets[k].log_prob(x)
    wall = {k: [] for k in kernels}
    cpu = {k: [] for k in kernels}
    for _ in range(repeat):
        for k in kernels:
            w0, c0 = time.perf_counter(), time.process_time()
            targets[k].log_prob(x)
            wall[k].append(time.perf_counter() - w0)
            cpu[k].append(time.process_time() - c0)
    thr = numba.get_num_threads()
    return {k: (np.median(wall[k]) / ev * 1e9, np.median(cpu[k]) / ev * 1e9 / thr)
            for k in kernels}


@contextmanager
def _today(kernel: str):
    """``"classic"``: the earlier code path (classic kernel, NumPy mixture density in PMC,
    BLAS on its own thread count); ``"lean"``: today's defaults.

    PMC's jitter kernels look the mixture density up in :mod:`mrfpe.mixture` at each call,
    so replacing it there switches every sampler that uses the kit.
    """
    from mrfpe import mixture, threads

    classic = kernel == "classic"
    numba_density = mixture.log_mixture_density
    mixture.log_mixture_density = (mixture.log_mixture_density_numpy if classic
                                   else numba_density)
    blas = threads.BLAS_THREADS
    threads.BLAS_THREADS = None if classic else blas
    try:
        yield
    finally:
        mixture.log_mixture_density = numba_density
        threads.BLAS_THREADS = blas


def pmc_compare(shape, n_labels, dtype, n_samples, n_iter, repeat) -> dict:
    """PMC today (classic kernel + NumPy mixture density) against lean + numba mixture."""
    import mrfpe

    ts = _targets(_scene("ward", shape, n_labels), dtype=dtype)
    out = {}
    for k in ("classic", "lean"):
        with _today(k):
            mrfpe.sample("pmc", ts[k], seed=0, n_samples=50, n_iterations=2)  # warm
    times = {"classic": [], "lean": []}
    for _ in range(repeat):
        for k in ("classic", "lean"):
            with _today(k), peak_memory() as mem:
                t0 = time.perf_counter()
                post = mrfpe.sample("pmc", ts[k], seed=0, n_samples=n_samples,
                                    n_iterations=n_iter)
                times[k].append(time.perf_counter() - t0)
            out[k + "_map"] = post["map_theta"].values[-1]
            out[k + "_rss"] = mem["rss_MiB"]
            out[k + "_traced"] = mem["traced_MiB"]
    out.update({k + "_s": float(np.median(v)) for k, v in times.items()})
    return out


def lm_compare(shape, n_labels, n_seeds, repeat) -> dict:
    import mrfpe
    from mrfpe.brdf.targets import jacobian

    ts = _targets(_scene("ward", shape, n_labels))
    orig = jacobian.supports
    times = {"today": [], "new": []}
    maps = {}
    try:
        for r in range(-1, repeat):  # r = -1: a warm-up of both (numba loads, tables)
            for k in ("today", "new"):
                jacobian.supports = orig if k == "new" else (lambda target: False)
                with _today("lean" if k == "new" else "classic"):
                    t0 = time.perf_counter()
                    post = mrfpe.sample("lm_multiseed", ts["lean" if k == "new" else "classic"],
                                        seed=0,
                                        n_seeds=n_seeds if r >= 0 else 1)
                    if r >= 0:
                        times[k].append(time.perf_counter() - t0)
                maps[k] = post["map_theta"].values[-1]
    finally:
        jacobian.supports = orig
    return {"today_s": float(np.median(times["today"])), "new_s": float(np.median(times["new"])),
            "map_diff": float(np.max(np.abs(maps["today"] - maps["new"])))}


def _mib(t) -> float:
    """Classic and lean tables (with the lean ones' node-major copy, built with them)."""
    return (t.nbytes + t._engine_tables.lean.nbytes) / 2**20


PARTS = ("nseval", "pmc", "lm", "growth")


def run(quick: bool = False, parts: tuple[str, ...] = PARTS) -> list[str]:
    """The markdown body of the suite (``parts``: which of :data:`PARTS` to run)."""
    import mrfpe
    from mrfpe.threads import configure_vector_width

    shape = (30, 30) if quick else (100, 100)
    rep = 2 if quick else 5
    body = [f"Kernel vector width: {configure_vector_width()} (mrfpe.threads; `MRFPE_AVX512=0` "
            "opts out). Ratios are lean ÷ classic in this process, medians of "
            f"{rep} alternated repeats; `SoL`: the lean Ward loop's {OPS_PER_EVAL} vector ops "
            f"per evaluation ({FMA_OPS_PER_EVAL} of them multiplies or FMAs) at the measured "
            "(nominal) FMA rate of all cores, the other ops on their own pipes where the CPU "
            "has them (AMD Zen 4).\n"]
    rows = ["| brdf | dtype | classic ns/eval | lean ns/eval | lean ÷ classic | classic cpu/thr "
            "| lean cpu/thr | cpu ratio | SoL measured | SoL nominal | lean ÷ SoL "
            "| N=1 classic ms | N=1 lean ms | N=1 lean ÷ classic |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    sol = {dt: speed_of_light(dt) for dt in ("float32", "float64")}
    for brdf in ("ward", "phong") if "nseval" in parts else ():
        scene = _scene(brdf, shape, 10 if quick else 20)
        for dt in ("float32", "float64"):
            ts = _targets(scene, dtype=dt)
            r = ns_per_eval(ts, 1000 if not quick else 200, rep)
            one = ns_per_eval(ts, 1, 4 * rep)
            ms1 = {k: one[k][0] * ts[k]._tables.brdf_evals_per_particle / 1e6 for k in one}
            s = sol[dt]
            rows.append(f"| {brdf} | {dt} | {r['classic'][0]:.3f} | {r['lean'][0]:.3f} | "
                        f"{r['lean'][0] / r['classic'][0]:.2f} | {r['classic'][1]:.3f} | "
                        f"{r['lean'][1]:.3f} | {r['lean'][1] / r['classic'][1]:.2f} | "
                        f"{s['sol_ns_eval_measured']:.3f} | {s['sol_ns_eval_nominal']:.3f} | "
                        f"{r['lean'][1] / s['sol_ns_eval_measured']:.1f} | "
                        f"{ms1['classic']:.2f} | {ms1['lean']:.2f} | "
                        f"{ms1['lean'] / ms1['classic']:.2f} |")
            print(rows[-1], flush=True)
    if "nseval" in parts:
        body += [*rows, ""]
    for dt, s in sol.items():
        body.append(f"- speed of light, {dt}: {s['vector_bits']}-bit vectors ({s['lanes']} lanes), "
                    f"measured {s['lane_ops_ns_measured']:.1f} FMA lane-ops/ns/core (nominal "
                    f"{s['lane_ops_ns_nominal']:.1f} at {s['ghz_nominal']:.2f} GHz), "
                    f"{s['cores']} cores, {s['fma_slots_per_eval']:g} FMA slots per evaluation")
    # PMC 1000 x 20, 10 labels
    if "pmc" in parts:
        body += ["", "| PMC | dtype | today s | lean s | lean ÷ today | MAP |lean − today| "
                 "| peak RSS MiB today / lean | traced MiB today / lean |",
                 "|---|---|---|---|---|---|---|---|"]
    for dt in ("float32", "float64") if "pmc" in parts else ():
        p = pmc_compare(shape, 10, dt, 200 if quick else 1000, 5 if quick else 20,
                        1 if quick else 2)
        d = float(np.max(np.abs(p["lean_map"] - p["classic_map"])))
        body.append(f"| {200 if quick else 1000}x{5 if quick else 20} | {dt} | "
                    f"{p['classic_s']:.2f} | {p['lean_s']:.2f} | {p['lean_s'] / p['classic_s']:.2f}"
                    f" | {d:.4f} | {p['classic_rss']:.0f} / {p['lean_rss']:.0f} | "
                    f"{p['classic_traced']:.0f} / {p['lean_traced']:.0f} |")
        print(body[-1], flush=True)
    if "lm" not in parts:
        return body
    # lm_multiseed
    lm = lm_compare((20, 20) if quick else (50, 50), 10 if quick else 20, 4 if quick else 27,
                    1 if quick else 2)
    body += ["", f"- lm_multiseed ({'20x20, 10' if quick else '50x50, 20'} labels, "
             f"{4 if quick else 27} seeds): today (classic kernel, forward differences) "
             f"{lm['today_s']:.1f} s, lean + analytic Jacobian {lm['new_s']:.1f} s, ratio "
             f"{lm['new_s'] / lm['today_s']:.2f}; MAP difference {lm['map_diff']:.2e}"]
    print(body[-1], flush=True)
    if "growth" not in parts:
        return body
    # growth (lean, float32)
    labels = (10, 20) if quick else (10, 20, 30, 40)
    sizes = ((20, 20), (40, 40)) if quick else ((50, 50), (100, 100), (200, 200), (400, 400))
    g = ["", "| growth (lean, float32, N=200) | nodes | labels | ns/eval | log_prob ms | "
         "tables MiB (classic + lean) |", "|---|---|---|---|---|---|"]
    for B in labels:
        t = mrfpe.targets.get("pls", _scene("ward", shape, B), dtype="float32")
        r = ns_per_eval({"lean": t}, 200, rep)["lean"]
        g.append(f"| labels | {t._tables.n_nodes} | {B} | {r[0]:.3f} | "
                 f"{r[0] * t._tables.brdf_evals_per_particle * 200 / 1e6:.1f} | "
                 f"{_mib(t):.0f} |")
        print(g[-1], flush=True)
    for sh in sizes:
        t = mrfpe.targets.get("pls", _scene("ward", sh, 20 if not quick else 10), dtype="float32")
        r = ns_per_eval({"lean": t}, 200, max(2, rep // 2))["lean"]
        g.append(f"| lattice {sh[0]}² | {t._tables.n_nodes} | {20 if not quick else 10} | "
                 f"{r[0]:.3f} | {r[0] * t._tables.brdf_evals_per_particle * 200 / 1e6:.1f} | "
                 f"{_mib(t):.0f} |")
        print(g[-1], flush=True)
    body += g
    return body


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--no-write", action="store_true")
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    args = p.parse_args(argv)
    info = machine()
    body = run(args.quick, tuple(args.parts))
    if not args.no_write:
        append_results("bench_kernel: lean vs classic" + (" (quick)" if args.quick
                                                                    else ""),
                       command_line(argv, "benchmarks.bench_kernel"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
