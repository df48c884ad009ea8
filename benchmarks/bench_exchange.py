"""Where the exchange algorithm's time goes: its auxiliary sweeps against everything else.

The exchange algorithm (Murray, Ghahramani & MacKay 2006) with auxiliary chains started
at the data (Caimo & Friel 2011) spends each step on one auxiliary draw per chain; the
rest of a step (proposal, target evaluations, the simulator's setup, the statistics of
the draws) is overhead. Per Ising lattice (coupling 0.3 in the spin convention, no
field; data from 300 sweeps), in one run:

* ``raw PL s``: the raw exp(PL) posterior (PMC with its defaults), the cheap reference;
* ``exchange s``: ``n_steps`` steps of 4 chains with a fixed ``aux_sweeps`` (so the
  sweep count is known) and the default auxiliary simulator (``sampler="auto"``);
* ``kernel µs/chain-sweep``: one chain-sweep of the simulator exchange calls, measured
  as ``(t(S sweeps) - t(0 sweeps)) / (S x chains)`` on the same call it makes per step
  (all chains in one call where the target offers ``simulate_aux``, else one call per
  chain), medians of alternated repeats;
* ``sweeps``: the steps' auxiliary sweeps (``n_steps x chains x aux_sweeps``) plus the
  two pilot runs that measure the auxiliary chain's autocorrelation time (each the
  smallest multiple of 250 sweeps of at least ``max(2000, 50 τ)``);
* ``exchange ÷ sweeps at kernel rate``: exchange's time over its sweeps at the kernel's
  rate (1 would be no overhead at all; the rate of a long call, so a call's fixed cost
  counts as overhead);
* ``in kernels s``: the time exchange spent inside the compiled sweep kernels, clocked
  by wrapping them (:func:`kernel_clock`); ``outside the kernels``: the rest, as a share
  of exchange's time; ``exchange ÷ raw PL``: this run's time over the raw PL's.

A second table times the auxiliary part of one step by the per-chain route (one
``simulate`` call per chain, as exchange ran before batching) and by the batched one,
alternated in one process, so that the ratio survives a noisy machine. A third prices
the auxiliary chain per unit of mixing at 64² -- its autocorrelation time times the
time of a sweep -- for Gibbs (scalar in exchange's batch of 4 chains; multi-spin with
64) and Swendsen-Wang, at the coupling 0.3 and near the
critical one (0.42; 0.4407 in the limit): the measurement behind ``sampler="auto"``
keeping Swendsen-Wang for the auxiliary chains.

Everything runs on one numba thread by default (``--threads``): a rate measured on two
threads of a shared 2-core machine depends on what else runs at that moment, and the
kernel's rate and exchange's steps must be measured alike.

Usage (from the repository root)::

    python -m benchmarks.bench_exchange             # appended to RESULTS.md
    python -m benchmarks.bench_exchange --no-write
    python -m benchmarks.bench_exchange --quick --no-write
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from contextlib import contextmanager

import numpy as np

from benchmarks._common import append_results, command_line, load_avg, machine

COUPLING = (0.3, 0.0)
CHAINS = 4
AUX_SWEEPS = 20  # about 10 τ of Swendsen-Wang at this coupling


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def kernel_seconds(target, theta: np.ndarray, n_sweeps: int = 400, repeat: int = 5) -> float:
    """Seconds of one chain-sweep of the auxiliary simulator, as exchange calls it."""
    rows = np.tile(theta, (CHAINS, 1))
    batched = callable(getattr(target, "simulate_aux", None))

    def call(k: int) -> None:
        if batched:
            target.simulate_aux(rows, seed=0, n_sweeps=k)
        else:
            for i in range(CHAINS):
                target.simulate(rows[i], seed=i, n_sweeps=k, init="data")

    call(1)  # compile
    per = [(_timed(lambda: call(n_sweeps)) - _timed(lambda: call(0))) / n_sweeps
           for _ in range(repeat)]
    return max(float(np.median(per)), 1e-12) / CHAINS


#: The compiled sweep kernels, as the Python code that calls them looks them up.
KERNELS = (("mrfpe.models.simulate", "_gibbs"), ("mrfpe.models.simulate", "_swendsen_wang"),
           ("mrfpe.models.simulate_batch", "_gibbs_chains"),
           ("mrfpe.models.simulate_batch", "_gibbs_blocks"),
           ("mrfpe.models.simulate_batch", "_sw_chains"), ("mrfpe.models.multispin", "sweeps"))


@contextmanager
def kernel_clock():
    """Seconds spent inside the compiled sweep kernels while the block runs (a one-item
    list, filled on exit): each kernel is wrapped by a timer in its caller's module."""
    import importlib

    spent = [0.0]
    saved = []
    for mod, name in KERNELS:
        module = importlib.import_module(mod)
        fn = getattr(module, name, None)
        if fn is None:
            continue

        def timed(*args, _fn=fn, **kwargs):
            t0 = time.perf_counter()
            try:
                return _fn(*args, **kwargs)
            finally:
                spent[0] += time.perf_counter() - t0

        saved.append((module, name, fn))
        setattr(module, name, timed)
    try:
        yield spent
    finally:
        for module, name, fn in saved:
            setattr(module, name, fn)


