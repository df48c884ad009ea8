"""The pseudolikelihood volume with PMC particles at iterations 1, 5, 10, 15, 20 (Figs. 7.15-7.28).

The thesis shows the pseudolikelihood on a regular grid over the unit cube of
parameters, with the PMC particles of iterations 1, 5, 10, 15 and 20
superimposed, for three synthetic cases: Ward with (ρ_d, ρ_s, 2α) =
(0.7, 0.4, 0.9) (Figs. 7.15-7.19), Ward with (0.8, 0.9, 0.5) (7.20-7.24) and
anisotropic Phong with (R_d, R_s, n/25) = (0.8, 0.9, 0.5) (7.25-7.28). Each
trial here builds one case (Ward on a smooth surface, Phong on a jagged one,
7.2), evaluates PL_s (7.7) on a ``volume_grid``³ grid, and runs PMC (the
thesis's PMC (II) by default) keeping every iteration's weighted set. The
figure of a case has one row per shown iteration: three orthogonal slices of
the log pseudolikelihood through the truth (relative to the grid's maximum,
clipped at ``-log_floor``), the particles projected onto each slice (size ∝
weight), and a 3-D view of the particles. Each row also reports the
distance of the iteration's best particle (under the full target) to the
truth and to the grid maximiser.

Full run: about 2 min on two cores. That is 3 cases × (25³ grid evaluations +
PMC 1000×20 + the full target at the particles of the five shown iterations)
at 100×100 pixels, measured at 32 s per case.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments.problems import (
    check_sampler_options,
    check_target_options,
    child_seeds,
    distance,
    positive,
    settings,
)
from mrfpe.experiments.writeup import blank_figure, markdown_table, save_figure, write_report
from mrfpe.study import Setting, Study

CASES = [["ward", [0.7, 0.4, 0.9]], ["ward", [0.8, 0.9, 0.5]], ["phong", [0.8, 0.9, 0.5]]]
THESIS_FIGURES = ["7.15-7.19", "7.20-7.24", "7.25-7.28"]


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One case: the PL volume, PMC particles at the shown iterations, their best points."""
    import mrfpe
    from mrfpe.targets.maximise import grid_points

    brdf, u = config["cases"][config["case"]]
    u = np.asarray(u, dtype=float)
    s_scene, s_pmc = child_seeds(seed, 2)
    model = mrfpe.brdf.get(brdf)
    scene = mrfpe.brdf.synthetic.make_scene(brdf=brdf, theta=model.to_natural(u),
                                       shape=tuple(config["shape"]),
                                       n_labels=config["n_labels"],
                                       surface=config["surfaces"][brdf], seed=s_scene)
    target = mrfpe.targets.get(config["target"], scene, **config["target_options"])
    n = config["volume_grid"]
    axis = np.linspace(0.0, 1.0, n)
    volume = target.log_prob(grid_points(target.bounds, n)).reshape(n, n, n)
    peak = np.unravel_index(int(np.argmax(volume)), volume.shape)
    grid_max = axis[list(peak)]
    post = mrfpe.sample("pmc", target, seed=s_pmc, keep_history=True, **config["pmc"])
    shown = [i for i in config["iterations"] if i <= post.sizes["step"]]
    hx = post["history_theta"].values[[i - 1 for i in shown]]
    hw = post["history_log_weight"].values[[i - 1 for i in shown]]
    best = np.empty((len(shown), model.d))
    for k in range(len(shown)):  # the iteration's best particle under the full target
        best[k] = hx[k][int(np.argmax(target.log_prob(hx[k])))]
    names = list(target.param_names)
    return xr.Dataset(
        {"log_pl": (("u0", "u1", "u2"), volume.astype(np.float32)),
         "particles": (("iteration", "sample", "param"), hx),
         "log_weight": (("iteration", "sample"), hw),
         "best": (("iteration", "param"), best),
         "best_to_truth": (("iteration",), distance(best, u)),
         "best_to_grid_max": (("iteration",), distance(best, grid_max)),
         "truth": (("param",), u), "grid_max": (("param",), grid_max)},
        coords={"u0": axis, "u1": axis, "u2": axis, "iteration": shown, "param": names},
        attrs={"brdf": brdf})


