"""Declared models (:mod:`mrfpe.models`): simulation and pseudolikelihood speed.

Every comparison is a **ratio in one run**: the two sides alternate and the
medians of several repeats are compared, so a shared, noisy machine slows both
alike.

* ``gibbs``: Gibbs site updates per second of :func:`mrfpe.models.simulate.simulate`
  (numba, colour classes, counter-based uniforms) against a plain vectorised NumPy
  checkerboard sweep (:func:`numpy_gibbs`, the sweep of
  :func:`mrfpe.models.short_forms.gibbs_sample`: neighbour counts, softmax, inverse CDF)
  on a 512 x 512 Ising model (q = 2, 4-neighbour), numba on one thread (against the
  single-threaded NumPy sweep) and with the threads the library takes by default
  (``thread_budget``: a second thread from ~1.6e6 site-states per sweep, so at 512²
  Ising still one). Sweep cost is ``(t(K sweeps) - t(0 sweeps)) / K``: the one-off
  setup (tables, CSR, colouring) is reported apart;
* ``growth``: the same, one thread, over lattice size (64² ... 2048², q = 2) and
  states (q = 2, 4, 8, 16 at 256²);
* ``swendsen_wang``: Swendsen-Wang and Gibbs sweeps per second (one thread), Potts
  512² at the critical coupling ``log(1 + sqrt(q))``.

* ``label_sweeps``: Gibbs sweeps of the BRDF label field
  (:func:`mrfpe.brdf.simulate.simulate_labels`) with the radiance memo
  against rendering every triangle, after a warm-up that fills the memo
  (:func:`label_sweeps`);
* ``posteriors``: the cost of a posterior over θ by raw exp(PL), the calibrated
  pseudolikelihood and the exchange algorithm (:func:`posterior_costs`);
* ``pl``: pseudolikelihood evaluation against a float64 GEMM of the same shape,
  over lattice size and states, with the build's time and peak memory
  (:func:`pl_rows`).

Each measurement is a function ``(quick) -> markdown lines`` in
:data:`MEASUREMENTS`; :func:`run` takes the part names.

Usage (from the repository root)::

    python -m benchmarks.bench_models                     # every part, appended to RESULTS.md
    python -m benchmarks.bench_models --parts gibbs --no-write
    python -m benchmarks.bench_models --quick --no-write  # small sizes: checks that it runs
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from benchmarks._common import append_results, command_line, machine


def numpy_gibbs(x: np.ndarray, J: float, h: np.ndarray, n_sweeps: int,
                rng: np.random.Generator) -> None:
    """Reference: ``n_sweeps`` vectorised NumPy checkerboard sweeps of ``x`` (H, W) in place.

    Potts ``J [x_i = x_j] + h[x_i]`` on the free-boundary 4-neighbour lattice, each half
    sweep drawing one colour from ``p(a) ∝ exp(J n_i(a) + h_a)`` by inverse CDF.
    """
    H, W = x.shape
    q = h.size
    colour = np.add.outer(np.arange(H), np.arange(W)) % 2
    masks = (colour == 0, colour == 1)
    states = np.arange(q)
    for _ in range(n_sweeps):
        for m in masks:
            oh = x[..., None] == states  # (H, W, q) one-hot
            n = np.zeros((H, W, q))
            n[1:] += oh[:-1]
            n[:-1] += oh[1:]
            n[:, 1:] += oh[:, :-1]
            n[:, :-1] += oh[:, 1:]
            logits = J * n[m] + h
            logits -= logits.max(axis=1, keepdims=True)
            cdf = np.cumsum(np.exp(logits), axis=1)
            u = rng.random(cdf.shape[0]) * cdf[:, -1]
            x[m] = np.minimum((u[:, None] >= cdf).sum(axis=1), q - 1)


def _potts(shape: tuple[int, int], q: int, J: float, field: float = 0.1):
    """Design and psi of Potts ``J [x_i = x_j]`` + field ``h_a = field * a / q`` (a >= 1)."""
    from mrfpe.models.discrete import MRF
    from mrfpe.models.graph import lattice
    from mrfpe.models.terms import Coupling, Field

    design, _, _ = MRF(lattice(4), q, [Coupling(), Field()]).compile(shape)
    h = field * np.arange(q) / q
    return design, design.psi(np.array([[J, *h[1:]]]))[0], h


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def simulate_rates(design, psi, method: str, n_sweeps: int, repeat: int,
                   threads: int | None = None) -> dict:
    """Median seconds per sweep (setup excluded) and of the setup alone."""
    import numba

    from mrfpe.models.simulate import simulate
    from mrfpe.threads import limit_threads

    def call(k):
        with limit_threads(threads or numba.get_num_threads()):
            return _timed(lambda: simulate(design, psi, 1, seed=0, method=method,
                                           n_sweeps=k))

    call(1)  # load or compile the kernel
    setup = [call(0) for _ in range(repeat)]
    total = [call(n_sweeps) for _ in range(repeat)]
    s0 = float(np.median(setup))
    return {"sweep_s": max(float(np.median(total)) - s0, 1e-12) / n_sweeps, "setup_s": s0}


def numpy_rate(shape, q, J, h, n_sweeps) -> float:
    """Seconds per sweep of :func:`numpy_gibbs`."""
    rng = np.random.default_rng(0)
    x = rng.integers(0, q, size=shape)
    return _timed(lambda: numpy_gibbs(x, J, h, n_sweeps, rng)) / n_sweeps


def gibbs_vs_numpy(quick: bool = False) -> list[str]:
    """The headline: numba Gibbs against the NumPy sweep, 512² Ising, alternated."""
    import numba

    shape = (128, 128) if quick else (512, 512)
    n_sites = shape[0] * shape[1]
    repeat, k_numba, k_numpy = (2, 20, 2) if quick else (5, 50, 4)
    design, psi, h = _potts(shape, 2, 0.6)
    threads = numba.get_num_threads()
    times: dict[str, list[float]] = {"numpy": [], "numba_1": [], f"numba_{threads}": []}
    setup = []
    for _ in range(repeat):
        times["numpy"].append(numpy_rate(shape, 2, 0.6, h, k_numpy))
        for t in (1, threads):
            r = simulate_rates(design, psi, "gibbs", k_numba, 1, t)
            times[f"numba_{t}"].append(r["sweep_s"])
            setup.append(r["setup_s"])
    med = {k: float(np.median(v)) for k, v in times.items()}
    rows = [f"Gibbs, Ising {shape[0]}² (q = 2, 4-neighbour, J = 0.6, field 0.05): medians of "
            f"{repeat} alternated repeats; simulate's setup {np.median(setup):.3f} s excluded.\n",
            "| sampler | threads | site updates/s | ns/site | ÷ NumPy time |",
            "|---|---|---|---|---|"]
    for k, label, thr in (("numpy", "NumPy checkerboard (reference)", "1"),
                          ("numba_1", "mrfpe.models.simulate gibbs", "1"),
                          (f"numba_{threads}", "mrfpe.models.simulate gibbs",
                           f"default (≤ {threads})")):
        if k == f"numba_{threads}" and threads == 1:
            continue
        rows.append(f"| {label} | {thr} | {n_sites / med[k]:.3g} | "
                    f"{med[k] / n_sites * 1e9:.2f} | {med['numpy'] / med[k]:.1f}× |")
        print(rows[-1], flush=True)
    return rows


def growth(quick: bool = False) -> list[str]:
    """Site updates per second over lattice size and number of states."""
    sizes = (32, 64) if quick else (64, 256, 1024, 2048)
    states = (2, 4) if quick else (2, 4, 8, 16)
    base = 32 if quick else 256
    rows = ["", "| growth (1 thread) | nodes | q | numba site updates/s | ns/site "
            "| setup s | NumPy ns/site | NumPy ÷ numba time |", "|---|---|---|---|---|---|---|---|"]
    cases = [("size", s, 2) for s in sizes] + [("states", base, q) for q in states[1:]]
    for what, side, q in cases:
        n_sites = side * side
        design, psi, h = _potts((side, side), q, 0.6)
        k = max(4, min(100, int(3e7 // (n_sites * q))))
        r = simulate_rates(design, psi, "gibbs", k, 3 if n_sites <= 1 << 20 else 1, threads=1)
        k_np = max(1, min(10, int(3e6 // (n_sites * q))))
        npt = numpy_rate((side, side), q, 0.6, h, k_np)
        rows.append(f"| {what} | {side}² | {q} | {n_sites / r['sweep_s']:.3g} | "
                    f"{r['sweep_s'] / n_sites * 1e9:.2f} | {r['setup_s']:.2f} | "
                    f"{npt / n_sites * 1e9:.1f} | {npt / r['sweep_s']:.1f}× |")
        print(rows[-1], flush=True)
    return rows


def swendsen_wang_rates(quick: bool = False) -> list[str]:
    """Swendsen-Wang against Gibbs sweeps per second at the critical Potts coupling."""
    side = 128 if quick else 512
    rows = ["", f"| Potts {side}², J = log(1 + √q), 1 thread | q | Swendsen-Wang sweeps/s | "
            "Gibbs sweeps/s | SW ns/site |", "|---|---|---|---|---|"]
    for q in (2, 4):
        design, psi, _ = _potts((side, side), q, float(np.log1p(np.sqrt(q))), field=0.0)
        sw = simulate_rates(design, psi, "swendsen_wang", 10 if quick else 30, 3, threads=1)
        gb = simulate_rates(design, psi, "gibbs", 10 if quick else 30, 3, threads=1)
        rows.append(f"| critical | {q} | {1 / sw['sweep_s']:.1f} | {1 / gb['sweep_s']:.1f} | "
                    f"{sw['sweep_s'] / side**2 * 1e9:.1f} |")
        print(rows[-1], flush=True)
    return rows


def _median_alternated(fns: list[Callable[[], object]], repeat: int) -> list[float]:
    """Median wall time of each function, the functions alternated ``repeat`` times."""
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            times[k].append(_timed(fn))
    return [float(np.median(t)) for t in times]


def pl_rows(quick: bool = False) -> list[str]:
    """PL evaluation against a float64 GEMM of the same shape; growth; build memory.

    The log-linear PL of a batch of N parameter vectors is ``(R (q-1), P) @ (P, N)``
    over the R distinct conditional rows (differences to the observed state), then
    a log-sum-exp over the states: the GEMM of that shape is its floor.
    ``ns/(row·state·θ)`` divides by the rows actually evaluated;
    ``ns/(node·state·θ)`` by the lattice's nodes (what the distinct-row reduction
    saves). Covariates make every row distinct (R = nodes).
    """
    from benchmarks._common import peak_memory
    from mrfpe import models

    N = 64 if quick else 256
    sides = (64, 128) if quick else (64, 256, 1024, 2048)
    states = (2, 4) if quick else (2, 4, 8, 16)
    rng = np.random.default_rng(0)
    rows = ["", "**Pseudolikelihood evaluation** (`model.target(\"pl\", x).log_prob` of N = "
            f"{N} parameter vectors; medians of alternated repeats, the GEMM "
            "`(R·(q-1), P) @ (P, N)` of the same shape beside it)", "",
            "| model | lattice | q | distinct rows R | build s | build peak MiB (traced) | "
            "PL ms | GEMM ms | PL ÷ GEMM | ns/(row·state·θ) | ns/(node·state·θ) |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    cases = [("potts", s, 2) for s in sides] + [("potts", 256, q) for q in states[1:]]
    cases.append(("autologistic + covariate", 128 if quick else 256, 2))
    for name, side, q in cases:
        if name == "potts":
            m = models.potts(q, 4)
            x = rng.integers(0, q, (side, side))
            opts: dict = {}
            th = np.column_stack([rng.uniform(0, 1, N), rng.uniform(-1, 1, (N, q - 1))])
        else:
            m = models.autologistic(["z"])
            x = rng.integers(0, 2, (side, side))
            opts = {"covariates": {"z": rng.normal(size=(side, side))}}
            th = rng.uniform(-0.5, 0.5, (N, 3))
        t0 = time.perf_counter()
        with peak_memory() as mem:
            t = m.target("pl", x, **opts)
        build = time.perf_counter() - t0
        R = t.n_rows
        G = t.rows[0].D.reshape(-1, t.rows[0].D.shape[-1])  # (R (q-1), P), as the PL's GEMM
        psi = np.ascontiguousarray(th.T)
        pl_s, gemm_s = _median_alternated([lambda t=t, th=th: t.log_prob(th),
                                           lambda G=G, psi=psi: G @ psi], 3 if quick else 7)
        denom_rows, denom_nodes = R * q * N, side * side * q * N
        rows.append(f"| {name} | {side}² | {q} | {R} | {build:.2f} | "
                    f"{mem.get('traced_MiB', float('nan')):.0f} | {pl_s * 1e3:.2f} | "
                    f"{gemm_s * 1e3:.3f} | {pl_s / gemm_s:.1f} | "
                    f"{pl_s / denom_rows * 1e9:.2f} | {pl_s / denom_nodes * 1e9:.4f} |")
        print(rows[-1], flush=True)
    return rows


#: Particles of the PMC sample of exp(PL) that ``pl_sample=`` calibrates from.
PL_SAMPLE_SIZE = 4000


def _dagger(post) -> str:
    """" †" for a posterior that flagged itself unreliable."""
    return "" if post.attrs.get("diag_reliable", 1) else " †"


def posterior_costs(quick: bool = False) -> list[str]:
    """Cost of a posterior over θ: raw exp(PL), the calibrated PL, the exchange algorithm.

    One Ising data set per lattice size at the coupling 0.3 (spin convention, no
    field); each method with its defaults, PMC on the two PL targets. Simulation
    sweeps are the model simulator's sweeps over the whole lattice (the build of
    ``pl_adjusted``: pilot, Fisher information and MCMC-MLE rounds; exchange: the
    auxiliary chains of every step, ``n_steps x n_chains x aux_sweeps``, plus its
    two pilot runs). The calibration is built twice: with exp(PL)'s moments from its
    own importance sampler (the default) and from a PMC sample of exp(PL) with
    :data:`PL_SAMPLE_SIZE` particles (``pl_sample=``; the sample's own time is its own
    column), which replaces that sampler's rounds by 32 PL evaluations. A time marked
    † is of a posterior that flagged itself unreliable.
    """
    import json
    import warnings

    import mrfpe
    from mrfpe import models

    sides = (16,) if quick else (16, 32, 64)
    rows = ["", "**Cost of a posterior over θ** (Ising, coupling 0.3; defaults; PMC on the "
            "PL targets)", "",
            "| lattice | raw PL + PMC s | pl_adjusted build s | + PMC s | sweeps (build) | "
            f"PL sample ({PL_SAMPLE_SIZE}) s | build with it s | exchange s | "
            "sweeps (exchange) | exchange ÷ raw PL |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    m = models.ising()
    # compile PMC's and the PL's kernels first: the first row would otherwise include it
    x0 = m.simulate([0.3, 0.0], shape=(8, 8), seed=0, n_sweeps=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a tiny warm-up run: its posterior is not used
        mrfpe.sample("pmc", m.target("pl", x0), seed=0, n_samples=50, n_iterations=2)
    for side in sides:
        x = m.simulate([0.3, 0.0], shape=(side, side), seed=side, n_sweeps=300)
        cfg = {"n_steps": 400, "burn_in": 100} if quick else {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a quick run's short chains say so; timed anyway
            t0 = time.perf_counter()
            raw_post = mrfpe.sample("pmc", m.target("pl", x), seed=0)
            raw = time.perf_counter() - t0
            t0 = time.perf_counter()
            adj = m.target("pl_adjusted", x)
            build = time.perf_counter() - t0
            t0 = time.perf_counter()
            adj_post = mrfpe.sample("pmc", adj, seed=0)
            adj_pmc = time.perf_counter() - t0
            t0 = time.perf_counter()
            pl_sample = mrfpe.sample("pmc", m.target("pl", x), seed=1, n_samples=PL_SAMPLE_SIZE)
            sample_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            m.target("pl_adjusted", x, pl_sample=pl_sample)
            build_sample = time.perf_counter() - t0
            t0 = time.perf_counter()
            post = mrfpe.sample("exchange", m.target("likelihood", x), seed=0, **cfg)
            ex = time.perf_counter() - t0
        c = json.loads(post.attrs["config"])
        sweeps = int(c["n_steps"] * c["n_chains"] * post.attrs["aux_sweeps"])
        rows.append(f"| {side}² | {raw:.2f}{_dagger(raw_post)} | {build:.2f} | "
                    f"{adj_pmc:.2f}{_dagger(adj_post)} | {adj.n_simulation_sweeps} | "
                    f"{sample_s:.2f}{_dagger(pl_sample)} | {build_sample:.2f} | "
                    f"{ex:.1f}{_dagger(post)} | ≥ {sweeps} | {ex / raw:.0f} |")
        print(rows[-1], flush=True)
    return rows


def _label_sweeps(field, u, x, sweeps: int, memo: bool) -> np.ndarray:
    """``sweeps`` label sweeps from ``x``, with the radiance memo or rendering every triangle."""
    from mrfpe.brdf.simulate import simulate_labels

    return simulate_labels(field, u, 1, n_sweeps=sweeps, seed=1, init=x, memoise=memo)[0]


def label_sweeps(quick: bool = False) -> list[str]:
    """Seconds per BRDF label sweep with the radiance memo and without, alternated.

    Each side continues its own chain (Ward, pixel form, range prior, the scene's
    parameters x 0.9) from the observed labels; the memoised side first runs
    ``warm`` sweeps. Both chains are the same chain (the memo's radiances are the
    render's), so the two sides do the same work but for the look-ups.
    """
    from mrfpe.brdf.simulate import label_field, simulate_labels
    from mrfpe.brdf.synthetic import make_scene

    cases = [((10, 10), 5)] if quick else [((20, 20), 10), ((40, 40), 10), ((100, 100), 20)]
    warm, sweeps, repeat = (5, 2, 2) if quick else (40, 5, 3)
    rows = ["\n### BRDF label sweeps: radiance memo against rendering every triangle\n",
            f"Ward, pixel form, range prior; {warm} warm-up sweeps, then the median of "
            f"{repeat} alternated runs of {sweeps} sweeps per side.\n",
            "| image | labels | render (s/sweep) | memo (s/sweep) | render ÷ memo |",
            "|---|---|---|---|---|"]
    for shape, B in cases:
        sc = make_scene("ward", theta=[0.5, 0.3, 0.2], shape=shape, n_labels=B, seed=2,
                        noise=0.01)
        u = sc.model.to_unit(sc.true_theta[None])[0] * 0.9
        fields = {"memo": label_field(sc, prior="range"), "render": label_field(sc, prior="range")}
        state = {k: simulate_labels(fields[k], u, 1, n_sweeps=warm if k == "memo" else 0,
                                    seed=0)[0] for k in fields}

        def side(k: str, fields=fields, state=state, u=u) -> Callable[[], object]:
            def go() -> None:
                state[k] = _label_sweeps(fields[k], u, state[k], sweeps, memo=k == "memo")
            return go

        render, memo = _median_alternated([side("render"), side("memo")], repeat)
        rows.append(f"| {shape[0]}×{shape[1]} | {B} | {render / sweeps:.4f} | "
                    f"{memo / sweeps:.4f} | {render / memo:.1f} |")
        print(rows[-1], flush=True)
    return rows


#: The suite's measurements, in order: name -> ``(quick) -> markdown lines``.
MEASUREMENTS: dict[str, Callable[[bool], list[str]]] = {
    "gibbs": gibbs_vs_numpy,
    "growth": growth,
    "swendsen_wang": swendsen_wang_rates,
    "pl": pl_rows,
    "label_sweeps": label_sweeps,
    "posteriors": posterior_costs,
}


def run(quick: bool = False, parts: tuple[str, ...] = tuple(MEASUREMENTS)) -> list[str]:
    """The markdown body of the suite (``parts``: names in :data:`MEASUREMENTS`)."""
    body: list[str] = []
    for name in parts:
        body += MEASUREMENTS[name](quick)
    return body


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--no-write", action="store_true", help="do not append to RESULTS.md")
    p.add_argument("--parts", nargs="+", choices=list(MEASUREMENTS), default=list(MEASUREMENTS))
    args = p.parse_args(argv)
    info = machine()
    print(" ".join(f"{k}={v}" for k, v in info.items()), flush=True)
    t0 = time.perf_counter()
    body = run(args.quick, tuple(args.parts))
    body.append(f"\nSuite time: {time.perf_counter() - t0:.0f} s.")
    if not args.no_write:
        append_results("declared models" + (" (quick)" if args.quick else ""),
                       command_line(argv, "benchmarks.bench_models"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
