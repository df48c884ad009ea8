"""The hidden-field sampler's sweep against a Gibbs sweep of the labels alone.

One sweep of the ``hidden`` sampler (labels with the data term, the emission's conjugate
update, the MRF's parameters by ``method="pl"``, the joint log density) on an image of
``--size``² pixels with q = 2 ... 6 states, one chain, against a Gibbs sweep of the same
labels without data (:func:`mrfpe.models.simulate.simulate`, method ``"gibbs"``):
medians of alternated repeats, so both see the same load. Goal: at most 3 x. Beside it,
the time per iteration (one chain) on a 500 x 500 image with bayesImageS's reported
11.5 s per 100 iterations of ``mcmcPotts`` (its paper's hardware, not this machine).

    python -m benchmarks.bench_hidden                 # 500 x 500, q = 2 ... 6
    python -m benchmarks.bench_hidden --size 200 --no-write
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import append_results, command_line, machine
from mrfpe import models
from mrfpe.models.hidden.point import start_point
from mrfpe.models.simulate import simulate
from mrfpe.samplers.hidden_steps import HiddenState, hidden_step, make_walks
from mrfpe.samplers.hidden_theta import make_theta_update

BAYESIMAGES_S_PER_ITERATION = 0.115  # 11.5 s / 100 iterations, 500 x 500 (its paper)


def _setup(size: int, q: int, seed: int = 0):
    hm = models.hidden(models.potts(q), models.emissions.gaussian())
    means = np.arange(q, dtype=float)
    _, y = hm.simulate([0.8, *np.zeros(q - 1), *means, 0.6], shape=(size, size), seed=seed,
                       n_sweeps=50)
    target = hm.target("hidden", y, fixed={n: 0.0 for n in hm.param_names()
                                           if n.startswith("field")})
    params, labels = start_point(target)
    params[0] = 0.8
    state = HiddenState(labels[None].copy(), params[None].copy(), np.zeros(1))
    walks = make_walks(target, 1, 0.05, 10, True, 0.3)
    return target, state, walks, make_theta_update(target)


def _median_pair(a, b, repeats: int) -> tuple[float, float]:
    ta, tb = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        a()
        ta.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        b()
        tb.append(time.perf_counter() - t0)
    return float(np.median(ta)), float(np.median(tb))


def measure(size: int, qs: tuple[int, ...], sweeps: int, repeats: int) -> list[str]:
    rows = ["| q | hidden sweep (s) | labels-only Gibbs sweep (s) | ratio | goal |",
            "|---|---|---|---|---|"]
    per_iteration = {}
    for q in qs:
        target, state, walks, update = _setup(size, q)
        rng = np.random.default_rng(1)
        psi = target.design.psi(state.params[:, : target.n_mrf])[0]
        x0 = state.labels[0].copy()

        def hidden(target=target, state=state, walks=walks, update=update, rng=rng):
            for _ in range(sweeps):
                hidden_step(target, state, walks, rng, theta_update=update, theta_steps=3,
                            swendsen_wang=False)

        def labels(target=target, psi=psi, x0=x0):
            simulate(target.design, psi, 1, seed=2, method="gibbs", n_sweeps=sweeps, init=x0)

        hidden(), labels()  # compile and warm the caches
        th, tl = _median_pair(hidden, labels, repeats)
        per_iteration[q] = th / sweeps
        rows.append(f"| {q} | {th / sweeps:.4f} | {tl / sweeps:.4f} | {th / tl:.2f} x | "
                    f"{'met' if th / tl <= 3 else 'not met'} (≤ 3 x) |")
    rows += ["", f"Image {size} x {size}, one chain, {sweeps} sweeps per repeat, medians of "
                 f"{repeats} alternated repeats. bayesImageS (its paper's hardware): "
                 f"{BAYESIMAGES_S_PER_ITERATION:.3f} s per iteration of `mcmcPotts` on 500 x 500; "
                 "ours: " + ", ".join(f"q = {q}: {t:.3f} s" for q, t in per_iteration.items())
                 + (" (this size)" if size != 500 else "") + "."]
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=500)
    p.add_argument("--q", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    p.add_argument("--sweeps", type=int, default=5)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--no-write", action="store_true")
    a = p.parse_args(argv)
    info = machine()
    body = measure(a.size, tuple(a.q), a.sweeps, a.repeats)
    print("\n".join(body))
    if not a.no_write:
        append_results("hidden-field sweep against a labels-only sweep",
                       command_line(argv, "benchmarks.bench_hidden"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
