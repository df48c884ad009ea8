"""PMC convergence: MAP distance and weight variance per iteration, synthetic data (Tab. 7.1-7.4).

The thesis's protocol (7.4.1): for each trial, a random surface (smooth for
Ward, jagged for Phong, 7.2), a random light at infinity and random true
parameters b^n; the synthetic pseudolikelihood PL_s (7.5-7.7) with B labels per
node; PMC with 1000, 125 and 64 particles for 20 iterations (sub-lattice
importance functions, 7.9); per iteration the distance of the MAP particle to
b^n and the variance of the normalised weights, averaged over 100 trials.

What we add: every run also reports the distance of its MAP to the target's
own global maximiser (:func:`mrfpe.targets.maximise`), and the maximiser's
distance to the truth, so that the sampler's error and the target's bias are
told apart; and each trial runs both the thesis's PMC (II) (``thesis2``, the
algorithm behind Tables 7.1-7.4) and our default Cappé-style ``mixture`` PMC on
the same scene. One trial = one scene (per model, label count and repetition);
the scenes of a repetition are shared across label counts (common random
numbers), so the columns of a table compare like with like.

Our MAP is the best-so-far particle under the full target (``map_theta``);
the thesis's is the highest-weight particle of each iteration (7.4.1 step 6),
whose average can rise between iterations: each trial records both
(``map_to_*`` and ``pimap_to_*``; trials written before the latter existed
lack it, and the report says over how many trials each mean is taken). Weight
variance is the population variance of the normalised weights of the
iteration's set (``var`` columns; for PMC (II) these are the 1/G weights of
6.6.2 that represent the uniform distribution).

Full run: about 3.5 h on two cores (one process per core) in float32 (the
default). That is 800 scenes (2 models × 4 label counts × 100) × (PMC with
1000+125+64 particles × 20 iterations, two variants, plus a maximiser) at
100×100 pixels; measured per scene on one core of a 2-core AMD EPYC (Dec 2026,
lean kernel, single-threaded BLAS): Ward 13 s at 10 labels, ~25 s at 20, ~40 s
at 40; Phong 19 s at 10 labels, 27 s at 20 (a 20-label Ward scene: PMC (II)
~7 s, mixture PMC ~4 s, the maximiser ~6 s, the rest building the scene).
float64 (``--set 'target_options={"dtype": "float64"}'``) takes about 2× as
long. An older 20-label Ward column (Nov 2026 defaults) is in
``docs/results/pmc_convergence_ward20``.

Precision: the target is built in float32 by default. PMC needs log-target
differences to a fraction of a nat; float32 per-node terms (summed in
float64) keep ``log_prob`` within 2e-6 relative, a few 1e-3 nats at a 100×100
lattice's values, with the same softened weights to 1e-4 in total variation
(``tests/brdf/targets/test_pseudolikelihood.py::test_float32_accuracy``); on one
20-label scene with the same seed, PMC (II) returned the same MAP in float32
and float64.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments._thesis import PMC_TABLE_NAMES, PMC_TABLES
from mrfpe.experiments.problems import (
    DEFAULTS,
    QUICK,
    check_problem,
    check_sampler_options,
    child_seeds,
    distance,
    highest_weight,
    positive,
    problem_from_config,
    sample_traced,
    settings,
    weight_variance,
)
from mrfpe.experiments.writeup import markdown_table, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study, by_cell

#: PMC's variants (:class:`mrfpe.samplers.pmc.PMC`): Cappé-style mixture, thesis (II), (I).
VARIANTS = ("mixture", "thesis2", "thesis2_literal", "thesis1")

def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One scene; PMC for every variant and particle count; per-iteration statistics."""
    s_problem, s_runs = child_seeds(seed, 2)
    prob = problem_from_config(config, s_problem)
    variants, sizes, T = config["variants"], config["n_samples"], config["n_iterations"]
    shape3 = (len(variants), len(sizes), T)
    stats = {k: np.full(shape3, np.nan) for k in
             ("map_to_truth", "map_to_maximiser", "pimap_to_truth", "pimap_to_maximiser",
              "weight_var", "ess", "n_target_evals")}
    final = np.full((len(variants), len(sizes), len(prob.truth)), np.nan)
    wall = np.full(shape3[:2], np.nan)
    final_lt = np.full(shape3[:2], np.nan)
    run_seeds = child_seeds(s_runs, len(variants) * len(sizes))
    for i, variant in enumerate(variants):
        for j, n in enumerate(sizes):
            post, evals = sample_traced("pmc", prob.target, run_seeds[i * len(sizes) + j],
                                        n_samples=n, n_iterations=T, variant=variant,
                                        keep_history=True,
                                        **variant_options(config["pmc_options"], variant))
            m = post["map_theta"].values
            stats["map_to_truth"][i, j] = distance(m, prob.truth)
            stats["map_to_maximiser"][i, j] = distance(m, prob.maximiser)
            top = highest_weight(post)
            stats["pimap_to_truth"][i, j] = distance(top, prob.truth)
            stats["pimap_to_maximiser"][i, j] = distance(top, prob.maximiser)
            stats["weight_var"][i, j] = weight_variance(post)
            stats["ess"][i, j] = post["ess"].values
            stats["n_target_evals"][i, j] = evals
            final[i, j] = m[-1]
            wall[i, j] = post.attrs["wall_time_s"]
            final_lt[i, j] = post["map_log_target"].values[-1]
    dims = ("variant", "n_samples", "iteration")
    ds = xr.Dataset(
        {**{k: (dims, v) for k, v in stats.items()},
         "final_map": (("variant", "n_samples", "param"), final),
         "final_log_target": (("variant", "n_samples"), final_lt),
         "wall_time_s": (("variant", "n_samples"), wall)},
        coords={"variant": variants, "n_samples": sizes, "iteration": np.arange(1, T + 1),
                "param": list(prob.target.param_names)})
    return ds.merge(prob.dataset())


