"""Target bias against sampler error: where each target's maximum lies, and how near samplers get.

Beyond the thesis. A pseudolikelihood rewards parameters under which the
*alternative* labels of each node fit badly (its normaliser, 7.5), so its
global maximum need not sit on the true parameters, and a sampler that
"converges" reaches that maximum, not the truth. This study separates the two
errors for three targets built from the same energies (:mod:`mrfpe.targets`):
``pls`` (7.7), ``fit`` (the conditional likelihood of the image at the observed
labels) and ``pml`` (each node's label marginalised under the range prior), over
the data-energy scale σ_b (multiples of the default ``auto_sigma_b``) and the
surface steepness (smooth thin-plate-spline or jagged surfaces, 7.2), for Ward
and Phong. Per scene and target it records the distance (unit cube) from the
target's global maximiser (dense grid + local optimiser) to the truth, and for
every configured sampler run the distances from its MAP to that maximiser and
to the truth. The scenes of a repetition are shared across σ_b values.

Full run: about 1.7 h on two cores (one process per core). That is 160 scenes
(2 models × 2 surfaces × 4 σ_b × 10) × 3 targets × (maximiser + PMC 1000×20) at
100×100 pixels, measured at 63 s per 20-label Ward/smooth scene on one core (AMD
EPYC, Dec 2026).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments.problems import (
    SURFACES,
    check_runs,
    check_target_options,
    child_seeds,
    distance,
    maximiser,
    positive,
    settings,
)
from mrfpe.experiments.writeup import markdown_table, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study, by_cell


def _target_names() -> tuple[str, ...]:
    import mrfpe.targets

    return mrfpe.targets.names()


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One scene; per target its maximiser, then every sampler run on that target."""
    import mrfpe
    from mrfpe.brdf.targets.pseudolikelihood import auto_sigma_b

    brdf = config["brdf"]
    s_truth, s_scene, s_max, s_runs = child_seeds(seed, 4)
    model = mrfpe.brdf.get(brdf)
    lo, hi = config["truth_range"]
    u = np.random.default_rng(s_truth).uniform(lo, hi, model.d)
    kw = dict(brdf=brdf, theta=model.to_natural(u), shape=tuple(config["shape"]),
              n_labels=config["n_labels"], surface=config["surface"], seed=s_scene)
    clean = mrfpe.brdf.synthetic.make_scene(**kw)
    noise = config["noise"] * float(np.percentile(clean.image, 99))
    scene = mrfpe.brdf.synthetic.make_scene(**kw, noise=noise) if noise > 0 else clean
    sigma_b = config["sigma_b_scale"] * auto_sigma_b(scene)
    targets, runs = config["targets"], list(config["runs"])
    max_to_truth = np.full(len(targets), np.nan)
    maxima = np.full((len(targets), model.d), np.nan)
    max_lp = np.full(len(targets), np.nan)
    map_lp = np.full((len(targets), len(runs)), np.nan)
    map_to_max = np.full((len(targets), len(runs)), np.nan)
    map_to_truth = np.full((len(targets), len(runs)), np.nan)
    wall = np.full((len(targets), len(runs)), np.nan)
    run_seeds = child_seeds(s_runs, len(targets) * len(runs))
    for i, name in enumerate(targets):
        target = mrfpe.targets.get(name, scene, sigma_b=sigma_b,
                                   **config["target_options"].get(name, {}))
        mx, max_lp[i] = maximiser(target, config["maximiser_grid"], s_max, u)
        maxima[i] = mx
        max_to_truth[i] = distance(mx, u)
        for j, label in enumerate(runs):
            opts = dict(config["runs"][label])
            post = mrfpe.sample(opts.pop("sampler"), target, seed=run_seeds[i * len(runs) + j],
                                **opts)
            m = post["map_theta"].values[-1]
            map_to_max[i, j], map_to_truth[i, j] = distance(m, mx), distance(m, u)
            wall[i, j] = post.attrs["wall_time_s"]
            map_lp[i, j] = post["map_log_target"].values[-1]
    return xr.Dataset(
        {"maximiser_to_truth": (("target",), max_to_truth),
         "maximiser": (("target", "param"), maxima),
         "maximiser_log_prob": (("target",), max_lp),
         "map_log_target": (("target", "run"), map_lp),
         "map_to_maximiser": (("target", "run"), map_to_max),
         "map_to_truth": (("target", "run"), map_to_truth),
         "wall_time_s": (("target", "run"), wall),
         "truth": (("param",), u), "sigma_b": ((), sigma_b), "noise": ((), noise)},
        coords={"target": targets, "run": runs, "param": list(model.param_names)})


def _mean_se(x: np.ndarray) -> tuple[float, float]:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    return float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else np.nan


