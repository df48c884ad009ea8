"""Construction and log_prob cost of the ``pls`` target.

For a ``--shape`` (default 100 x 100) synthetic scene with 10, 20, 30 and 40
labels it measures, per BRDF model:

* construction time of ``mrfpe.targets.get("pls", scene)`` (fresh tables) and
  the target's memory (its precomputed tables) and the construction's peak
  traced allocation (``tracemalloc``);
* ``log_prob`` wall time and throughput (BRDF evaluations per second) for
  batches of 1, 64 and 1000 parameter vectors (best of ``--repeat``) and the
  CPU time of the 1000 batch;
* ns per BRDF evaluation (the log-sum-exp over labels included in the time):
  wall-clock on this machine's threads, and CPU time divided by the thread
  count -- the wall time the same work takes on that many idle cores (the two
  differ when other processes share the machine);
* a comparison kernel: the bare minimum loop doing the same number of Ward
  evaluations (same features, same vectorised exp) and one log-sum-exp per
  (node, particle) over the labels, with no data-term structure -- how close
  ``log_prob`` is to what this machine can do;
* optionally (``--pmc``) the wall time of PMC 1000 x 20 beside the thesis's
  Table 8.12 (4 min at 10 labels ... 16 min at 40), its growth with the labels
  (least-squares line), and the run's peak memory (traced and process RSS).

Usage (from the repository root; ``python -m benchmarks`` runs every suite)::

    python -m benchmarks.bench_targets                     # ward, 10/20/30/40 labels
    python -m benchmarks.bench_targets --brdf ward phong --pmc
    python -m benchmarks.bench_targets --labels 10 --shape 50 50 --no-write
    python -m benchmarks.bench_targets --dtype float64 float32

Results are printed and, unless ``--no-write``, appended to
``benchmarks/RESULTS.md`` as a dated section with machine and versions.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import (
    append_results,
    best,
    command_line,
    machine,
    peak_memory,
)
from mrfpe.experiments._thesis import RUNTIME_MINUTES

THETA = {"ward": [0.7, 0.4, 0.45], "phong": [0.5, 0.4, 0.3], "lambertian": [0.7],
         "ward_aniso": [0.7, 0.4, 0.45, 0.3], "phong_aniso": [0.5, 0.4, 0.3, 0.5]}
SURFACE = {"ward": "smooth", "ward_aniso": "smooth", "lambertian": "smooth"}


def comparison_kernel():
    """The bare-minimum loop for the same Ward evaluations and label log-sum-exps."""
    from numba import njit, prange

    from mrfpe.fastmath import FASTMATH, vexp, vlog

    @njit(parallel=True, fastmath=FASTMATH, error_model="numpy")
    def floor(coef, feat, n_nodes, B, nv, bl, out):
        npad = coef.shape[1]
        nblk = npad // bl
        chunk = 64
        n_chunks = -(-n_nodes // chunk)
        part = np.zeros((n_chunks, npad))
        for c in prange(n_chunks):
            en = np.empty((B, bl))
            ssum = np.empty(bl)
            c0 = np.empty(bl)
            c1 = np.empty(bl)
            e1 = np.empty(bl)
            for blk in range(nblk):
                q0 = blk * bl
                for p in range(bl):
                    c0[p] = coef[0, q0 + p]
                    c1[p] = coef[1, q0 + p]
                    e1[p] = coef[3, q0 + p]
                    ssum[p] = 0.0
                for i in range(c * chunk, min(n_nodes, (c + 1) * chunk)):
                    base = i * B * nv
                    for s in range(B):
                        es = en[s]
                        for p in range(bl):
                            es[p] = 0.0
                        for t in range(nv):
                            e = base + t * B + s
                            f0 = feat[0, e]
                            f1 = feat[1, e]
                            g1 = feat[3, e]
                            for p in range(bl):
                                es[p] += c0[p] * f0 + c1[p] * f1 * vexp(e1[p] * g1)
                    for p in range(bl):
                        c0[p] = 0.0  # reuse as the label sum
                    for s in range(B):
                        es = en[s]
                        for p in range(bl):
                            c0[p] += vexp(-es[p])
                    for p in range(bl):
                        ssum[p] += vlog(c0[p])
                        c0[p] = coef[0, q0 + p]
                for p in range(bl):
                    part[c, q0 + p] = ssum[p]
        for c in range(n_chunks):
            for q in range(npad):
                out[q] += part[c, q]

    return floor


def bench(brdf: str, shape: tuple[int, int], labels: list[int], repeat: int, pmc: bool,
          floor_kernel, dtype: str = "float64") -> list[dict]:
    """One row per label count: construction, memory, log_prob timings, floor, PMC."""
    import numba

    import mrfpe
    from mrfpe.brdf.engine.classic import block_size
    from mrfpe.brdf.synthetic import make_scene
    from mrfpe.brdf.targets import reflectance

    model = mrfpe.brdf.get(brdf)
    threads = numba.get_num_threads()
    rng = np.random.default_rng(0)
    theta = rng.random((1000, model.d))
    truth = model.to_natural(np.array(THETA[brdf]))
    surface = SURFACE.get(brdf, "jagged")
    # compile this dtype's kernels outside the timings
    tiny = mrfpe.targets.get("pls", make_scene(brdf=brdf, theta=truth, shape=(2, 2),
                                               n_labels=2, seed=0), dtype=dtype)
    tiny.log_prob(theta[:70])
    if pmc:  # first-call costs (imports, scipy/numpy caches) out of the PMC timings
        mrfpe.sample("pmc", tiny, seed=0, n_samples=50, n_iterations=2)
    rows = []
    for B in labels:
        scene = make_scene(brdf=brdf, theta=truth, shape=shape, n_labels=B, surface=surface,
                           seed=0)
        with peak_memory() as mem:
            t0 = time.perf_counter()
            target = mrfpe.targets.get("pls", scene, dtype=dtype)
            t_build = time.perf_counter() - t0
        evals = target._tables.brdf_evals_per_particle
        row = {"brdf": brdf, "dtype": dtype, "labels": B, "build_s": t_build,
               "target_MiB": target.nbytes / 2**20, "build_peak_MiB": mem["traced_MiB"],
               "evals_per_particle": evals}
        for n in (1, 64, 1000):
            target.log_prob(theta[:n])  # warm-up (page faults, caches)
            wall, cpu = best(lambda n=n, t=target: t.log_prob(theta[:n]), repeat)
            row[f"lp{n}_ms"] = wall * 1e3
            row[f"Meval_s_{n}"] = n * evals / wall / 1e6
            if n == 1000:
                row["lp1000_cpu_ms"] = cpu * 1e3
                row["ns_eval_wall"] = wall / (n * evals) * 1e9
                row["ns_eval_cpu_per_thread"] = cpu / (n * evals) * 1e9 / threads
        # comparison kernel: same number of Ward evaluations and label LSEs
        nv = max(1, round(target._tables.var_feat.shape[1] / (target._tables.n_nodes * B)))
        feat = np.ascontiguousarray(target._tables.var_feat, dtype=np.float64)
        nn = feat.shape[1] // (B * nv)
        coefm = reflectance.coefficients("ward", np.tile([0.5, 0.5, 0.2], (1000, 1)))
        bl = block_size(1000)
        npad = -(-1000 // bl) * bl
        ct = np.ascontiguousarray(np.resize(coefm, (npad, 5)).T)
        out = np.empty(npad)
        floor_kernel(ct, feat, nn, B, nv, bl, out)
        args = (ct, feat, nn, B, nv, bl, out)
        wall, _ = best(lambda a=args: floor_kernel(*a), repeat)
        row["floor_ms"] = wall * 1e3 * evals / (nn * B * nv)
        row["ratio_to_floor"] = row["lp1000_ms"] / row["floor_ms"]
        if pmc:
            with peak_memory() as mem:
                t0 = time.perf_counter()
                mrfpe.sample("pmc", target, seed=0, n_samples=1000, n_iterations=20)
                row["pmc_1000x20_s"] = time.perf_counter() - t0
            row["pmc_traced_MiB"] = mem["traced_MiB"]
            row["pmc_rss_MiB"] = mem["rss_MiB"]
            minutes = RUNTIME_MINUTES["pmc"].get(B)
            if minutes is not None:
                row["thesis_pmc_s"] = 60.0 * minutes
                row["speedup"] = 60.0 * minutes / row["pmc_1000x20_s"]
        rows.append(row)
        print(_fmt_row(row), flush=True)
    return rows


COLUMNS = [
    ("brdf", "brdf", "{}"), ("dtype", "dtype", "{}"), ("labels", "B", "{}"),
    ("build_s", "build s", "{:.2f}"),
    ("target_MiB", "target MiB", "{:.0f}"), ("build_peak_MiB", "build peak MiB", "{:.0f}"),
    ("lp1_ms", "lp(1) ms", "{:.2f}"), ("lp64_ms", "lp(64) ms", "{:.1f}"),
    ("lp1000_ms", "lp(1000) ms", "{:.0f}"), ("lp1000_cpu_ms", "cpu ms", "{:.0f}"),
    ("Meval_s_1", "Meval/s N=1", "{:.0f}"), ("Meval_s_64", "Meval/s N=64", "{:.0f}"),
    ("Meval_s_1000", "Meval/s N=1000", "{:.0f}"),
    ("ns_eval_wall", "ns/eval wall", "{:.3f}"),
    ("ns_eval_cpu_per_thread", "ns/eval cpu/thr", "{:.3f}"),
    ("floor_ms", "floor ms", "{:.0f}"), ("ratio_to_floor", "lp/floor", "{:.2f}"),
    ("pmc_1000x20_s", "PMC 1000x20 s", "{:.1f}"), ("thesis_pmc_s", "thesis s", "{:.0f}"),
    ("speedup", "× thesis", "{:.0f}"),
    ("pmc_traced_MiB", "PMC peak MiB", "{:.0f}"), ("pmc_rss_MiB", "PMC peak RSS MiB", "{:.0f}"),
]

NOTES = (
    "`Meval/s` counts BRDF evaluations (variable + fixed triangles) per second for a batch "
    "of N parameter vectors; `ns/eval` is per evaluation at N=1000, the label log-sum-exp "
    "included in the time; `cpu/thr` divides the CPU time by the thread count (the wall "
    "time on idle cores). `floor` is the comparison kernel (the bare Ward + log-sum-exp "
    "loop, float64) scaled to the same number of evaluations. `thesis s`: Table 8.12 (PMC "
    "1000 x 20 on an AMD Athlon 4600). `build peak` and `PMC peak` are traced (numpy) "
    "allocations above the start; `PMC peak RSS` is the whole process's high-water mark "
    "during the run (interpreter and libraries included)."
)


def _fmt_row(row: dict) -> str:
    cells = (fmt.format(row[k]) if k in row else "-" for k, _, fmt in COLUMNS)
    return "| " + " | ".join(cells) + " |"


def table(rows: list[dict]) -> str:
    head = "| " + " | ".join(h for _, h, _ in COLUMNS) + " |"
    sep = "|" + "|".join("---" for _ in COLUMNS) + "|"
    return "\n".join([head, sep, *(_fmt_row(r) for r in rows)])


def pmc_growth(rows: list[dict]) -> list[str]:
    """Least-squares line of PMC seconds against labels, per (brdf, dtype)."""
    lines = []
    for key in sorted({(r["brdf"], r["dtype"]) for r in rows}):
        sel = [r for r in rows if (r["brdf"], r["dtype"]) == key and "pmc_1000x20_s" in r]
        if len(sel) < 2:
            continue
        B = np.array([r["labels"] for r in sel], dtype=float)
        t = np.array([r["pmc_1000x20_s"] for r in sel])
        slope, icpt = np.polyfit(B, t, 1)
        resid = np.max(np.abs(t - (slope * B + icpt)) / t)
        lines.append(f"- PMC growth, {key[0]} {key[1]}: {slope:.3f} s per label + {icpt:.2f} s "
                     f"(largest relative deviation from the line {resid:.0%})")
    return lines


def run(brdfs: list[str], dtypes: list[str], labels: list[int], shape: tuple[int, int],
        repeat: int = 3, pmc: bool = False) -> tuple[list[dict], list[str]]:
    """All rows and the markdown body (table, notes, PMC growth)."""
    floor = comparison_kernel()
    print("| " + " | ".join(h for _, h, _ in COLUMNS) + " |")
    rows = []
    for brdf in brdfs:
        for dtype in dtypes:
            rows += bench(brdf, shape, labels, repeat, pmc, floor, dtype)
    body = [f"`pls` on {shape[0]}x{shape[1]} synthetic scenes. {NOTES}\n", table(rows)]
    growth = pmc_growth(rows)
    if growth:
        body += ["", *growth]
    return rows, body


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--brdf", nargs="+", default=["ward"])
    p.add_argument("--labels", nargs="+", type=int, default=[10, 20, 30, 40])
    p.add_argument("--dtype", nargs="+", default=["float64"], choices=["float64", "float32"])
    p.add_argument("--shape", nargs=2, type=int, default=[100, 100])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--pmc", action="store_true", help="also time PMC 1000 x 20 (and its memory)")
    p.add_argument("--no-write", action="store_true", help="do not append to RESULTS.md")
    args = p.parse_args(argv)

    info = machine()
    print(" ".join(f"{k}={v}" for k, v in info.items()))
    _, body = run(args.brdf, args.dtype, args.labels, tuple(args.shape), args.repeat, args.pmc)
    if not args.no_write:
        append_results(f"bench_targets: pls {args.shape[0]}x{args.shape[1]}",
                       command_line(argv, "benchmarks.bench_targets"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