def _plot_case(ds: xr.Dataset, floor: float, title: str, path: Path) -> str:
    vol = ds["log_pl"].values.astype(float)
    rel = np.clip(vol - np.nanmax(vol[np.isfinite(vol)]), -floor, 0.0)
    axis = ds["u0"].values
    names = [str(p) for p in ds["param"].values]
    truth = ds["truth"].values
    idx = [int(np.argmin(np.abs(axis - t))) for t in truth]
    # (slice image, x parameter, y parameter): each plane passes through the truth
    planes = [(rel[:, :, idx[2]], 0, 1), (rel[:, idx[1], :], 0, 2), (rel[idx[0], :, :], 1, 2)]
    its = ds["iteration"].values
    h = 0.5 / (axis.size - 1)  # grid points are pixel centres
    fig = blank_figure(size=(13, 3.0 * len(its)))
    for r, it in enumerate(its):
        x = ds["particles"].sel(iteration=it).values
        w = np.exp(ds["log_weight"].sel(iteration=it).values)
        size = 2 + 40 * w / max(w.max(), 1e-300)
        for c, (img, a, b) in enumerate(planes):
            ax = fig.add_subplot(len(its), 4, 4 * r + c + 1)
            ax.imshow(img.T, origin="lower", extent=(-h, 1 + h, -h, 1 + h), cmap="magma",
                      vmin=-floor, vmax=0, aspect="auto")
            ax.scatter(x[:, a], x[:, b], s=size, c="cyan", alpha=0.5, linewidths=0)
            ax.plot(truth[a], truth[b], "g+", ms=10, mew=2)
            ax.set(xlabel=names[a], ylabel=names[b], xlim=(0, 1), ylim=(0, 1))
            if c == 0:
                ax.set_title(f"iteration {it}: best→truth "
                             f"{float(ds['best_to_truth'].sel(iteration=it)):.3f}, →grid max "
                             f"{float(ds['best_to_grid_max'].sel(iteration=it)):.3f}",
                             fontsize=8, loc="left")
        ax3 = fig.add_subplot(len(its), 4, 4 * r + 4, projection="3d")
        ax3.scatter(x[:, 0], x[:, 1], x[:, 2], s=size / 4, c=w, cmap="viridis")
        ax3.scatter(*truth, c="g", marker="+", s=80)
        ax3.set(xlim=(0, 1), ylim=(0, 1), zlim=(0, 1), xlabel=names[0], ylabel=names[1],
                zlabel=names[2])
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=80)


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """One figure per case and a table of best-particle distances per iteration."""
    rows, sections, figs = [], [f"Config: `{json.dumps(config)}`."], []
    for ds in results:
        case = json.loads(ds.attrs["cell"])["case"]
        brdf = ds.attrs["brdf"]
        truth = ds["truth"].values
        ref = THESIS_FIGURES[case] if case < len(THESIS_FIGURES) else "–"
        title = (f"case {case}: {brdf}, truth {np.round(truth, 3).tolist()} (thesis Figs. "
                 f"{ref}); log PL_s relative to its grid maximum, clipped at "
                 f"-{config['log_floor']:g}")
        figs.append(_plot_case(ds, config["log_floor"], title,
                               out_dir / f"slices_case{case}_{brdf}.png"))
        for it in ds["iteration"].values:
            rows.append([case, brdf, int(it), float(ds["best_to_truth"].sel(iteration=it)),
                         float(ds["best_to_grid_max"].sel(iteration=it))])
        rows.append([case, brdf, "grid max→truth", float(distance(ds["grid_max"].values,
                                                                   truth)), "–"])
    table = markdown_table(["case", "brdf", "iteration", "best→truth", "best→grid max"], rows)
    sections += ["Best particle of each shown iteration (under the full target): distance "
                 "(unit cube) to the truth and to the maximiser of the volume grid.", table]
    sections += [f"![{f}]({f})" for f in figs]
    write_report(out_dir, "Pseudolikelihood volumes with PMC particles (thesis Figs. "
                 "7.15-7.28)", sections)
    return table


STUDY = Study(
    name="posterior_slices",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 1, "seed": 715},
    settings=[
        *settings("surfaces", "shape", "n_labels", "target", "target_options", n_labels=20),
        Setting("case", [0, 1, 2], "case indices (into cases), one grid column each"),
        Setting("cases", CASES, "[model, unit-cube truth] of every case (Figs. 7.15-7.28)"),
        Setting("pmc", {"n_samples": 1000, "n_iterations": 20, "variant": "thesis2"},
                "options of the PMC run", check=lambda opts: check_sampler_options("pmc", opts)),
        Setting("iterations", [1, 5, 10, 15, 20], "PMC iterations shown, one figure row each",
                check=positive),
        Setting("volume_grid", 25, "grid points per axis of the PL volume", check=positive),
        Setting("log_floor", 200.0, "slices are clipped this many log units below the maximum",
                check=positive),
    ],
    check=check_target_options,
    quick={"case": [0, 2], "shape": [12, 12], "n_labels": 10,
           "pmc": {"n_samples": 64, "n_iterations": 5, "variant": "thesis2"},
           "iterations": [1, 3, 5], "volume_grid": 10},
    trial=trial,
    summarise=summarise,
    grid=("case",),
)