def _cells(results: list[xr.Dataset], config: dict) -> tuple[list[list], dict]:
    """Table rows per (model, surface, σ_b, target) and the bias curves for the figure."""
    runs = list(config["runs"])
    rows = []
    curves: dict = {}
    for (brdf, surface, scale), group in by_cell(results, "brdf", "surface",
                                                 "sigma_b_scale").items():
        stack = xr.concat(group, dim="trial")
        for name in config["targets"]:
            s = stack.sel(target=name)
            bias, bias_se = _mean_se(s["maximiser_to_truth"].values)
            row = [brdf, surface, scale, name, len(group), bias, bias_se]
            beaten = int((s["map_log_target"] > s["maximiser_log_prob"] + 1e-6).sum())
            for run in runs:
                row += [_mean_se(s["map_to_maximiser"].sel(run=run).values)[0],
                        _mean_se(s["map_to_truth"].sel(run=run).values)[0]]
            rows.append([*row, beaten])
            curves.setdefault((brdf, surface, name), []).append(
                (scale, bias, _mean_se(s["map_to_maximiser"].sel(run=runs[0]).values)[0]))
    return rows, curves


def table(rows: list[list], config: dict) -> str:
    """The markdown table of :func:`_cells`'s rows."""
    header = ["brdf", "surface", "σ_b × auto", "target", "scenes", "max→truth", "± s.e."]
    for run in config["runs"]:
        header += [f"{run}: MAP→max", f"{run}: MAP→truth"]
    header.append("MAP > max")
    return markdown_table(header, rows)


def figure(curves: dict, config: dict, out_dir: Path) -> str:
    """Bias and sampler error against σ_b, one panel per (model, surface); the file name."""
    runs = list(config["runs"])
    panels = [(b, s) for b in config["brdf"] for s in config["surface"]]
    fig, axes = new_figure(1, len(panels), size=(3.6 * len(panels), 3.4), sharey=True)
    for ax, (brdf, surface) in zip(axes[0], panels):
        for k, name in enumerate(config["targets"]):
            pts = sorted(curves.get((brdf, surface, name), []))
            if not pts:
                continue
            sc, bias, err = zip(*pts)
            ax.plot(sc, bias, "o-", color=f"C{k}", label=f"{name}: maximiser→truth")
            ax.plot(sc, err, "x--", color=f"C{k}", label=f"{name}: {runs[0]} MAP→maximiser")
        ax.set(xscale="log", yscale="log", xlabel="σ_b / auto", title=f"{brdf}, {surface}")
    axes[0, 0].set_ylabel("mean distance (unit cube)")
    axes[0, -1].legend(fontsize=6)
    return save_figure(fig, out_dir / "target_bias.png")


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """``report.md``: config, legend, table per (model, surface, σ_b, target), figure."""
    rows, curves = _cells(results, config)
    summary = table(rows, config)
    png = figure(curves, config, out_dir)
    write_report(out_dir, "Target bias and sampler error (beyond the thesis)", [
        f"Config: `{json.dumps(config)}`.",
        "*max→truth*: distance from the target's global maximiser to the true parameters "
        "(the target's bias); *MAP→max*: distance from a sampler's final MAP to that "
        "maximiser (the sampler's error); *MAP→truth*: what a study that only knows the "
        "truth would report. Means over scenes. *MAP > max*: runs whose MAP scored higher "
        "than the maximiser found (should be 0; otherwise the maximiser search missed the "
        "peak).",
        summary, f"![bias]({png})"])
    return summary


STUDY = Study(
    name="target_bias",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 10, "seed": 99},
    settings=[
        *settings("brdf", "shape", "n_labels", "noise", "truth_range", "maximiser_grid",
                  n_labels=20, noise=0.01),
        Setting("surface", list(SURFACES), "surface types, one grid column each",
                choices=SURFACES),
        Setting("sigma_b_scale", [0.5, 1.0, 2.0, 4.0],
                "data-energy scale σ_b as multiples of auto_sigma_b", check=positive),
        Setting("targets", ["pls", "fit", "pml"], "targets built on every scene",
                choices=_target_names),
        Setting("target_options", {}, "per-target keyword options, {target: {option: value}}",
                choices=_target_names),
        Setting("runs", {"pmc": {"sampler": "pmc", "n_samples": 1000, "n_iterations": 20}},
                "sampler runs per target, {label: {\"sampler\": NAME, option: value}}",
                check=check_runs),
    ],
    check=check_target_options,
    quick={"n_trials": 1, "brdf": ["ward"], "sigma_b_scale": [1.0, 4.0], "shape": [12, 12],
           "n_labels": 10, "maximiser_grid": 8,
           "runs": {"pmc": {"sampler": "pmc", "n_samples": 64, "n_iterations": 5}}},
    trial=trial,
    summarise=summarise,
    grid=("brdf", "surface", "sigma_b_scale"),
    shared_seed=("sigma_b_scale",),
)
