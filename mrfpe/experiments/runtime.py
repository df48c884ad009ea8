"""Running time of every sampler at 10-40 labels, beside the thesis's Table 8.12.

Table 8.12 gives approximate times on an AMD Athlon 4600 for a 100×100 image:
multiple-seed LM (512 seeds, 10 iterations) 1.3-5 h, R-type MCMC (20000
steps) 9-36 min, PMC (1000 samples, 20 iterations) 4-16 min, growing linearly
with the number of labels (8.3). Each trial here builds one synthetic Ward
scene (smooth surface, 7.2), its PL_s target (7.7) and the target's global
maximiser, then runs every configured sampler on it in turn (``runs``: a label
for each run, its sampler and that sampler's settings; the defaults are the
thesis's where it gives them). For each run it records the wall time, the
target evaluations (full-lattice equivalents) and the evaluations after which
the best-so-far MAP first comes within ``level`` (0.1) of the truth and of the
maximiser.

Timings are only meaningful when nothing else competes for the cores: run
this study in-process (no ``--scheduler``) on an otherwise idle machine.

Full run: about 1.9 h on two cores, one trial per core (measured 2026-12-02;
3.6 core-hours). That is 12 scenes (4 label counts × 3) × all ten
runs; per 20-label Ward scene most of the time goes to the single-point
samplers: ``nlopt_multiseed`` (512 seeds × up to 500 evaluations at ~0.65 ms),
the two 20000-step chains (~15 s each) and 512-seed LM run to convergence
(4-8 min).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments._thesis import RUNTIME_MINUTES
from mrfpe.experiments.problems import (
    SURFACES,
    check_runs,
    check_target_options,
    child_seeds,
    distance,
    first_reach,
    make_problem,
    maximiser,
    positive,
    sample_traced,
    settings,
)
from mrfpe.experiments.writeup import markdown_table, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study, by_cell


def _brdf_names() -> tuple[str, ...]:
    import mrfpe.brdf

    return mrfpe.brdf.names()

#: Which run is compared with which column of Table 8.12.
THESIS_COLUMN = {"pmc_thesis2": "pmc", "pmc": "pmc", "dw_r": "dw_r",
                 "lm_multiseed": "lm_multiseed"}


#: The thesis's runs (Table 8.12 settings where it gives them).
RUNS = {
    "pmc": {"sampler": "pmc", "n_samples": 1000, "n_iterations": 20},
    "pmc_thesis2": {"sampler": "pmc", "n_samples": 1000, "n_iterations": 20,
                    "variant": "thesis2"},
    "dw_r": {"sampler": "dw_r", "n_steps": 20000},
    "dw_q": {"sampler": "dw_q", "n_steps": 20000},
    # each seed to convergence: the reading of Table 8.12's "10 iterations" that reproduces
    # the thesis's LM results (mrfpe.experiments.lm_multiseed)
    "lm_multiseed": {"sampler": "lm_multiseed", "n_seeds": 512},
    "nlopt_multiseed": {"sampler": "nlopt_multiseed", "n_seeds": 512},
    "mh": {"sampler": "mh"},
    "emcee": {"sampler": "emcee"},
    "sir": {"sampler": "sir"},
    "ppf": {"sampler": "ppf"},
}


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One scene; every run in ``config["runs"]``; times and evaluations to reach ``level``."""
    s_problem, s_runs = child_seeds(seed, 2)
    t0 = time.perf_counter()
    prob = make_problem(config["brdf"], s_problem, surface=config["surface"],
                        shape=config["shape"], n_labels=config["n_labels"],
                        noise=config["noise"], target=config["target"],
                        target_options=config["target_options"],
                        truth_range=config["truth_range"], maximiser_grid=None)
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    mx, _ = maximiser(prob.target, config["maximiser_grid"], s_problem, prob.truth)
    max_s = time.perf_counter() - t0
    labels = list(config["runs"])
    out = {k: np.full(len(labels), np.nan) for k in
           ("wall_time_s", "n_target_evals", "evals_to_truth", "evals_to_maximiser",
            "final_to_truth", "final_to_maximiser")}
    for k, (label, run_seed) in enumerate(zip(labels, child_seeds(s_runs, len(labels)))):
        opts = dict(config["runs"][label])
        name = opts.pop("sampler")
        post, evals = sample_traced(name, prob.target, run_seed, **opts)
        m = post["map_theta"].values
        d_truth, d_max = distance(m, prob.truth), distance(m, mx)
        out["wall_time_s"][k] = post.attrs["wall_time_s"]
        out["n_target_evals"][k] = post.attrs["n_target_evals"]
        out["evals_to_truth"][k] = first_reach(d_truth, evals, config["level"])
        out["evals_to_maximiser"][k] = first_reach(d_max, evals, config["level"])
        out["final_to_truth"][k], out["final_to_maximiser"][k] = d_truth[-1], d_max[-1]
    ds = xr.Dataset({k: (("run",), v) for k, v in out.items()},
                    coords={"run": labels, "param": list(prob.target.param_names)})
    ds["build_time_s"] = ((), build_s)
    ds["maximiser_time_s"] = ((), max_s)
    ds["maximiser"] = (("param",), np.asarray(mx, dtype=float))
    ds["truth"] = (("param",), prob.truth)
    return ds


