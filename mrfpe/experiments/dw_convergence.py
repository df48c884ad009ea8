"""Dynamically weighted MCMC (Q- and R-type): mean MAP distance against step (Figs. 7.7-7.14).

The thesis's protocol (7.4): for each of N = 100 random synthetic scenes and
true parameters b^n, run the Q-type and the R-type dynamically weighted
sampler (5.47-5.49; θ = 1, Gaussian proposal σ = 0.05, initial point uniform
in the unit cube) for 20000 steps on PL_s (7.7), keep the best-so-far sample
θ_max at every step, and plot d_i = mean_n ‖b^n − θ^n_{i,max}‖ against i
(Figs. 7.7-7.10), and single runs (Figs. 7.11-7.14). The thesis reads the curves
at 700 and 1300 steps against PMC with 64 and 125 particles (equal cost).

What we add: the same curve for the distance to the target's global
maximiser. Both samplers run on the same scene in one trial; the trace is kept
at steps 1-10 and then every ``record_stride`` steps.

Full run: about 14 h on two cores (one process per core), in float32 (the
default, as in ``pmc_convergence``: ``log_prob`` within 2e-6 relative, a few
1e-2 nats at these lattices' values, far below the acceptance ratios' scale).
That is 800 scenes (2 models × 4 label counts × 100) × 2 samplers × 20000
single-point evaluations at 100×100 pixels plus a maximiser per scene; measured
on a 2-core AMD EPYC (Zen 4, Dec 2026) with the nodes-as-SIMD small-batch
kernel, one scene per core beside another study on the other core (medians of
the committed trials): 31 s per 10-label Ward scene, 68 s per 20-label one;
Phong's cost 2.5× Ward's (76 s at 10 labels) before the kernel left isotropic
Phong's unused second-exponent rows unread (0.66× the time per evaluation; same
numbers). One evaluation reads the whole table (13 MB for Ward at 20 labels), so
a step is bound by memory; running the two samplers in lockstep threads, their
points in one call, was slower (``docs/design-changes.md``). Time grows about
linearly with the labels: about 27 core-hours in all. ``--trials 10`` gives usable
curves in about an hour and a half.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments.problems import (
    DEFAULTS,
    QUICK,
    check_problem,
    check_sampler_options,
    child_seeds,
    distance,
    positive,
    problem_from_config,
    sample_traced,
    sampler_names,
    settings,
)
from mrfpe.experiments.writeup import markdown_table, mean_sd, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study, by_cell

#: The steps at which the report's table reads the curves (700 ≈ PMC 64 × 20 /
#: sub-lattice cost, 1300 ≈ PMC 125 × 20 / ..., as compared in 7.4.2).
TABLE_STEPS = (100, 700, 1300, 5000, 10000, 20000)
FIGURES = {("dw_r", "phong"): ("7.7", "7.11"), ("dw_r", "ward"): ("7.8", "7.12"),
           ("dw_q", "phong"): ("7.9", "7.13"), ("dw_q", "ward"): ("7.10", "7.14")}


def recorded_steps(n_steps: int, stride: int) -> np.ndarray:
    """1-based steps kept in the trial file: 1..10, then every ``stride``-th, and the last."""
    return np.unique(np.r_[np.arange(1, min(10, n_steps) + 1),
                           np.arange(stride, n_steps + 1, stride), n_steps])


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One scene; every sampler for ``n_steps``; MAP distance traces."""
    samplers = config["samplers"]
    s_problem, s_runs = child_seeds(seed, 2)
    prob = problem_from_config(config, s_problem)
    steps = recorded_steps(config["n_steps"], config["record_stride"])
    to_truth = np.empty((len(samplers), steps.size))
    to_max = np.empty((len(samplers), steps.size))
    evals = np.empty((len(samplers), steps.size))
    wall = np.empty(len(samplers))
    final_lt = np.empty(len(samplers))
    for k, (name, run_seed) in enumerate(zip(samplers, child_seeds(s_runs, len(samplers)))):
        post, ev = sample_traced(name, prob.target, run_seed, n_steps=config["n_steps"],
                                 **config["sampler_options"])
        m = post["map_theta"].values[steps - 1]
        to_truth[k] = distance(m, prob.truth)
        to_max[k] = distance(m, prob.maximiser)
        evals[k] = ev[steps - 1]
        wall[k] = post.attrs["wall_time_s"]
        final_lt[k] = post["map_log_target"].values[-1]
    ds = xr.Dataset(
        {"map_to_truth": (("sampler", "step"), to_truth.astype(np.float32)),
         "map_to_maximiser": (("sampler", "step"), to_max.astype(np.float32)),
         "n_target_evals": (("sampler", "step"), evals),
         "final_log_target": (("sampler",), final_lt),
         "wall_time_s": (("sampler",), wall)},
        coords={"sampler": samplers, "step": steps, "param": list(prob.target.param_names)})
    return ds.merge(prob.dataset())