def _thesis(brdf: str, labels: int, n: int, T: int) -> tuple[list, list]:
    ref = PMC_TABLES.get((brdf, labels, n))
    if ref is None or T != 20:
        return [None] * T, [None] * T
    return ref[0], [v * 1e-6 for v in ref[1]]


def tables(results: list[xr.Dataset], config: dict) -> tuple[str, list[str]]:
    """The final-iteration summary table, and one section per (model, labels) in the
    thesis's layout (ours beside Tables 7.1-7.4)."""
    variants, sizes, T = config["variants"], config["n_samples"], config["n_iterations"]
    main = _main_variant(variants)
    sections, summary_rows = [], []
    for (brdf, labels), group in by_cell(results, "brdf", "n_labels").items():
        stacked = _stack(group)
        mean = stacked.mean("trial")  # NaN-skipping: π-MAP over the trials that have it
        n_pi = int(stacked["pimap_to_truth"].isel(variant=0, n_samples=0, iteration=0)
                   .notnull().sum())
        max_to_truth = float(mean["maximiser_to_truth"])
        header = ["iter"]
        cols = []
        for n in sizes:
            d_ref, v_ref = _thesis(brdf, labels, n, T)
            m = mean.sel(variant=main, n_samples=n)
            header += [f"N={n} truth", "thesis", "π-MAP", "max", "var×1e6", "thesis var×1e6"]
            cols += [m["map_to_truth"].values, d_ref,
                     m["pimap_to_truth"].values if n_pi else [None] * T,
                     m["map_to_maximiser"].values,
                     m["weight_var"].values * 1e6, [None if v is None else v * 1e6
                                                     for v in v_ref]]
        rows = [[it + 1, *(c[it] for c in cols)] for it in range(T)]
        table = PMC_TABLE_NAMES.get((brdf, labels), "–")
        sections.append(
            f"## {brdf}, {labels} labels, PMC variant `{main}` (thesis Table {table})\n\n"
            f"{len(group)} trials ({n_pi} with the π-MAP); the target's maximiser lies "
            f"{max_to_truth:.4f} from the truth on average.\n\n" + markdown_table(header, rows))
        for variant in variants:
            for n in sizes:
                m = mean.sel(variant=variant, n_samples=n)
                d_ref, _ = _thesis(brdf, labels, n, T)
                beaten = sum(int(ds["final_log_target"].sel(variant=variant, n_samples=n)
                                 > ds["maximiser_log_prob"] + 1e-6) for ds in group)
                summary_rows.append([brdf, labels, variant, n, len(group),
                                     float(m["map_to_truth"][-1]), d_ref[-1],
                                     float(m["map_to_maximiser"][-1]), max_to_truth, beaten,
                                     float(m["wall_time_s"]), float(m["n_target_evals"][-1])])
    summary = markdown_table(
        ["brdf", "labels", "variant", "N", "trials", "MAP→truth", "thesis", "MAP→max",
         "max→truth", "MAP > max", "time s", "evals"], summary_rows)
    return summary, sections


