"""Readings of the thesis's PMC (II) (6.6.2, eq. 6.67 with the importance functions 7.9).

Which reading of 6.6.2 / 6.67 / 7.9 reproduces Table 7.1?
This script is standalone (it does not touch ``mrfpe/``): it rebuilds the
``pmc_convergence`` study's synthetic Ward scenes (same seeds as the committed
run in ``docs/results/pmc_convergence_ward20``) and runs each reading of the
resampling weight ``w`` with the same pieces ``PMC._thesis2_step`` uses
(:func:`mrfpe.samplers.kit.grid`, :func:`~mrfpe.samplers.kit.jitter`,
:func:`mrfpe.resampling.resample`, the target's ``partition(k, "strided")`` and
the softening ``log G^j = l * log ePL_s^j`` of 5.69-5.72).

Every step evaluates *all* ``k`` sub-lattice log-PLs at the new points (one
full-lattice evaluation per particle, since the parts sum to the full PL), so
``G^n`` at the new points, ``G^{n+1}`` at the same points (needed by 6.67 on the
next step) and the full ``ePL_s`` (for pi and every MAP definition) all come
from one evaluation.

Readings (each a pure function of the :class:`State` -> resampling log weights)
-------------------------------------------------------------------------------
``literal``   (today's ``variant="thesis2"``) ``w = c^{n-1} G^n(a^{n-1})`` with
              ``c^{n-1} = 1/G^{n-1}(a^{n-1})`` at the same points:
              ``w = G^n(a^{n-1}) / G^{n-1}(a^{n-1})``. With ``k = 1`` it is
              exactly 1 (no selection).
``compound``  ``c^{n-1}`` is the ``c̄ = 1/N`` that ``resampleParticles``
              returns (5.1.1 step 6), so ``w = G^n(a^{n-1})``: the cloud's
              density compounds ``prod_j G^j`` (an annealing whose power grows
              by ``l/k`` of the full PL per iteration, minus the jitter's
              spreading). ``c^n = 1/G^n(a^n)`` is kept for pi and the variances.
``ancestor``  ``c^{n-1}`` taken where the previous weights were computed, i.e.
              at the *ancestor* (pre-jitter) points:
              ``w_i = G^n(a_i^{n-1}) / G^{n-1}(a_{I_i}^{n-2})``.

Settings: ``power`` l (5.69), ``per_node`` (divide each part's log PL by its
node count before the power: ``log G^j = l * log ePL^j / |S^j|``), ``k``,
``sigma_schedule`` (``"lib"``: ``σ_n = σ0 (1 - n/T)``, n = 0..T-1, as
``PMC._sigma``; ``"zero"``: ``σ0 (1 - n/(T-1))``, reaching 0 at the last
iteration as 6.6's "until finally σ_T = 0"), ``sigma_b`` and ``prior_weight``
of the target (``prior_weight = 0.3`` reads σ = B/5 of 7.4 in pixel widths
instead of label steps).

Per iteration it records the distance to the truth of five MAP definitions
(``bsf_cand``: today's best-so-far under the full PL over one candidate per
iteration, the argmax of G^n, plus all particles at the end; ``bsf_all``:
best-so-far over every particle evaluated; ``it_pi``: 7.4.1 step 6, the
particle of highest ``pi = ePL/G^n`` at that iteration; ``it_pin``: the same
with the PL divided by the node count; ``it_pl``: highest full PL at that
iteration) and the variances of four normalised weight vectors
(``c`` = 1/G^n(a^n), ``w`` = resampling weights, ``pi``, ``pin``) plus
``lib`` (what ``weight_variance`` reports for the library's run: ``c``, and
``pi`` at the last iteration).

Usage::

    NUMBA_NUM_THREADS=1 nice -n 10 python docs/results/pmc_thesis2_readings/readings.py \\
        run --scenes 0-4 --readings literal,compound --powers 1e-2,1e-4 --n 1000

Rows are appended to ``results.jsonl`` (one per scene × reading × setting) as
they finish; rerunning skips rows already present. ``summary`` prints tables.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mrfpe.experiments.pmc_convergence import STUDY
from mrfpe.experiments.problems import child_seeds, make_problem
from mrfpe.resampling import resample
from mrfpe.samplers.kit import grid, jitter, log_ratio
from mrfpe.study import trial_seed

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results.jsonl"
READINGS = ("literal", "compound", "ancestor")
MAPS = ("bsf_cand", "bsf_all", "it_pi", "it_pin", "it_pl")
VARS = ("c", "w", "pi", "pin", "lib")


# --------------------------------------------------------------------------------------
# scenes
# --------------------------------------------------------------------------------------
def scene_seeds(repeat: int) -> tuple[int, int]:
    """(problem seed, run seed) of repetition ``repeat`` of the 20-label Ward column.

    As ``mrfpe.study.tasks`` and ``pmc_convergence.trial``: the trial seed
    ``trial_seed(741, repeat, {"brdf": "ward"})`` (``n_labels`` is a shared-seed
    key) split into the problem's and the runs' seeds.
    """
    cfg = STUDY.config
    seed = trial_seed(cfg["seed"], repeat, {"brdf": "ward"})
    s_problem, s_runs = child_seeds(seed, 2)
    return s_problem, s_runs


def run_seed(s_runs: int, n: int) -> int:
    """The seed ``pmc_convergence.trial`` gives ``thesis2`` with ``n`` particles (other n: hashed).

    With it, the ``literal`` reading at the library's settings replays the
    committed run's random stream (resample, then jitter, per iteration).
    """
    sizes = STUDY.config["n_samples"]
    seeds = child_seeds(s_runs, len(STUDY.config["variants"]) * len(sizes))
    if n in sizes:
        return seeds[sizes.index(n)]
    return int(np.random.SeedSequence([s_runs, n]).generate_state(1)[0])


def make_scene(repeat: int, *, sigma_b: float | str = "auto", prior_weight: float = 1.0,
               dtype: str = "float32"):
    """The study's Ward scene ``repeat`` (100×100, smooth, 20 labels, PL_s of 7.5-7.7).

    ``sigma_b``: "auto" (the library's default), a number, or ``"x<f>"``: ``f``
    times the scene's automatic value.
    """
    cfg = STUDY.config
    s_problem, _ = scene_seeds(repeat)
    opts = {"dtype": dtype}
    if isinstance(sigma_b, str) and sigma_b.startswith("x"):
        import dataclasses

        import mrfpe

        base = make_scene(repeat, prior_weight=prior_weight, dtype=dtype)
        opts = {**opts, "sigma_b": float(sigma_b[1:]) * base.target.sigma_b}
        if prior_weight != 1.0:
            opts["prior_weight"] = float(prior_weight)
        tgt = mrfpe.targets.get(cfg["target"], base.scene, **opts)
        return dataclasses.replace(base, target=tgt,
                                   truth_log_prob=float(tgt.log_prob(base.truth[None])[0]))
    if sigma_b != "auto":
        opts["sigma_b"] = float(sigma_b)
    if prior_weight != 1.0:
        opts["prior_weight"] = float(prior_weight)
    return make_problem("ward", s_problem, surface=cfg["surfaces"]["ward"],
                        shape=cfg["shape"], n_labels=20, noise=cfg["noise"],
                        target=cfg["target"], target_options=opts,
                        truth_range=cfg["truth_range"], maximiser_grid=None)


# --------------------------------------------------------------------------------------
# the sampler: state, readings, one step
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Settings:
    """One PMC (II) configuration (thesis 6.6.2; defaults as ``PMC(variant="thesis2")``)."""

    reading: str = "literal"
    power: float = 0.01
    per_node: bool = False
    k: int = 3
    n: int = 1000
    T: int = 20
    sigma0: float = 0.07
    sigma_schedule: str = "lib"
    resampling: str = "multinomial"

    def sigma(self, it: int) -> float:
        """Jitter σ_n of iteration ``it`` (0-based): 6.6's linear decrease to 0."""
        if self.sigma_schedule == "lib":
            return self.sigma0 * (1.0 - it / self.T)
        if self.sigma_schedule == "zero":
            return self.sigma0 * (1.0 - it / max(1, self.T - 1))
        raise ValueError(self.sigma_schedule)


@dataclass(frozen=True)
class State:
    """PMC (II) state after iteration n-1.

    ``x``: the particles a^{n-1} (N, d); ``lp``: unsoftened sub-lattice log PLs
    ``log ePL_s^j(a^{n-1})`` (N, k) (their row sums are the full log PL);
    ``lg_anc``: ``log G^{n-1}`` at each particle's ancestor (pre-jitter) point,
    the weight that selected it (for the ``ancestor`` reading).
    """

    x: np.ndarray
    lp: np.ndarray
    lg_anc: np.ndarray


def log_g(lp: np.ndarray, j: int, power: float, scale: np.ndarray) -> np.ndarray:
    """``log G^j = l · log ePL_s^j / scale_j`` (7.9 with the softening 5.69-5.72).

    ``scale`` is 1 per part, or the part's node count when the PL is normalised
    per node. ``-inf`` stays ``-inf``.
    """
    return (power / scale[j]) * lp[:, j]


def weights_literal(lg_n_prev: np.ndarray, lg_prev_prev: np.ndarray,
                    lg_anc: np.ndarray) -> np.ndarray:
    """6.67 read literally: ``log w = log c^{n-1} + log G^n(a^{n-1})``.

    ``c^{n-1} = 1/G^{n-1}(a^{n-1})`` (6.6.2 step 2) at the same points.

    Parameters
    ----------
    lg_n_prev : ``log G^n(a^{n-1})``, the new importance function at the current points.
    lg_prev_prev : ``log G^{n-1}(a^{n-1})``, the previous importance function at the same
        points (``-log c^{n-1}``, 6.6.2 step 2).
    lg_anc : unused (signature shared by all readings).

    Notes
    -----
    With one sub-lattice (``k = 1``) ``G^n = G^{n-1}`` and the weight is exactly
    ``-g + g = 0`` in floating point: no selection at all.
    """
    return lg_n_prev + log_ratio(0.0, lg_prev_prev)


def weights_compound(lg_n_prev: np.ndarray, lg_prev_prev: np.ndarray,
                     lg_anc: np.ndarray) -> np.ndarray:
    """6.67 with ``c^{n-1} = c̄ = 1/N`` (the output of resampleParticles, 5.1.1 step 6).

    ``log w = log G^n(a^{n-1})``: resampling multiplies the cloud's density by
    ``G^n``, so after n iterations it is about ``prod_j G^j`` (7.9), smoothed by the jitter.
    """
    return np.asarray(lg_n_prev, dtype=np.float64).copy()


def weights_ancestor(lg_n_prev: np.ndarray, lg_prev_prev: np.ndarray,
                     lg_anc: np.ndarray) -> np.ndarray:
    """6.67 with ``c^{n-1} = 1/G^{n-1}`` at the ancestor (pre-jitter) point.

    ``log w_i = log G^n(a_i^{n-1}) - log G^{n-1}(a_{I_i}^{n-2})``: the c carried
    through resampling from where the weights that selected the particle were
    computed.
    """
    return log_ratio(lg_n_prev, lg_anc)


WEIGHTS = {"literal": weights_literal, "compound": weights_compound,
           "ancestor": weights_ancestor}


def thesis2_step(state: State | None, it: int, s: Settings, scale: np.ndarray,
                 evaluate_parts, rng: np.random.Generator, bounds: np.ndarray):
    """One PMC (II) iteration (6.6.2, n = ``it``) under reading ``s.reading``.

    ``it = 0``: the evenly spaced grid u^0 weighted by ``G^0`` (6.6.2, n = 0,
    step 1), resampled with jitter σ_0. ``it > 0``: the reading's weights
    (:data:`WEIGHTS`, 6.67), resampled with jitter σ_n (``resampleParticles(·, σ_n)``).
    In both cases ``c^n = 1/G^n(a^n)`` (6.6.2 step 2) at the new points.

    Returns
    -------
    (State, dict)
        The new state and ``{"lw": resampling log weights, "lg": log G^n(a^n),
        "lt": full log PL at a^n, "idx": ancestors}``.
    """
    j = it % s.k
    if state is None:
        x = grid(bounds, s.n)
        lp = evaluate_parts(x)
        lw = log_g(lp, j, s.power, scale)
        lg_anc = np.zeros(s.n)
    else:
        x = state.x
        lw = WEIGHTS[s.reading](log_g(state.lp, j, s.power, scale),
                                log_g(state.lp, (it - 1) % s.k, s.power, scale), state.lg_anc)
        lg_anc = log_g(state.lp, j, s.power, scale)  # G^n at the points that get resampled
    idx = resample(lw, s.n, s.resampling, rng)
    a = jitter(x[idx], s.sigma(it), bounds, rng)
    lp_a = evaluate_parts(a)
    new = State(x=a, lp=lp_a, lg_anc=lg_anc[idx])
    return new, {"lw": lw, "lg": log_g(lp_a, j, s.power, scale), "lt": lp_a.sum(axis=1),
                 "idx": idx}


# --------------------------------------------------------------------------------------
# one run with bookkeeping
# --------------------------------------------------------------------------------------
def _var(lw: np.ndarray) -> float:
    """Population variance of the normalised weights ``exp(lw)/Σ`` (Table 7.1's "var")."""
    lw = np.asarray(lw, dtype=np.float64)
    ok = np.isfinite(lw)
    if not ok.any():
        return float("nan")
    w = np.zeros_like(lw)
    w[ok] = np.exp(lw[ok] - lw[ok].max())
    w /= w.sum()
    return float(w.var())


def run_pmc(target, truth: np.ndarray, s: Settings, seed: int) -> dict:
    """Run PMC (II) under ``s``; per-iteration MAP distances and weight variances."""
    rng = np.random.default_rng(seed)
    bounds = np.asarray(target.bounds, dtype=np.float64)
    parts = target.partition(s.k, kind="strided") if s.k > 1 else [target]
    counts = np.array([p._tables.n_nodes for p in parts], dtype=np.float64) \
        if s.k > 1 else np.array([target._tables.n_nodes], dtype=np.float64)
    n_total = float(target._tables.n_nodes)
    scale = counts if s.per_node else np.ones(s.k)

    def evaluate_parts(x):
        out = np.stack([np.asarray(p.log_prob(x), dtype=np.float64) for p in parts], axis=1)
        return np.where(np.isnan(out), -np.inf, out)

    dist = {m: [] for m in MAPS}
    var = {v: [] for v in VARS}
    best = {"bsf_cand": (-np.inf, None), "bsf_all": (-np.inf, None)}
    state = None
    t0 = time.perf_counter()
    for it in range(s.T):
        state, info = thesis2_step(state, it, s, scale, evaluate_parts, rng, bounds)
        x, lt, lg = state.x, info["lt"], info["lg"]
        last = it == s.T - 1
        # best-so-far over every evaluated particle
        i = int(np.argmax(lt))
        if lt[i] > best["bsf_all"][0]:
            best["bsf_all"] = (float(lt[i]), x[i].copy())
        # today's: one candidate (argmax G^n) per iteration, every particle at the end
        cand = np.arange(x.shape[0]) if last else [int(np.argmax(lg))]
        ic = cand[int(np.argmax(lt[cand]))]
        if lt[ic] > best["bsf_cand"][0]:
            best["bsf_cand"] = (float(lt[ic]), x[ic].copy())
        lpi = log_ratio(lt, lg)                 # pi^n = ePL_s(a^n) / G^n(a^n) (6.6.2 step 5)
        lpin = log_ratio(lt / n_total, lg)      # the same with log PL per node
        lc = log_ratio(0.0, lg)                 # c^n = 1/G^n(a^n)
        for m, v in (("bsf_cand", best["bsf_cand"][1]), ("bsf_all", best["bsf_all"][1]),
                     ("it_pi", x[int(np.argmax(lpi))]), ("it_pin", x[int(np.argmax(lpin))]),
                     ("it_pl", x[i])):
            dist[m].append(float(np.linalg.norm(v - truth)))
        var["c"].append(_var(lc))
        var["w"].append(_var(info["lw"]))
        var["pi"].append(_var(lpi))
        var["pin"].append(_var(lpin))
        var["lib"].append(_var(lpi if last else lc))
    return {"dist": dist, "var": var, "final_map": best["bsf_cand"][1].tolist(),
            "final_lt": best["bsf_cand"][0], "wall_s": time.perf_counter() - t0}


# --------------------------------------------------------------------------------------
# CLI: run (resumable JSONL) and summary
# --------------------------------------------------------------------------------------
def _key(row: dict) -> str:
    fields = {k: row[k] for k in ("scene", "settings", "sigma_b", "prior_weight", "dtype")}
    return hashlib.sha1(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]


def _done(path: Path) -> set:
    if not path.exists():
        return set()
    keys = set()
    for line in path.read_text().splitlines():
        if line.strip():
            keys.add(json.loads(line)["key"])
    return keys


def _ints(spec: str) -> list[int]:
    out: list[int] = []
    for part in spec.split(","):
        if "-" in part:
            a, b = part.split("-")
            out += list(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def cmd_run(args) -> None:
    out = Path(args.out)
    done = _done(out)
    readings = args.readings.split(",")
    powers = [float(p) for p in args.powers.split(",")]
    ns = [int(n) for n in args.n.split(",")]
    base = Settings(k=args.k, T=args.T, sigma_schedule=args.sigma_schedule,
                    per_node=args.per_node)
    for scene in _ints(args.scenes):
        prob = None
        _, s_runs = scene_seeds(scene)
        for n in ns:
            for reading in readings:
                for power in powers:
                    s = replace(base, reading=reading, power=power, n=n)
                    row = {"scene": scene, "settings": s.__dict__, "sigma_b": args.sigma_b,
                           "prior_weight": args.prior_weight, "dtype": args.dtype}
                    row["key"] = _key(row)
                    if row["key"] in done:
                        continue
                    if prob is None:
                        prob = make_scene(scene, sigma_b=args.sigma_b,
                                          prior_weight=args.prior_weight, dtype=args.dtype)
                    seed = run_seed(s_runs, n)
                    res = run_pmc(prob.target, prob.truth, s, seed)
                    row.update(res, truth=prob.truth.tolist(), truth_lt=prob.truth_log_prob,
                               seed=seed)
                    with out.open("a") as fh:
                        fh.write(json.dumps(row) + "\n")
                    d = res["dist"]["bsf_cand"]
                    print(f"scene {scene} N={n} {reading} l={power:g} pn={s.per_node} "
                          f"sched={s.sigma_schedule}: {d[0]:.3f} -> {d[4]:.3f} -> {d[-1]:.3f} "
                          f"var_lib1={res['var']['lib'][0]:.3g} ({res['wall_s']:.1f}s)",
                          flush=True)


def load(path: Path = RESULTS) -> list[dict]:
    """All rows of ``results.jsonl``."""
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def group_rows(rows: list[dict]) -> dict:
    """Rows grouped by setting (everything but the scene)."""
    groups: dict = {}
    for r in rows:
        s = dict(r["settings"])
        key = (s["reading"], s["power"], s["per_node"], s["k"], s["n"], s["sigma_schedule"],
               str(r["sigma_b"]), r["prior_weight"])
        groups.setdefault(key, []).append(r)
    return groups


def cmd_summary(args) -> None:
    rows = load(Path(args.out))
    its = [0, 4, 9, 19]
    print("| reading | l | per_node | k | N | sched | σ_b | prior_w | MAP | scenes | "
          + " | ".join(f"it {i + 1}" for i in its)
          + " | fall % | var c it1 ×1e6 | var lib it20 ×1e6 |")
    print("|" + "---|" * (15 + len(its) - 4 + 3))
    for key, g in sorted(group_rows(rows).items(), key=lambda kv: tuple(map(str, kv[0]))):
        for m in args.maps.split(","):
            d = np.array([r["dist"][m] for r in g])
            mu, sd = d.mean(0), d.std(0, ddof=1) if len(g) > 1 else np.zeros(d.shape[1])
            fall = 100 * (1 - mu[-1] / mu[0])
            vc = np.mean([r["var"]["c"][0] for r in g]) * 1e6
            vl = np.mean([r["var"]["lib"][-1] for r in g]) * 1e6
            cells = " | ".join(f"{mu[i]:.3f}±{sd[i]:.3f}" for i in its)
            print(f"| {' | '.join(map(str, key))} | {m} | {len(g)} | {cells} | {fall:.0f} | "
                  f"{vc:.3g} | {vl:.3g} |")


def _label(key) -> str:
    reading, power, per_node, k, _n, sched, sigma_b, pw = key
    lab = f"{reading} l={power:g}" + (" /node" if per_node else "")
    extra = [f"k={k}"] if k != 3 else []
    extra += [f"σ:{sched}"] if sched != "lib" else []
    extra += [f"σ_b={sigma_b}"] if sigma_b != "auto" else []
    extra += [f"prior_w={pw:g}"] if pw != 1.0 else []
    return lab + (f" ({', '.join(extra)})" if extra else "")


def tables(rows: list[dict], maps=("bsf_cand", "it_pi"), min_scenes: int = 1,
           scenes: set | None = None) -> str:
    """Markdown tables: MAP distance (mean ± sd over scenes) and weight variances.

    Beside Table 7.1 (20 labels, Ward, PMC (II), 100 runs): the thesis's MAP
    distance and "var" columns (``mrfpe.experiments._thesis.PMC_TABLES``).
    """
    from mrfpe.experiments._thesis import PMC_TABLES

    its = [0, 4, 9, 19]
    out = []
    groups = group_rows([r for r in rows if scenes is None or r["scene"] in scenes])
    for n in sorted({k[4] for k in groups}, reverse=True):
        d_ref, v_ref = PMC_TABLES[("ward", 20, n)]
        head = ("| setting | MAP | scenes | " + " | ".join(f"it {i + 1}" for i in its)
                + " | fall % | d1 − d20 ± se (improved) | MAP ≥ truth PL | time s |")
        lines = [f"**N = {n}**, MAP distance to the truth, mean ± sd over scenes", "", head,
                 "|" + "---|" * (len(its) + 7),
                 "| thesis Table 7.1 | highest π | 100 | "
                 + " | ".join(f"{d_ref[i]:.3f}" for i in its)
                 + f" | {100 * (1 - d_ref[19] / d_ref[0]):.0f} | | | |"]
        vlines = ["", f"**N = {n}**, variance of the normalised weights × 10⁶ (mean over "
                  "scenes): *c* = 1/G^n(a^n) (what the library records), *pin* = π with the "
                  "PL per node, at iterations 1, 2, 5, 10, 20", "",
                  "| setting | scenes | c: it 1 | 2 | 5 | 10 | 20 | pin: it 1 | 20 | "
                  "π (unnormalised PL) it 20 |", "|" + "---|" * 10,
                  "| thesis Table 7.1 | 100 | "
                  + " | ".join(f"{v_ref[i]:.4g}" for i in (0, 1, 4, 9, 19)) + " | | | |"]
        for key, g in sorted(groups.items(), key=lambda kv: _label(kv[0])):
            if key[4] != n or len(g) < min_scenes:
                continue
            for m in maps:
                d = np.array([r["dist"][m] for r in g])
                mu = d.mean(0)
                sd = d.std(0, ddof=1) if len(g) > 1 else np.zeros(d.shape[1])
                ok = np.mean([r["final_lt"] >= r["truth_lt"] - 1e-6 for r in g])
                wall = np.mean([r["wall_s"] for r in g])
                fall = d[:, 0] - d[:, -1]
                se = fall.std(ddof=1) / np.sqrt(len(g)) if len(g) > 1 else 0.0
                lines.append(f"| {_label(key)} | {m} | {len(g)} | "
                             + " | ".join(f"{mu[i]:.3f} ± {sd[i]:.3f}" for i in its)
                             + f" | {100 * (1 - mu[-1] / mu[0]):.0f} | {fall.mean():.3f} ± "
                             f"{se:.3f} ({int(np.sum(fall > 1e-12))}/{len(g)}) | "
                             f"{100 * ok:.0f} % | "
                             f"{wall:.0f} |")
            vc = np.array([r["var"]["c"] for r in g]).mean(0) * 1e6
            vp = np.array([r["var"]["pin"] for r in g]).mean(0) * 1e6
            vpi = np.mean([r["var"]["pi"][-1] for r in g]) * 1e6
            vlines.append(f"| {_label(key)} | {len(g)} | "
                          + " | ".join(f"{vc[i]:.3g}" for i in (0, 1, 4, 9, 19))
                          + f" | {vp[0]:.3g} | {vp[-1]:.3g} | {vpi:.3g} |")
        out.append("\n".join(lines + vlines))
    return "\n\n".join(out) + "\n"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--scenes", default="0-4")
    r.add_argument("--readings", default="literal,compound")
    r.add_argument("--powers", default="0.01,1e-4")
    r.add_argument("--n", default="1000")
    r.add_argument("--k", type=int, default=3)
    r.add_argument("--T", type=int, default=20)
    r.add_argument("--per-node", action="store_true")
    r.add_argument("--sigma-schedule", default="lib", choices=("lib", "zero"))
    r.add_argument("--sigma-b", default="auto")
    r.add_argument("--prior-weight", type=float, default=1.0)
    r.add_argument("--dtype", default="float32")
    r.add_argument("--out", default=str(RESULTS))
    s = sub.add_parser("summary")
    s.add_argument("--out", default=str(RESULTS))
    s.add_argument("--maps", default="bsf_cand")
    t = sub.add_parser("tables", help="markdown tables (tables.md)")
    t.add_argument("--out", default=str(RESULTS))
    t.add_argument("--maps", default="bsf_cand,it_pi")
    t.add_argument("--min-scenes", type=int, default=1)
    t.add_argument("--scenes", default=None)
    args = p.parse_args(argv)
    if args.cmd == "run":
        if args.sigma_b != "auto" and not args.sigma_b.startswith("x"):
            args.sigma_b = float(args.sigma_b)
        cmd_run(args)
    elif args.cmd == "tables":
        sc = set(_ints(args.scenes)) if args.scenes else None
        print(tables(load(Path(args.out)), tuple(args.maps.split(",")), args.min_scenes, sc))
    else:
        cmd_summary(args)


if __name__ == "__main__":
    main(sys.argv[1:])
