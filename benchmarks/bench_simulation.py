"""Batched simulation of declared models (:mod:`mrfpe.models.simulate_batch`): ratios.

Every comparison is a **ratio in one run**: the sides alternate and the medians of a few
repeats are compared, so a shared, noisy machine slows both alike. Sweep cost is
``(t(K sweeps) - t(0 sweeps)) / K``: the one-off setup (tables, CSR, colouring) is left out.

* ``scalar``: per-site update rate (updates/ns) of the scalar Gibbs sweep
  (:func:`~mrfpe.models.simulate_batch.simulate_batch`, one chain, one thread), the
  lattice kernel (:mod:`mrfpe.models.lattice_gibbs`) against the general CSR kernel (the
  same draws) on a binary 4-neighbour lattice at 512² and a 6-state one at 256², and on
  the binary one against :class:`NumpyCheckerboard`, a vectorised int8 NumPy
  checkerboard sweep (goal: >= 6x);
* ``batch``: 64 chains at 64 parameter vectors in one call against 64 single-chain calls,
  and the batch's aggregate per-site rate against one chain's (goal >= 10x once a
  multi-spin kernel exists; what the scalar batched path gives is reported);
* ``threads``: two threads against one on one chain at 1024² (goal >= 1.7x on an idle
  machine), with the library's spare-core rule and with two threads forced, and the
  single-chain :func:`~mrfpe.models.simulate.simulate` beside.

Anchors printed beside (published, other machines): scalar C++ checkerboard 0.16-0.33
updates/ns/core; multi-spin coding ~28 updates/ns/core; bayesImageS ~0.005 updates/ns/core.

Usage (from the repository root)::

    python -m benchmarks.bench_simulation                 # appended to RESULTS.md
    python -m benchmarks.bench_simulation --quick --no-write
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from benchmarks._common import append_results, command_line, load_avg, machine

ANCHORS = ("scalar C++ checkerboard 0.16-0.33 updates/ns/core; multi-spin ~28 updates/ns/core; "
           "bayesImageS ~0.005 updates/ns/core")


class NumpyCheckerboard:
    """Reference: Gibbs sweeps of the Ising model ``J [x_i = x_j] + h [x_i = 1]`` (free
    boundary, 4 neighbours) in vectorised NumPy, written for speed.

    The two colour classes are stored apart as int8 ``(H, W/2)`` arrays (site ``(r, c)``
    of class ``(r + c) % 2`` at ``[r, c // 2]``), so a half sweep touches only its own
    sites: the neighbours of a site are the other class's entries ``[r +- 1, k]``,
    ``[r, k]`` and ``[r, k - 1]`` or ``[r, k + 1]`` by row parity. The count of neighbours
    in state 1 plus five times the degree indexes a float32 table of ``p(x_i = 1)``, met
    by float32 uniforms; every buffer is preallocated.
    """

    def __init__(self, shape: tuple[int, int], J: float, h: float, seed: int = 0) -> None:
        H, W = shape
        if W % 2:
            raise ValueError("the width must be even")
        self.rng = np.random.default_rng(seed)
        r, c = np.indices(shape)
        deg = 4 - (r == 0) - (r == H - 1) - (c == 0) - (c == W - 1)
        self.off = [self._split(5 * deg, s).astype(np.int8) for s in (0, 1)]
        code = np.arange(25)
        n1, d = code % 5, code // 5
        self.table = (1 / (1 + np.exp(-(J * (2 * n1 - d) + h)))).astype(np.float32)
        self.x = [self.rng.integers(0, 2, (H, W // 2), dtype=np.int8) for _ in (0, 1)]
        self.n = np.empty((H, W // 2), np.int8)
        self.p = np.empty((H, W // 2), np.float32)
        self.u = np.empty((H, W // 2), np.float32)

    @staticmethod
    def _split(F: np.ndarray, s: int) -> np.ndarray:
        """Class ``s``'s entries of the full ``(H, W)`` array ``F``, as ``(H, W/2)``."""
        out = np.empty((F.shape[0], F.shape[1] // 2), F.dtype)
        out[0::2], out[1::2] = F[0::2, s::2], F[1::2, 1 - s::2]
        return out

    def sweep(self, n_sweeps: int = 1) -> None:
        for _ in range(n_sweeps):
            for s in (0, 1):
                self._half(s)

    def _half(self, s: int) -> None:
        S, O, n = self.x[s], self.x[1 - s], self.n
        np.copyto(n, O)
        n[1:] += O[:-1]
        n[:-1] += O[1:]
        left, right = slice(s, None, 2), slice(1 - s, None, 2)  # rows by parity
        n[left, 1:] += O[left, :-1]
        n[right, :-1] += O[right, 1:]
        n += self.off[s]
        np.take(self.table, n, out=self.p)
        self.rng.random(out=self.u, dtype=np.float32)
        np.less(self.u, self.p, out=S.view(np.bool_))

    def configuration(self) -> np.ndarray:
        H, W2 = self.n.shape
        x = np.empty((H, 2 * W2), np.int8)
        for s in (0, 1):
            x[0::2, s::2], x[1::2, 1 - s::2] = self.x[s][0::2], self.x[s][1::2]
        return x


def _design(side: int, q: int = 2):
    from mrfpe.models.discrete import MRF
    from mrfpe.models.graph import lattice
    from mrfpe.models.terms import Coupling, Field

    return MRF(lattice(4), q, [Coupling(), Field()]).compile((side, side))[0]


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _sweep_seconds(run: Callable[[int], object], k: int, repeat: int) -> float:
    """Median of ``(t(k) - t(0)) / k`` over ``repeat`` paired calls."""
    run(1)  # load or compile
    return float(np.median([max(_timed(lambda: run(k)) - _timed(lambda: run(0)), 1e-12) / k
                            for _ in range(repeat)]))


@contextmanager
def _general_kernel() -> Iterator[None]:
    """Route simulate_batch's Gibbs chains to the general (CSR) kernel, as for a non-lattice."""
    from mrfpe.models import simulate_batch as sb

    saved = sb.lattice_stencil
    sb.lattice_stencil = lambda design: None
    try:
        yield
    finally:
        sb.lattice_stencil = saved


def scalar_vs_numpy(quick: bool) -> list[str]:
    """The lattice kernel against the general CSR kernel (the same draws) and, on the binary
    lattice, the NumPy checkerboard; one thread, the three alternated."""
    return [*_scalar_case(2, 512, quick), "", *_scalar_case(6, 256, quick)]


def _scalar_case(q: int, side: int, quick: bool) -> list[str]:
    """One lattice size and q: the three samplers' per-site rates, as a table."""
    from mrfpe.models.simulate_batch import simulate_batch
    from mrfpe.threads import limit_threads

    rows: list[str] = []
    side, k, repeat = (side // 4, 20, 2) if quick else (side, 60, 5)
    design = _design(side, q)
    h = [0.05] if q == 2 else np.linspace(-0.1, 0.1, q - 1)  # q = 2: NumPy's model
    psi = design.psi(np.array([[0.4, *h]]))

    def sweeps(m: int) -> object:
        return simulate_batch(design, psi, 1, seed=0, method="gibbs", n_sweeps=m,
                              kernel="scalar")

    def general(m: int) -> object:
        with _general_kernel():
            return sweeps(m)

    ref = NumpyCheckerboard((side, side), 0.4, 0.05) if q == 2 else None
    times: dict[str, list[float]] = {"lattice": [], "general": [], "numpy": []}
    with limit_threads(1):
        for _ in range(repeat):
            times["lattice"].append(_sweep_seconds(sweeps, k, 1))
            times["general"].append(_sweep_seconds(general, k, 1))
            if ref is not None:
                ref.sweep(1)
                times["numpy"].append(_timed(lambda: ref.sweep(max(2, k // 10)))
                                      / max(2, k // 10))
    rate = {key: side * side / (np.median(t) * 1e9) for key, t in times.items() if t}
    base = rate.get("numpy")
    rows += [f"**Scalar Gibbs, {q}-state Potts {side}² (4-neighbour, "
             f"coupling 0.4), one thread**: medians of {repeat} alternated repeats.\n",
             "| sampler | updates/ns | ns/update | ÷ general kernel's time | ÷ NumPy time |",
             "|---|---|---|---|---|"]
    for key, label in (("lattice", "simulate_batch gibbs, lattice kernel (uint8 stencil)"),
                       ("general", "simulate_batch gibbs, general kernel (CSR)"),
                       ("numpy", "NumPy int8 checkerboard (reference, binary only)")):
        if key in rate:
            a = rate[key]
            vs = f"{a / base:.2f}×" if base else "–"
            rows.append(f"| {label} | {a:.3f} | {1 / a:.2f} | {a / rate['general']:.2f}× "
                        f"| {vs} |")
    if base:
        rows.append(f"\nGoal ≥ 6× NumPy: {'met' if rate['lattice'] / base >= 6 else 'not met'}"
                    f" ({rate['lattice'] / base:.2f}×). Anchors: {ANCHORS}.")
    return rows


def batch_vs_single(quick: bool) -> list[str]:
    import numba

    from mrfpe.models.simulate import simulate
    from mrfpe.models.simulate_batch import simulate_batch
    from mrfpe.threads import limit_threads

    side, B, k, repeat = (32, 16, 20, 2) if quick else (64, 64, 100, 3)
    design = _design(side)
    psi = design.psi(np.column_stack([np.linspace(0.0, 0.9, B), np.zeros(B)]))
    threads = numba.get_num_threads()

    def batched(t: int) -> float:
        with limit_threads(t):
            return _timed(lambda: simulate_batch(design, psi, 1, seed=0, method="gibbs",
                                                 n_sweeps=k))

    def separate() -> float:
        return _timed(lambda: [simulate(design, p, 1, seed=b, method="gibbs", n_sweeps=k)
                               for b, p in enumerate(psi)])

    one = _sweep_seconds(lambda m: simulate(design, psi[B // 2], 1, seed=0, method="gibbs",
                                            n_sweeps=m), k, repeat)
    batched(1), separate()  # compile
    t1, tt, ts = (float(np.median(v)) for v in zip(*[(batched(1), batched(threads), separate())
                                                     for _ in range(repeat)]))
    work = B * side * side * k
    rate1, rate_t, rate_one = work / t1 / 1e9, work / tt / 1e9, side * side / one / 1e9
    return ["", f"**{B} chains at {B} parameter vectors, Ising {side}², {k} sweeps each** "
            f"(medians of {repeat} alternated repeats; whole calls, setup included).\n",
            "| route | threads | s | updates/ns (all chains) | ÷ separate calls' time | "
            "÷ one chain's per-site rate |", "|---|---|---|---|---|---|",
            f"| {B} single-chain simulate calls | default | {ts:.3f} | {work / ts / 1e9:.3f} "
            f"| 1× | {work / ts / 1e9 / rate_one:.2f}× |",
            f"| one simulate_batch call | 1 | {t1:.3f} | {rate1:.3f} | {ts / t1:.2f}× | "
            f"{rate1 / rate_one:.2f}× |",
            f"| one simulate_batch call | {threads} | {tt:.3f} | {rate_t:.3f} | {ts / tt:.2f}× "
            f"| {rate_t / rate_one:.2f}× |",
            f"\nOne chain alone (sweeps only, one thread's default at {side}²): "
            f"{rate_one:.3f} updates/ns. Goal ≥ 10× the one-chain per-site rate needs "
            f"multi-spin coding; the scalar batched path gives {rate_t / rate_one:.2f}×."]


def two_vs_one_thread(quick: bool) -> list[str]:
    import numba

    from mrfpe.models import simulate_batch as sb
    from mrfpe.models.simulate import simulate
    from mrfpe.threads import limit_threads

    side, k, repeat = (256, 10, 2) if quick else (1024, 40, 3)
    design = _design(side)
    psi = design.psi(np.array([[0.4, 0.05]]))
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    spare = sb.spare_cores

    def every_core() -> int:
        return threads

    def run(route: str, t: int) -> float:
        def fn(m: int) -> object:
            if route == "simulate":
                return simulate(design, psi[0], 1, seed=0, method="gibbs", n_sweeps=m)
            return sb.simulate_batch(design, psi, 1, seed=0, method="gibbs", n_sweeps=m)

        sb.spare_cores = every_core if route == "forced" else spare
        try:
            with limit_threads(t):
                return _sweep_seconds(fn, k, 1)
        finally:
            sb.spare_cores = spare

    routes = (("simulate_batch, spare-core rule (default)", "spare"),
              ("simulate_batch, 2 threads forced", "forced"),
              ("simulate (single chain, static blocks)", "simulate"))
    rows = ["", f"**Two threads vs one, one chain, Ising {side}², {k} sweeps** (medians of "
            f"{repeat} alternated repeats; load average at start {load_avg()}).\n",
            "| route | 1 thread ns/update | 2 threads ns/update | speed-up |", "|---|---|---|---|"]
    for label, route in routes:
        one, two = (float(np.median(v)) for v in zip(*[(run(route, 1), run(route, threads))
                                                       for _ in range(repeat)]))
        n = side * side
        rows.append(f"| {label} | {one / n * 1e9:.2f} | {two / n * 1e9:.2f} | {one / two:.2f}× |")
        print(rows[-1], flush=True)
    rows.append(f"\nLoad average at end {load_avg()}; goal ≥ 1.7× on an idle machine.")
    return rows


MEASUREMENTS = {"scalar": scalar_vs_numpy, "batch": batch_vs_single, "threads": two_vs_one_thread}


def run(quick: bool = False, parts: list[str] | None = None) -> list[str]:
    body: list[str] = []
    for name in parts or list(MEASUREMENTS):
        lines = MEASUREMENTS[name](quick)
        print("\n".join(lines), flush=True)
        body += lines
    return body


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_simulation", description=__doc__,
                                formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--parts", nargs="+", choices=list(MEASUREMENTS), default=list(MEASUREMENTS))
    p.add_argument("--quick", action="store_true", help="small sizes: checks that it runs")
    p.add_argument("--no-write", action="store_true", help="print only; do not append")
    args = p.parse_args(argv)
    info = machine()
    print(" ".join(f"{k}={v}" for k, v in info.items()), flush=True)
    t0 = time.perf_counter()
    body = run(args.quick, args.parts)
    body.append(f"\nSuite time: {time.perf_counter() - t0:.0f} s.")
    if not args.no_write:
        append_results("batched simulation of declared models" + " (quick)" * args.quick,
                       command_line(argv, "benchmarks.bench_simulation"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