def figures(results: list[xr.Dataset], config: dict, out_dir: Path) -> list[str]:
    """Mean MAP distance per iteration, one PNG per (model, variant); their file names."""
    variants, sizes, T = config["variants"], config["n_samples"], config["n_iterations"]
    main = _main_variant(variants)
    cells = by_cell(results, "brdf", "n_labels")
    figs = []
    for brdf in config["brdf"]:
        for variant in variants:
            width = max(4.8, 3.2 * len(config["n_labels"]))  # room for the title
            fig, axes = new_figure(1, len(config["n_labels"]), size=(width, 3.4), sharey=True)
            for ax, labels in zip(axes[0], config["n_labels"]):
                group = cells.get((brdf, labels))
                if not group:
                    continue
                mean = _stack(group).mean("trial").sel(variant=variant)
                it = mean["iteration"].values
                for k, n in enumerate(sizes):
                    c = f"C{k}"
                    ax.plot(it, mean["map_to_truth"].sel(n_samples=n), c, label=f"N={n} truth")
                    ax.plot(it, mean["map_to_maximiser"].sel(n_samples=n), c + "--",
                            label=f"N={n} max")
                    ref, _ = _thesis(brdf, labels, n, T)
                    if ref[0] is not None and variant == main:
                        ax.plot(it, ref, c + ":", marker=".", label=f"N={n} thesis")
                ax.set(title=f"{labels} labels", xlabel="PMC iteration", yscale="log")
            axes[0, 0].set_ylabel("mean MAP distance")
            filled = [ax for ax in axes[0] if ax.get_legend_handles_labels()[0]]
            if filled:  # a cell with no trials yet leaves its panel empty
                filled[-1].legend(fontsize=6)
            fig.suptitle(f"PMC, {variant} variant, on {brdf} ({config['surfaces'][brdf]} "
                         "surfaces)")
            figs.append(save_figure(fig, out_dir / f"pmc_{brdf}_{variant}.png"))
    return figs


def chosen_trial(group: list[xr.Dataset], config: dict) -> xr.Dataset:
    """The cell's "randomly chosen run" (Tables 7.5-7.8): drawn from the study seed, so
    every report of the same trials shows the same one."""
    order = sorted(group, key=lambda ds: int(ds.attrs.get("repeat", 0)))
    return order[int(np.random.default_rng(config["seed"]).integers(len(order)))]


def single_runs(results: list[xr.Dataset], config: dict) -> list[str]:
    """One section per (model, labels): the chosen trial's per-iteration MAP distances and
    weight variance (the layout of the thesis's single-run Tables 7.5-7.8)."""
    sizes, T = config["n_samples"], config["n_iterations"]
    main = _main_variant(config["variants"])
    out = []
    for (brdf, labels), group in by_cell(results, "brdf", "n_labels").items():
        ds = _stack([chosen_trial(group, config)]).isel(trial=0).sel(variant=main)
        header, cols = ["iter"], []
        for n in sizes:
            m = ds.sel(n_samples=n)
            header += [f"N={n} π-MAP", "best-so-far", "var×1e6"]
            cols += [m["pimap_to_truth"].values, m["map_to_truth"].values,
                     m["weight_var"].values * 1e6]
        rows = [[it + 1, *(c[it] for c in cols)] for it in range(T)]
        out.append(f"### {brdf}, {labels} labels: repetition {int(ds.attrs.get('repeat', -1))}"
                   f" (`{main}`)\n\n" + markdown_table(header, rows))
    return out


def scene_figure(results: list[xr.Dataset], config: dict, out_dir: Path) -> list[str]:
    """Figs. 7.1-7.2: the chosen trial's surface (range of the true labels) and its
    rendering, per model; rebuilt from the trial's seed (no maximiser)."""
    cells = by_cell(results, "brdf", "n_labels")
    shown = {}
    for (brdf, labels), group in cells.items():
        shown.setdefault(brdf, (labels, chosen_trial(group, config)))
    if not shown:
        return []
    fig, axes = new_figure(len(shown), 2, size=(8.0, 3.4 * len(shown)))
    for row, (brdf, (labels, ds)) in zip(axes, shown.items()):
        cfg = {**config, "n_labels": labels, "maximiser_grid": None}
        prob = problem_from_config(cfg, child_seeds(int(ds.attrs["seed"]), 2)[0], brdf=brdf)
        sc = prob.scene
        depth = np.take_along_axis(sc.label_ranges, sc.observed_labels[..., None], -1)[..., 0]
        # the image's scale clipped at its 99th percentile: a sharp highlight would
        # otherwise leave the rest black
        for ax, img, title, vmax in ((row[0], depth, "true ranges", None),
                                     (row[1], sc.image, "image (clipped at p99)",
                                      float(np.percentile(sc.image, 99)))):
            h = ax.imshow(img, cmap="viridis" if vmax is None else "gray", vmax=vmax)
            fig.colorbar(h, ax=ax, fraction=0.046)
            ax.set(title=f"{brdf} ({config['surfaces'][brdf]}): {title}", xticks=[], yticks=[])
    return [save_figure(fig, out_dir / "pmc_scenes.png")]