def _pilot_sweeps(tau: float) -> int:
    """Sweeps of one autocorrelation pilot (:func:`mrfpe.models.mixing.autocorrelation_time`)."""
    need = max(2000.0, 50.0 * tau) if math.isfinite(tau) else 20000.0
    return int(250 * math.ceil(min(need, 20000.0) / 250))


def rows(quick: bool = False, n_steps: int = 1000) -> list[str]:
    import mrfpe
    from mrfpe import models

    sides = (16,) if quick else (16, 32, 64)
    n_steps = 200 if quick else n_steps
    burn_in = n_steps // 4
    m = models.ising()
    x0 = m.simulate(list(COUPLING), shape=(8, 8), seed=0, n_sweeps=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # warm-up runs: compile the kernels, not timed
        mrfpe.sample("pmc", m.target("pl", x0), seed=0, n_samples=50, n_iterations=2)
        mrfpe.sample("exchange", m.target("likelihood", x0), seed=0, n_steps=40, burn_in=10,
                     aux_sweeps=2)
    out = [f"Ising, coupling {COUPLING[0]} (spin convention), {CHAINS} chains x {n_steps} "
           f"steps (burn-in {burn_in}), aux_sweeps = {AUX_SWEEPS}, default auxiliary "
           f"simulator; raw PL: PMC with its defaults.\n",
           "| lattice | raw PL s | exchange s | ms/step | kernel µs/chain-sweep | sweeps | "
           "exchange ÷ sweeps at kernel rate | in kernels s | exchange ÷ in kernels | "
           "outside the kernels | exchange ÷ raw PL | load |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for side in sides:
        x = m.simulate(list(COUPLING), shape=(side, side), seed=side, n_sweeps=300)
        target = m.target("likelihood", x)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # short chains say so; timed anyway
            pl = m.target("pl", x)
            raw = _timed(lambda: mrfpe.sample("pmc", pl, seed=0))  # noqa: B023 - called here
            with kernel_clock() as inside:
                t0 = time.perf_counter()
                post = mrfpe.sample("exchange", target, seed=0, n_steps=n_steps,
                                    burn_in=burn_in, n_chains=CHAINS, aux_sweeps=AUX_SWEEPS)
                ex = time.perf_counter() - t0
        cfg = json.loads(post.attrs["config"])
        sweeps = cfg["n_steps"] * CHAINS * AUX_SWEEPS + _pilot_sweeps(
            post.attrs["aux_tau_burn_in"]) + _pilot_sweeps(post.attrs["aux_tau_posterior_mean"])
        k = kernel_seconds(target, np.array(COUPLING))
        ratio = ex / (sweeps * k)
        out.append(f"| {side}² | {raw:.2f} | {ex:.2f} | {ex / n_steps * 1e3:.2f} | "
                   f"{k * 1e6:.1f} | {sweeps} | {ratio:.2f} | {inside[0]:.2f} | "
                   f"{ex / inside[0]:.2f} | {100 * (1 - inside[0] / ex):.0f} % | "
                   f"{ex / raw:.0f} | {load_avg()} |")
        print(out[-1], flush=True)
    return out


class PerChain:
    """A likelihood target without ``simulate_aux``: exchange's per-chain route (one
    ``simulate`` call and one ``unnormalised`` product per chain, as before batching)."""

    def __init__(self, target) -> None:
        self.target = target

    def simulate(self, *args, **kwargs):
        return self.target.simulate(*args, **kwargs)

    def unnormalised(self, *args, **kwargs):
        return self.target.unnormalised(*args, **kwargs)


def step_rows(quick: bool = False, repeat: int = 40) -> list[str]:
    """The auxiliary part of one exchange step (:func:`mrfpe.samplers.exchange.
    auxiliary_log_ratio`, 4 chains, ``AUX_SWEEPS`` sweeps) by the per-chain route and by
    one batched call, alternated in one process (medians), against its sweeps at the
    batched kernel's rate."""
    from mrfpe import models
    from mrfpe.samplers.exchange import auxiliary_log_ratio

    m = models.ising()
    out = [f"\nAuxiliary part of one step ({CHAINS} chains, {AUX_SWEEPS} sweeps each, the "
           f"default simulator), per-chain calls against one batched call, alternated in one "
           f"process: medians of {repeat}.\n",
           "| lattice | per-chain ms | batched ms | speed-up | sweeps at the kernel's rate ms | "
           "batched ÷ kernel | per-chain ÷ kernel |", "|---|---|---|---|---|---|---|"]
    for side in (16,) if quick else (16, 32, 64):
        x = m.simulate(list(COUPLING), shape=(side, side), seed=side, n_sweeps=300)
        t = m.target("likelihood", x)
        th = np.tile(COUPLING, (CHAINS, 1))
        prop = th + np.array([0.01, 0.0])
        rng = np.random.default_rng(0)
        routes = {"per": PerChain(t), "batched": t}
        times = {k: [] for k in routes}
        for _ in range(repeat):
            for k, tg in routes.items():
                times[k].append(_timed(lambda tg=tg, th=th, prop=prop, rng=rng:
                                       auxiliary_log_ratio(tg, th, prop, rng, AUX_SWEEPS)))
        per, bat = (float(np.median(times[k])) for k in ("per", "batched"))
        kern = kernel_seconds(t, np.array(COUPLING)) * CHAINS * AUX_SWEEPS
        out.append(f"| {side}² | {per * 1e3:.2f} | {bat * 1e3:.2f} | {per / bat:.2f}× | "
                   f"{kern * 1e3:.2f} | {bat / kern:.2f} | {per / kern:.2f} |")
        print(out[-1], flush=True)
    return out


def mixing_rows(quick: bool = False) -> list[str]:
    """Cost of the auxiliary chain per unit of mixing, Gibbs against Swendsen-Wang: the
    integrated autocorrelation time ``τ`` (sweeps, the mean of 3 pilots of
    :func:`mrfpe.models.mixing.autocorrelation_time` at θ from the data) times the time of
    one chain-sweep in exchange's batch of 4 chains (and of 64 on the multi-spin kernel)."""
    from mrfpe import models
    from mrfpe.models.mixing import autocorrelation_time

    side = 16 if quick else 64
    m = models.ising()
    out = [f"\nAuxiliary chain per unit of mixing, Ising {side}², started at data simulated "
           "at the coupling (300 sweeps): τ x µs per chain-sweep.\n",
           "| coupling | sampler | τ (sweeps) | µs/chain-sweep (4 chains) | µs x τ | "
           "µs/chain-sweep (64 chains, multi-spin) | µs x τ |", "|---|---|---|---|---|---|---|"]
    for coupling in (0.3, 0.42):
        theta = np.array([coupling, 0.0])
        x = m.simulate(list(theta), shape=(side, side), seed=side, n_sweeps=300)
        for sampler in ("gibbs", "swendsen_wang"):
            t = m.target("likelihood", x, sampler=sampler)
            tau = float(np.mean([autocorrelation_time(t, theta, seed=s) for s in range(3)]))
            k = kernel_seconds(t, theta) * 1e6
            if sampler == "gibbs":
                rows = np.tile(theta, (64, 1))
                t.simulate_aux(rows, seed=0, n_sweeps=1, kernel="multispin")
                per = [(_timed(lambda: t.simulate_aux(rows, seed=0, n_sweeps=100,  # noqa: B023
                                                      kernel="multispin"))
                        - _timed(lambda: t.simulate_aux(rows, seed=0, n_sweeps=0,  # noqa: B023
                                                        kernel="multispin"))) / 100 / 64
                       for _ in range(5)]
                ms = f"{np.median(per) * 1e6:.1f} | {np.median(per) * 1e6 * tau:.0f}"
            else:
                ms = "- | -"
            out.append(f"| {coupling} | {sampler} | {tau:.1f} | {k:.1f} | {k * tau:.0f} | {ms} |")
            print(out[-1], flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--quick", action="store_true", help="16² only, 200 steps")
    p.add_argument("--steps", type=int, default=1000, help="exchange steps per lattice")
    p.add_argument("--no-write", action="store_true", help="print only")
    p.add_argument("--threads", type=int, default=1, help="numba threads (default 1: the "
                   "kernel's rate and exchange's steps measured alike on a shared machine)")
    p.add_argument("--main-only", action="store_true", help="the first table only (no step "
                   "routes, no cost per unit of mixing)")
    p.add_argument("--title", default="exchange: auxiliary sweeps against overhead "
                   "(bench_exchange)")
    args = p.parse_args(argv)
    import numba

    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    info = machine()
    t0 = time.perf_counter()
    body = rows(args.quick, args.steps)
    if not args.main_only:  # the tree before batching has neither route to compare
        body += step_rows(args.quick) + mixing_rows(args.quick)
    body += ["", f"Suite time: {time.perf_counter() - t0:.0f} s."]
    if not args.no_write:
        append_results(args.title, command_line(argv, "benchmarks.bench_exchange"), info, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