def _unit(seconds: float) -> tuple[float, str]:
    """Seconds below two minutes, minutes above."""
    return (1.0, "s") if seconds < 120 else (60.0, "min")


def _minutes(seconds: float) -> str:
    scale, unit = _unit(seconds)
    return f"{seconds / scale:.3g} {unit}"


def _with_range(values: np.ndarray) -> str:
    """The mean time, and with more than one scene the range over scenes in the mean's unit."""
    mean = float(np.mean(values))
    if values.size < 2:
        return _minutes(mean)
    scale, _ = _unit(mean)
    return f"{_minutes(mean)} ({values.min() / scale:.3g}–{values.max() / scale:.3g})"


def _thesis_minutes(run: str, labels: int) -> float | None:
    """Table 8.12's time for the thesis column this run compares with, or None."""
    return RUNTIME_MINUTES.get(THESIS_COLUMN.get(run, ""), {}).get(labels)


#: Table 8.12's argument: LM costs about 20× PMC. Our ratio per scene, for these pairs.
RATIOS = (("lm_multiseed", "pmc_thesis2"), ("lm_multiseed", "pmc"), ("dw_r", "pmc_thesis2"))


def ratio_table(cells: dict[tuple, list[xr.Dataset]], runs: list[str],
                thesis_size: bool) -> str:
    """Per-scene time ratios (mean and range) beside the thesis's ratio of its columns."""
    rows = []
    for num, den in RATIOS:
        if num not in runs or den not in runs:
            continue
        for (lab,), group in cells.items():
            r = np.array([float(g["wall_time_s"].sel(run=num) / g["wall_time_s"].sel(run=den))
                          for g in group])
            ref_num, ref_den = _thesis_minutes(num, lab), _thesis_minutes(den, lab)
            ref = (f"{ref_num / ref_den:.3g}×" if thesis_size and ref_num and ref_den
                   else "–")
            spread = f" ({r.min():.3g}–{r.max():.3g})" if r.size > 1 else ""
            rows.append([f"{num} ÷ {den}", lab, len(group), f"{r.mean():.3g}×{spread}", ref])
    return markdown_table(["ratio", "labels", "scenes", "ours (range over scenes)",
                           "thesis"], rows)


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """Table 8.12 layout (ours beside the thesis), evaluations to reach the level, a figure."""
    cells = by_cell(results, "n_labels")
    labels_list = [lab for (lab,) in cells]
    runs = list(config["runs"])
    means = {lab: xr.concat(g, dim="trial").mean("trial") for (lab,), g in cells.items()}
    # The thesis's times are for 100×100 images: compare only like with like.
    thesis_size = list(config["shape"]) == [100, 100]
    rows = []
    for run in runs:
        for lab in labels_list:
            m = means[lab].sel(run=run)
            ref = _thesis_minutes(run, lab) if thesis_size else None
            walls = np.array([float(g["wall_time_s"].sel(run=run)) for g in cells[(lab,)]])
            wall = float(walls.mean())
            reached = sum(bool(np.isfinite(g["evals_to_truth"].sel(run=run)))
                          for g in cells[(lab,)])
            rows.append([run, lab, _with_range(walls), "–" if ref is None else f"{ref:g} min",
                         "–" if ref is None else f"{ref * 60 / wall:.0f}×",
                         float(m["n_target_evals"]), f"{reached}/{len(cells[(lab,)])}",
                         float(m["evals_to_truth"]), float(m["evals_to_maximiser"]),
                         float(m["final_to_truth"]), float(m["final_to_maximiser"])])
    level = config["level"]
    table = markdown_table(["run", "labels", "ours", "thesis (Athlon 4600)", "speed-up",
                            "target evals", "reached", f"evals to {level} of truth",
                            f"evals to {level} of max", "final→truth", "final→max"], rows)
    setup = markdown_table(
        ["labels", "scenes", "scene + target build", "maximiser"],
        [[lab, len(cells[(lab,)]), _minutes(float(means[lab]["build_time_s"])),
          _minutes(float(means[lab]["maximiser_time_s"]))] for lab in labels_list])
    fig, axes = new_figure(1, 1, size=(6, 4))
    ax = axes[0, 0]
    for k, run in enumerate(runs):
        ax.plot(labels_list, [float(means[lab]["wall_time_s"].sel(run=run))
                              for lab in labels_list], "o-", color=f"C{k % 10}", label=run)
        ref = RUNTIME_MINUTES.get(THESIS_COLUMN.get(run, ""))
        if ref and run != "pmc" and thesis_size:
            ax.plot(labels_list, [ref.get(lab, np.nan) * 60 for lab in labels_list], "x:",
                    color=f"C{k % 10}", label=f"{run} (thesis)")
    ax.set(xlabel="labels per node", ylabel="wall time (s)", yscale="log",
           title="Running time per run (Table 8.12)")
    ax.legend(fontsize=6, ncol=2)
    png = save_figure(fig, out_dir / "runtime.png")
    write_report(out_dir, "Running times (thesis Table 8.12)", [
        f"Config: `{json.dumps(config)}`.",
        "Mean over scenes (*ours*: the wall time, with its range over scenes). *target "
        "evals*: full-lattice-equivalent evaluations; *evals to "
        f"{level}*: evaluations after which the best-so-far MAP first lies within {level} "
        "(unit cube) of the truth / of the target's global maximiser (mean over the scenes "
        "where it does; *reached*: in how many scenes it does). The thesis's times are for "
        "its PMC (II), R-type MCMC and 512-seed LM on 100×100 images; `pmc` (mixture) is "
        "compared with the same column.",
        table, "Time ratios per scene (Table 8.12's argument: LM costs about 20× PMC):\n\n"
        + ratio_table(cells, runs, thesis_size),
        "Set-up per scene:\n\n" + setup, f"![runtime]({png})"])
    return table