def table(results: list[xr.Dataset], config: dict) -> str:
    """Mean distances to the truth and to the maximiser at :data:`TABLE_STEPS`, per sampler."""
    cells = by_cell(results, "brdf", "n_labels")
    steps = [s for s in TABLE_STEPS if s < config["n_steps"]] + [config["n_steps"]]
    rows = []
    for (brdf, labels), group in cells.items():
        mean = xr.concat(group, dim="trial").mean("trial")
        for sampler in config["samplers"]:
            m = mean.sel(sampler=sampler)
            cols = []
            for s in steps:
                near = m.sel(step=s, method="nearest")
                cols += [float(near["map_to_truth"]), float(near["map_to_maximiser"])]
            beaten = sum(int(ds["final_log_target"].sel(sampler=sampler)
                             > ds["maximiser_log_prob"] + 1e-6) for ds in group)
            rows.append([sampler, brdf, labels, len(group), *cols,
                         float(mean["maximiser_to_truth"]), beaten, float(m["wall_time_s"])])
    header = ["sampler", "brdf", "labels", "scenes",
              *(f"{s}: {r}" for s in steps for r in ("truth", "max")), "max→truth",
              "MAP > max", "time s"]
    return markdown_table(header, rows)


def spread_table(results: list[xr.Dataset], config: dict) -> str:
    """Spread over scenes of the final MAP distance to the truth: the mean hides a heavy tail.

    A few chains stuck far from the peak pull the mean up; the median, the quartiles and the
    share of scenes within the thesis's level (0.1) say how typical a run is.
    """
    rows = []
    for (brdf, labels), group in by_cell(results, "brdf", "n_labels").items():
        final = xr.concat(group, dim="trial")["map_to_truth"].sel(step=config["n_steps"])
        for sampler in config["samplers"]:
            d = final.sel(sampler=sampler).values
            q1, med, q3 = np.percentile(d, [25, 50, 75])
            rows.append([sampler, brdf, labels, d.size, mean_sd(d.mean(), d.std(ddof=1)),
                         med, f"{q1:.3f}–{q3:.3f}", f"{int(np.sum(d <= 0.1))} / {d.size}"])
    header = ["sampler", "brdf", "labels", "scenes", "mean ± sd", "median", "quartiles",
              "≤ 0.1"]
    return markdown_table(header, rows, spec=".3f")


def figures(results: list[xr.Dataset], config: dict, out_dir: Path) -> list[str]:
    """Figs. 7.7-7.14: mean and single-scene curves per (sampler, model); their file names."""
    cells = by_cell(results, "brdf", "n_labels")
    means = {key: xr.concat(group, dim="trial").mean("trial") for key, group in cells.items()}
    figs = []
    for (sampler, brdf), (fig_mean, fig_single) in FIGURES.items():
        if sampler not in config["samplers"] or brdf not in config["brdf"]:
            continue
        for kind, fig_no in (("mean", fig_mean), ("single", fig_single)):
            fig, axes = new_figure(1, 2, size=(9, 3.4), sharey=True)
            for labels in config["n_labels"]:
                if (brdf, labels) not in cells:
                    continue
                data = (means[(brdf, labels)] if kind == "mean"
                        else cells[(brdf, labels)][0]).sel(sampler=sampler)
                for ax, var in zip(axes[0], ("map_to_truth", "map_to_maximiser")):
                    ax.plot(data["step"], data[var], label=f"{labels} labels")
            for ax, ref in zip(axes[0], ("truth", "PL maximiser")):
                ax.set(xlabel="step i", ylabel=f"distance to {ref}", xscale="log")
            axes[0, 1].legend(fontsize=7)
            what = "mean over scenes" if kind == "mean" else "one scene"
            fig.suptitle(f"Fig. {fig_no}: {sampler} on {brdf}, {what}", fontsize=9)
            figs.append(save_figure(fig, out_dir / f"{sampler}_{brdf}_{kind}.png"))
    return figs


def check_config(config: dict) -> None:
    """Every sampler accepts ``n_steps`` and ``sampler_options``."""
    check_problem(config)
    for name in config["samplers"]:
        check_sampler_options(name, {"n_steps": config["n_steps"], **config["sampler_options"]})


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """``report.md``: config, legend, the table, the figures."""
    summary = table(results, config)
    legend = ("Mean distance (unit cube) of the best-so-far sample to the truth (*truth*) and "
              "to the target's global maximiser (*max*) after the given number of steps. The "
              "thesis (7.4) reports that the curves approach 0.1 after about 20000 steps. "
              "*MAP > max*: runs whose final MAP scored higher than the maximiser found for "
              "the scene (should be 0).")
    spread = ("Spread over scenes of the distance to the truth after all "
              f"{config['n_steps']} steps (sd over scenes; *≤ 0.1*: scenes within the "
              "thesis's level).\n\n" + spread_table(results, config))
    figs = figures(results, config, out_dir)
    write_report(out_dir, "Dynamically weighted MCMC convergence (thesis Figs. 7.7-7.14)",
                 [f"Config: `{json.dumps(config)}`.", legend, summary, spread,
                  *(f"![{f}]({f})" for f in figs)])
    return summary


STUDY = Study(
    name="dw_convergence",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 100, "seed": 74},
    settings=[
        *settings(*DEFAULTS, target_options={"dtype": "float32"}),
        Setting("samplers", ["dw_r", "dw_q"], "samplers run on every scene (R-, Q-type)",
                choices=sampler_names),
        Setting("n_steps", 20000, "steps per sampler run", check=positive),
        Setting("sampler_options", {}, "further keyword options of every sampler"),
        Setting("record_stride", 10, "keep the trace every this many steps (after step 10)",
                check=positive),
    ],
    quick={**QUICK, "n_steps": 300},
    check=check_config,
    trial=trial,
    summarise=summarise,
    grid=("brdf", "n_labels"),
    shared_seed=("n_labels",),
)
