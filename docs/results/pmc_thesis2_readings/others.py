"""The other thesis samplers on the same scenes: PMC (I), SIR alternative, PPF, R/Q-type DW.

A brief check: do PMC (I) (6.6.1, 6.66), the alternative
SIR (5.2.2, 5.29-5.31), PPF (5.3, 5.32-5.35) and R/Q-type dynamically weighted
MCMC (5.48, 5.49) with the literal initial weight Π₀ = ϱ(θ₀) (7.13,
``initial_weight="absolute"``) behave as the thesis reports? Library samplers
at their thesis settings, on the ``pmc_convergence`` Ward scenes of
``readings.py``. One JSON row per (scene, sampler) in ``others.jsonl``.

Usage::

    NUMBA_NUM_THREADS=1 nice -n 10 python docs/results/pmc_thesis2_readings/others.py 0-2
    python docs/results/pmc_thesis2_readings/others.py summary   # the markdown table
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np

import mrfpe

HERE = Path(__file__).resolve().parent
OUT = HERE / "others.jsonl"

SAMPLERS = {
    # the cell-centred grid the rows ran with (the thesis variants' default until 2026-12-02)
    "pmc_thesis1": ("pmc", {"n_samples": 1000, "n_iterations": 20, "variant": "thesis1",
                            "initial": "grid", "keep_history": True}),
    # the thesis's weights, pinned: the library's defaults became "mixture" after the first
    # three scenes were run (those rows were made with "thesis", then the default)
    # (and the cell centres, which SIR and PPF always started from until 2026-12-03)
    "sir_alternative": ("sir", {"n_samples": 1000, "n_iterations": 20,
                                "variant": "alternative", "weights": "thesis",
                                "initial": "grid", "keep_history": True}),
    "ppf": ("ppf", {"n_samples": 1000, "n_partitions": 20, "k": 3, "weights": "thesis",
                    "initial": "grid", "keep_history": True}),
    "dw_r_absolute": ("dw_r", {"n_steps": 20000, "initial_weight": "absolute"}),
    "dw_q_absolute": ("dw_q", {"n_steps": 20000, "initial_weight": "absolute"}),
    "dw_r_relative": ("dw_r", {"n_steps": 20000, "initial_weight": "relative"}),
    # the literal Π₀ on the PL divided by the node count (log ϱ / |S|, via the softening)
    "dw_r_absolute_per_node": ("dw_r", {"n_steps": 20000, "initial_weight": "absolute"}),
    "dw_q_absolute_per_node": ("dw_q", {"n_steps": 20000, "initial_weight": "absolute"}),
}
# the same three from the grid from face to face, their thesis weights' default since
# 2026-12-02 (PMC) and 2026-12-03 (SIR, PPF)
SAMPLERS.update({f"{label}_faces": (SAMPLERS[label][0],
                                    {**SAMPLERS[label][1], "initial": "grid_faces"})
                 for label in ("pmc_thesis1", "sir_alternative", "ppf")})


def _readings():
    spec = importlib.util.spec_from_file_location("readings", HERE / "readings.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str]) -> None:
    """Run every sampler of :data:`SAMPLERS` on the scenes ``argv[0]`` (e.g. ``0-2``)."""
    R = _readings()
    scenes = R._ints(argv[0] if argv else "0-2")
    names = argv[1].split(",") if len(argv) > 1 else list(SAMPLERS)
    done = set()
    if OUT.exists():
        done = {(r["scene"], r["sampler"]) for r in map(json.loads, OUT.read_text().splitlines())}
    for scene in scenes:
        prob = None
        _, s_runs = R.scene_seeds(scene)
        for label in names:
            if (scene, label) in done:
                continue
            prob = prob or R.make_scene(scene)
            name, cfg = SAMPLERS[label]
            target = prob.target
            if label.endswith("_per_node"):
                from mrfpe.targets.softening import softened

                target = softened(target, 1.0 / target._tables.n_nodes)
            t0 = time.perf_counter()
            post = mrfpe.sample(name, target, seed=int(s_runs % 2**31), **cfg)
            mt = post["map_theta"].values
            d = np.linalg.norm(mt - prob.truth, axis=1)
            row = {"scene": scene, "sampler": label, "config": cfg,
                   "map_dist": d.tolist() if d.size <= 100 else [*d[::1000].tolist(), d[-1]],
                   "ess": post["ess"].values.tolist() if post["ess"].size <= 100 else None,
                   "final_map_lt": float(post["map_log_target"].values[-1]),
                   "truth_lt": prob.truth_log_prob, "wall_s": time.perf_counter() - t0}
            if "history_log_weight" in post:
                row["weight_var"] = np.exp(post["history_log_weight"].values).var(axis=1).tolist()
            if "acceptance" in post:
                row["acceptance_mean"] = float(np.mean(post["acceptance"].values))
            if "log_weight" in post:
                lw = post["log_weight"].values
                row["log_weight_range"] = [float(np.min(lw)), float(np.max(lw))]
            with OUT.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(scene, label, f"{d[0]:.3f} -> {d[len(d) // 4]:.3f} -> {d[-1]:.3f}",
                  f"({row['wall_s']:.0f}s)", flush=True)


def _ms(x: np.ndarray) -> str:
    return f"{np.mean(x):.3f} ± {np.std(x, ddof=1) if x.size > 1 else 0:.3f}"


def summary() -> str:
    """One markdown row per sampler of ``others.jsonl``: mean ± sd over its scenes.

    MAP distance (best-so-far, to the truth) at the first iteration/step, a quarter
    of the way (iteration 6 of 20, step 5000 of 20000) and the end; how many scenes end
    within 0.15; the final MAP's log-PL minus the truth's (median and range, nats: ≥ 0
    where the sampler found the PL's peak region, which lies off the truth; not for the
    per-node rows, whose target is rescaled); the ESS and
    the acceptance where the sampler has them; the median wall time.
    """
    rows = [json.loads(line) for line in OUT.read_text().splitlines()]
    order = list(dict.fromkeys(r["sampler"] for r in rows))
    out = ["| sampler | scenes | first | ¼ | end | end ≤ 0.15 | MAP log-PL − truth's "
           "| ESS first → last (median) | acceptance | wall (median) |", "|" + "---|" * 10]
    for name in order:
        rs = sorted((r for r in rows if r["sampler"] == name), key=lambda r: r["scene"])
        d = np.array([r["map_dist"] for r in rs])
        q = d.shape[1] // 4
        gap = np.array([r["final_map_lt"] - r["truth_lt"] for r in rs])
        reach = ("—" if name.endswith("_per_node") else
                 f"{np.median(gap):+.1f} [{gap.min():+.0f}, {gap.max():+.0f}]")
        ess = [r["ess"] for r in rs if r.get("ess")]
        ess_s = (f"{np.median([e[0] for e in ess]):.1f} → {np.median([e[-1] for e in ess]):.1f}"
                 if ess else "—")
        acc = [r["acceptance_mean"] for r in rs if "acceptance_mean" in r]
        acc_s = f"{np.mean(acc):.3f} [{min(acc):.3f}–{max(acc):.3f}]" if acc else "—"
        out.append(f"| {name} | {len(rs)} | {_ms(d[:, 0])} | {_ms(d[:, q])} | {_ms(d[:, -1])} | "
                   f"{int(np.sum(d[:, -1] <= 0.15))}/{len(rs)} | {reach} | {ess_s} | {acc_s} | "
                   f"{np.median([r['wall_s'] for r in rs]):.0f} s |")
    return "\n".join(out)


if __name__ == "__main__":
    if sys.argv[1:2] == ["summary"]:
        print(summary())
    else:
        main(sys.argv[1:])