STUDY = Study(
    name="runtime",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 3, "seed": 812},
    settings=[
        *settings("n_labels", "shape", "noise", "target", "target_options", "truth_range",
                  "maximiser_grid"),
        Setting("brdf", "ward", "reflectance model of every scene", choices=_brdf_names),
        Setting("surface", "smooth", "surface type of every scene", choices=SURFACES),
        Setting("level", 0.1, "distance (unit cube) a MAP must come within to count as reached",
                check=positive),
        Setting("runs", RUNS, "sampler runs per scene, {label: {\"sampler\": NAME, option: "
                "value}}", check=check_runs),
    ],
    check=check_target_options,
    quick={
        "n_trials": 1, "n_labels": [10, 20], "shape": [12, 12], "maximiser_grid": 8,
        "runs": {
            "pmc": {"sampler": "pmc", "n_samples": 64, "n_iterations": 5},
            "pmc_thesis2": {"sampler": "pmc", "n_samples": 64, "n_iterations": 5,
                            "variant": "thesis2"},
            "dw_r": {"sampler": "dw_r", "n_steps": 300},
            "dw_q": {"sampler": "dw_q", "n_steps": 300},
            "lm_multiseed": {"sampler": "lm_multiseed", "n_seeds": 8, "max_iterations": 10},
            "nlopt_multiseed": {"sampler": "nlopt_multiseed", "n_seeds": 8, "max_evals": 40},
            "mh": {"sampler": "mh", "n_steps": 100, "n_chains": 4, "burn_in": 20},
            "emcee": {"sampler": "emcee", "n_walkers": 8, "n_steps": 40, "burn_in": 10},
            "sir": {"sampler": "sir", "n_samples": 64, "n_iterations": 5},
            "ppf": {"sampler": "ppf", "n_samples": 64, "n_partitions": 5},
        },
    },
    trial=trial,
    summarise=summarise,
    grid=("n_labels",),
    shared_seed=("n_labels",),
)