def _stack(group: list[xr.Dataset]) -> xr.Dataset:
    """A cell's trials along ``trial``; trials written before the π-MAP was recorded get NaN."""
    filled = []
    for ds in group:
        for k in ("pimap_to_truth", "pimap_to_maximiser"):
            if k not in ds:
                ds = ds.assign({k: xr.full_like(ds["map_to_truth"], np.nan)})
        filled.append(ds)
    return xr.concat(filled, dim="trial")


def _main_variant(variants: list[str]) -> str:
    return "thesis2" if "thesis2" in variants else variants[0]


def variant_options(pmc_options: dict, variant: str) -> dict:
    """The PMC options of one variant: ``pmc_options``' plain keys apply to every variant, a
    key naming a variant (``{"thesis2": {"initial": "grid"}}``) adds options for that one."""
    shared = {k: v for k, v in pmc_options.items() if k not in VARIANTS}
    return {**shared, **pmc_options.get(variant, {})}


def check_config(config: dict) -> None:
    """Every PMC run of a trial can be built: variant × particle count × ``pmc_options``."""
    check_problem(config)
    for key, value in config["pmc_options"].items():
        if key in VARIANTS and not isinstance(value, dict):
            raise ValueError(f"pmc_options[{key!r}] must be an object of options for variant "
                             f"{key!r}, e.g. {{\"initial\": \"grid\"}}; got {value!r}")
    for variant in config["variants"]:
        for n in config["n_samples"]:
            check_sampler_options("pmc", {"n_samples": n, "n_iterations": config["n_iterations"],
                                          "variant": variant, "keep_history": True,
                                          **variant_options(config["pmc_options"], variant)})


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """``report.md``: config, legend, summary table, per-cell tables, figures."""
    summary, sections = tables(results, config)
    legend = (
        "Distances are Euclidean in the unit cube. *truth*: best-so-far MAP to the true "
        "parameters (the thesis's \"MAP dist\"); *max*: MAP to the target's global maximiser; "
        "*π-MAP*: the highest-weight particle of the iteration's set, the thesis's own "
        "bookkeeping (7.4.1 step 6), to the truth; "
        "*var*: variance of the normalised weights × 10⁶. Thesis columns: Tables 7.1-7.4 "
        "(PMC (II), 100 runs, highest-weight particle per iteration). *MAP > max*: runs "
        "whose MAP scored higher than the maximiser found for the scene (it should be 0; "
        "otherwise the maximiser search missed the peak and *max* distances are suspect).")
    figs = figures(results, config, out_dir)
    scenes = scene_figure(results, config, out_dir)
    singles = ("## Single runs (the layout of Tables 7.5-7.8)\n\nOne run per cell, drawn "
               "from the study seed (the thesis's are other random scenes, so only the "
               "pattern compares: the highest-weight particle's distance moves up and down, "
               "the best-so-far falls). *π-MAP* is missing (nan) in trials written before "
               "it was recorded.")
    write_report(out_dir, "PMC convergence (thesis Tables 7.1-7.8, Figs. 7.1-7.2)", [
        f"Config: `{json.dumps(config)}`.", legend,
        "## Final iteration, all variants\n\n" + summary, *sections,
        *(f"![{f}]({f})" for f in figs), singles, *single_runs(results, config),
        "## The synthetic scenes (Figs. 7.1-7.2)\n\nThe chosen run's scene per model: "
        "smooth thin-plate-spline surfaces for Ward, jagged ones for Phong (7.2).",
        *(f"![{f}]({f})" for f in scenes)])
    return summary


STUDY = Study(
    name="pmc_convergence",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 100, "seed": 741},
    settings=[
        *settings(*DEFAULTS, target_options={"dtype": "float32"}),
        Setting("n_samples", [1000, 125, 64], "PMC particle counts N, each run on every scene",
                check=positive),
        Setting("n_iterations", 20, "PMC iterations per run", check=positive),
        Setting("variants", ["thesis2", "mixture"], "PMC variants, each run on every scene",
                choices=VARIANTS),
        Setting("pmc_options", {}, "further keyword options of the PMC sampler, for every "
                "variant, or for one under its name: {\"thesis2\": {\"initial\": \"grid\"}}"),
    ],
    check=check_config,
    quick={**QUICK, "n_samples": [64, 27], "n_iterations": 5},
    trial=trial,
    summarise=summarise,
    grid=("brdf", "n_labels"),
    shared_seed=("n_labels",),
)
