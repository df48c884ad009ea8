"""Material classification from posteriors on a synthetic benchmark (Tables 8.3-8.11).

The thesis classifies 12 real materials × 4 surfaces (48 posteriors from
stereo photographs, which are not available) with the Miss / WNN / NN1
statistics of 8.2.4 under many distances (8.2.1-8.2.4). This study builds the
same experiment synthetically: each *material* is a fixed BRDF parameter set
(unit cube; the list mirrors the thesis's materials, with two near-identical
t-shirt cloths like its #8 and #9), each of its 4 *specimens* a different
random smooth surface, random light at infinity and pixel-noise level
(``noise_levels``, as fractions of the noise-free image's 99th percentile).
For every specimen it computes

* the *unevolved* set: the thesis's evenly spaced initial grid (1000 points)
  weighted by the full target (Tables 8.6, 8.7);
* the *evolved* set: PMC (1000 particles, 20 iterations; the thesis's PMC (II)
  of 6.6.2 by default) (Tables 8.8-8.11);
* the best of multiple-seed LM (512 seeds, ranked by the LM error 7.12;
  "LM512" in Tables 8.10, 8.11),

then every registered distance between all pairs, the similarity matrices
(higher = more alike, :mod:`mrfpe.classify`), the Miss / WNN / NN1 counts in
the thesis's layout beside its numbers, and heat-maps (Tables 8.3-8.5 as
pictures). The thesis's posteriors used PL_3 on stereo reconstructions; ours
use PL_s (7.7) on synthetic scenes, so only the pattern, not the counts, can
be compared.

Full run: about 1 h on two cores (one process per core). That is 96
specimens (2 models × 12 × 4) × (PMC 1000×20 + 512-seed LM of 10 iterations +
1000 grid evaluations) at 100×100 pixels, measured at 37-45 s per 20-label Ward
and ~75 s per Phong specimen on one core (AMD EPYC, Dec 2026), plus the
summary's pairwise distances of 1000-point sets: 25 min on one core, most of it
POT's exact EMD (``summary_jobs`` spreads the pair loops over the cores).

The report opens with Kish's ESS of every feature set. With the thesis's
settings both the grid set (weighted by a log-PL of order -10⁴) and PMC (II)'s
final 1/G weights have ESS ≈ 1, so the covariance-based distances would compare
the spread of a few points. Two summary settings, which re-summarise the same
trials (they are not part of a trial's config), make the sets informative:

* ``grid_power`` λ tempers the grid set's weights to p^λ (exact on the uniform
  grid). Default 1e-4: the largest λ of the report's sweep at which every
  specimen's set has ESS ≥ 10 d (d = 3 parameters; measured on the full
  benchmark, Dec 2026), and the softening power PMC (II) itself runs at;
  λ = 1 is the thesis's weighting;
* ``evolved_weights``: ``"uniform"`` gives the final PMC cloud equal weights,
  the particles being drawn around a population resampled by the softened
  target; ``"sampler"`` keeps the sampler's final weights (for PMC (II) its π,
  the thesis's sets, ESS ≈ 1; for PMC (I) and ``mixture`` proper importance
  weights). The default ``"auto"`` is uniform for PMC (II) (the study's
  ``pmc`` setting) and the sampler's weights for the other variants.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.experiments._thesis import AGMMP_SIGMAS, CLASSIFICATION
from mrfpe.experiments.problems import (
    SURFACES,
    check_sampler_options,
    check_target_options,
    child_seeds,
    non_negative,
    positive,
    settings,
)
from mrfpe.experiments.writeup import markdown_table, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study
from mrfpe.validation import check_n_jobs


def _brdf_names() -> tuple[str, ...]:
    import mrfpe.brdf

    return mrfpe.brdf.names()


def _distance_names() -> list[str]:
    import mrfpe.distances

    return list(mrfpe.distances.available())


def _non_negatives(values: list) -> None:
    for v in values:
        non_negative(v)


def _unit_power(value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value <= 1:
        raise ValueError(f"must be a number in (0, 1]; got {value!r}")


#: Powers λ of the report's sweep of the grid sets' ESS and spread (``grid_power`` joins them).
POWER_SWEEP = (1.0, 1e-2, 1e-3, 3e-4, 1e-4)
#: Ways of weighting the final PMC cloud (``evolved_weights``).
EVOLVED_WEIGHTS = ("auto", "uniform", "sampler")
#: PMC variants whose final weights are not importance weights of the target (PMC (II)'s π).
_NOT_IMPORTANCE = ("thesis2", "thesis2_literal")


def _uniform_cloud(config: dict) -> bool:
    """Whether the evolved sets get equal weights (``evolved_weights``; ``auto``: for PMC (II))."""
    mode = config["evolved_weights"]
    if mode == "auto":  # the variant the pmc options select, the sampler's default included
        import mrfpe.samplers

        return mrfpe.samplers.get("pmc")(**config["pmc"]).variant in _NOT_IMPORTANCE
    return mode == "uniform"

MATERIAL_NAMES = ["shiny fabric", "shiny plastic", "laminated paper", "glossy brown paper",
                  "canvas", "smooth cloth", "fuzzy cloth", "t-shirt cloth",
                  "t-shirt cloth (2)", "smooth blue cloth", "black leather", "froth"]
#: Unit-cube parameters: Ward (ρ_d, ρ_s, 2α), Phong (R_d, R_s, n/25). Shiny materials
#: have a small Ward roughness α and a large Phong exponent n.
MATERIALS = {
    "ward": [[0.45, 0.35, 0.30], [0.30, 0.65, 0.12], [0.55, 0.40, 0.10], [0.35, 0.30, 0.22],
             [0.75, 0.08, 0.70], [0.55, 0.15, 0.45], [0.85, 0.05, 0.90], [0.70, 0.12, 0.60],
             [0.66, 0.14, 0.56], [0.40, 0.20, 0.40], [0.10, 0.55, 0.80], [0.50, 0.45, 0.18]],
    "phong": [[0.45, 0.35, 0.40], [0.30, 0.65, 0.85], [0.55, 0.40, 0.90], [0.35, 0.30, 0.60],
              [0.75, 0.08, 0.10], [0.55, 0.15, 0.25], [0.85, 0.05, 0.05], [0.70, 0.12, 0.15],
              [0.66, 0.14, 0.18], [0.40, 0.20, 0.30], [0.10, 0.55, 0.08], [0.50, 0.45, 0.70]],
}


def specimen_scene(config: dict, seed: int,
                   shape: tuple[int, int] | None = None) -> tuple[Any, np.ndarray, float]:
    """A specimen's scene, true parameters (unit cube) and pixel-noise sd, from its trial
    config (``brdf``, ``material``, ``specimen`` and the study's settings) and trial seed;
    ``shape`` overrides the config's image size (same surface law, light and noise level)."""
    import mrfpe

    brdf, material, specimen = config["brdf"], config["material"], config["specimen"]
    model = mrfpe.brdf.get(brdf)
    u = np.asarray(config["materials"][brdf][material], dtype=float)
    kw = dict(brdf=brdf, theta=model.to_natural(u),
              shape=tuple(config["shape"] if shape is None else shape),
              n_labels=config["n_labels"], surface=config["surface"],
              seed=child_seeds(seed, 3)[0])
    clean = mrfpe.brdf.synthetic.make_scene(**kw)  # same seed: same surface and light, no noise
    noise = config["noise_levels"][specimen % len(config["noise_levels"])] * float(
        np.percentile(clean.image, 99))
    scene = mrfpe.brdf.synthetic.make_scene(**kw, noise=noise) if noise > 0 else clean
    return scene, u, noise


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One specimen: scene, target, and its unevolved, evolved and LM feature sets."""
    import mrfpe
    from mrfpe.posterior import normalise_log_weights
    from mrfpe.samplers.kit import grid

    _, s_pmc, s_lm = child_seeds(seed, 3)
    scene, u, noise = specimen_scene(config, seed)
    target = mrfpe.targets.get(config["target"], scene, **config["target_options"])
    evolved = mrfpe.sample("pmc", target, seed=s_pmc, **config["pmc"])
    pts = grid(np.asarray(target.bounds, dtype=float), config["grid_samples"])
    grid_lt = target.log_prob(pts)
    lm = mrfpe.sample("lm_multiseed", target, seed=s_lm, **config["lm"])
    best = int(np.nanargmin(np.where(np.isfinite(lm["lm_cost"].values),
                                     lm["lm_cost"].values, np.inf)))
    return xr.Dataset(
        {"evolved_theta": (("evolved_sample", "param"), evolved["theta"].values),
         "evolved_log_weight": (("evolved_sample",), evolved["log_weight"].values),
         "evolved_map": (("param",), evolved["map_theta"].values[-1]),
         "grid_theta": (("grid_sample", "param"), pts),
         "grid_log_weight": (("grid_sample",), normalise_log_weights(grid_lt)),
         "lm_best": (("param",), lm["theta"].values[best]),
         "truth": (("param",), u), "noise": ((), noise),
         "pmc_time_s": ((), evolved.attrs["wall_time_s"]),
         "lm_time_s": ((), lm.attrs["wall_time_s"])},
        coords={"param": list(target.param_names)})


def posterior_set(theta: np.ndarray, log_weight: np.ndarray, names: list,
                  map_theta: np.ndarray | None = None) -> xr.Dataset:
    """A minimal posterior Dataset (what the distances read)."""
    if map_theta is None:
        map_theta = theta[int(np.argmax(log_weight))]
    return xr.Dataset({"theta": (("sample", "param"), theta),
                       "log_weight": (("sample",), log_weight),
                       "map_theta": (("step", "param"), np.asarray(map_theta)[None])},
                      coords={"param": names})


#: Parameters per posterior: the ESS floor of the ``grid_power`` choice is 10 per dimension.
_DIM = 3


def _information(posts: list[xr.Dataset]) -> list[str]:
    """Median and min Kish ESS, count below ``10 * d``, median weighted sd (mean over axes)."""
    from mrfpe.posterior import ess, weighted_cov

    e = np.array([ess(p) for p in posts])
    sd = [np.sqrt(np.diag(weighted_cov(p))).mean() for p in posts]
    return [f"{np.median(e):.1f}", f"{e.min():.1f}", f"{int(np.sum(e < 10 * _DIM))} / {e.size}",
            f"{np.median(sd):.3f}"]


def _grid_set(ds: xr.Dataset, power: float) -> xr.Dataset:
    """A specimen's unevolved set, its target weights raised to ``power``."""
    from mrfpe.posterior import normalise_log_weights

    lw = normalise_log_weights(power * ds["grid_log_weight"].values)
    return posterior_set(ds["grid_theta"].values, lw, [str(p) for p in ds["param"].values])


def _evolved_set(ds: xr.Dataset, uniform: bool) -> xr.Dataset:
    """A specimen's final PMC cloud, equally weighted or with the sampler's weights."""
    lw = ds["evolved_log_weight"].values
    return posterior_set(ds["evolved_theta"].values, np.zeros_like(lw) if uniform else lw,
                      [str(p) for p in ds["param"].values], ds["evolved_map"].values)


def _ranks(S: np.ndarray) -> np.ndarray:
    """Off-diagonal entries replaced by their ranks in [0, 1] (diagonal NaN) for display.

    Like the thesis's linear rescaling of its tables, any increasing map leaves every
    classification statistic unchanged; ranks keep heavy-tailed distances readable. Ties
    are the statistics' ties (:func:`mrfpe.classify.merge_ties`), ranked together.
    """
    from scipy.stats import rankdata

    from mrfpe.classify import merge_ties

    off = ~np.eye(S.shape[0], dtype=bool)
    out = np.full(S.shape, np.nan)
    r = rankdata(merge_ties(S)[off])
    out[off] = (r - 1) / max(r.size - 1, 1)
    return out


def _columns(kind: str, config: dict) -> list[tuple[str, str, dict]]:
    """(column label, distance name, params) for one of the thesis's table kinds."""
    agmmp = [(f"agmmp:{s:g}", "agmmp", {"sigma": s}) for s in config["agmmp_sigmas"]]
    if kind == "unevolved":
        return [*agmmp, ("map", "map_euclidean", {}), ("emd", "emd", {}),
                ("corr", "correlation", {}), ("ip", "inner_product", {})]
    if kind == "evolved_agmmp":
        return agmmp
    return [("chernoff", "chernoff", {"alpha": 0.7}), ("bhattacharyya", "bhattacharyya", {}),
            ("kl", "kl", {}), ("symmetric_kl", "symmetric_kl", {}),
            ("patrick_fisher", "patrick_fisher", {}), ("mahalanobis", "mahalanobis", {}),
            ("map", "map_euclidean", {}), ("emd", "emd", {}), ("lm512", "lm512", {}),
            *[(name, name, {}) for name in config["extra_distances"]]]


#: Each table's title, by the kind of feature set and distance columns it shows.
_TABLE_TITLES = {"unevolved": "samples at their initial grid positions",
                 "evolved_agmmp": "PMC-evolved sets, AGMMP",
                 "evolved": "PMC-evolved sets"}
#: The similarity matrices drawn as heat-maps, by (table kind, column).
_PICTURED = [("evolved", "symmetric_kl"), ("evolved_agmmp", "agmmp:0.005"),
             ("unevolved", "emd"), ("unevolved", "corr")]


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """Similarity matrices, Miss/WNN/NN1 tables beside the thesis's, heat-maps."""
    sections = [f"Config: `{json.dumps(config)}`.",
                "Each column classifies the specimens by one similarity; rows *Miss*, *WNN*, "
                "*NN1* as defined under the thesis's Table 8.5 (lower is better; ties count as "
                "no error), *1-NN acc.* the leave-one-out nearest-neighbour accuracy; the "
                "thesis's counts (48 real surfaces) follow in italics. Materials: " +
                ", ".join(f"{i}: {n}" for i, n in enumerate(MATERIAL_NAMES)) + "."]
    summary_rows, figs, ess_rows = [], [], []
    lam = float(config["grid_power"])
    powers = sorted({*POWER_SWEEP, lam}, reverse=True)
    uniform = _uniform_cloud(config)
    for brdf in config["brdf"]:
        group, classes = _specimens(results, brdf)
        grids = {power: [_grid_set(ds, power) for ds in group] for power in powers}
        clouds = {flat: [_evolved_set(ds, flat) for ds in group] for flat in (False, True)}
        for power, posts in grids.items():
            ess_rows.append([brdf, "unevolved", f"{power:g}" + (" ←" if power == lam else ""),
                             *_information(posts)])
        for flat, posts in clouds.items():
            ess_rows.append([brdf, "evolved", ("uniform" if flat else "sampler (π)")
                             + (" ←" if flat == uniform else ""), *_information(posts)])
        sets = {"unevolved": grids[lam], "evolved": clouds[uniform]}
        lm_best = np.stack([ds["lm_best"].values for ds in group])
        matrices: dict[tuple[str, str], np.ndarray] = {}
        for kind in ("unevolved", "evolved_agmmp", "evolved"):
            posts = sets["unevolved" if kind == "unevolved" else "evolved"]
            sections.append(_error_table(brdf, kind, posts, lm_best, classes, config,
                                         matrices, summary_rows))
        figs.append(_similarity_figure(brdf, matrices, classes, out_dir))
    sections.insert(1, _information_section(config, uniform, lam, ess_rows))
    sections += [f"![{f}]({f})" for f in figs]
    write_report(out_dir, "Material classification on a synthetic benchmark "
                 "(thesis Tables 8.3-8.11)", sections)
    return markdown_table(["brdf", "sets", "measure", "Miss", "WNN", "NN1", "1-NN acc."],
                          summary_rows)


def _specimens(results: list[xr.Dataset], brdf: str) -> tuple[list[xr.Dataset], np.ndarray]:
    """The trials of model ``brdf`` by material then specimen, and their materials."""
    group = [ds for ds in results if json.loads(ds.attrs["cell"])["brdf"] == brdf]
    cells = [json.loads(ds.attrs["cell"]) for ds in group]
    order = sorted(range(len(group)), key=lambda i: (cells[i]["material"],
                                                     cells[i]["specimen"]))
    return [group[i] for i in order], np.array([cells[i]["material"] for i in order])


def _error_table(brdf: str, kind: str, posts: list[xr.Dataset], lm_best: np.ndarray,
                 classes: np.ndarray, config: dict, matrices: dict,
                 summary_rows: list) -> str:
    """One table of the report: Miss/WNN/NN1/accuracy per distance column, the thesis's
    counts beneath; each similarity matrix goes into ``matrices``, each column's numbers
    into ``summary_rows``."""
    from scipy.spatial.distance import cdist

    from mrfpe.classify import error_stats, knn_accuracy, similarity_matrix

    header, stats = ["statistic"], {"miss": [], "wnn": [], "nn1": [], "acc": []}
    for label, name, params in _columns(kind, config):
        if name == "lm512":
            S = -cdist(lm_best, lm_best)
        else:
            S = similarity_matrix(posts, name, n_jobs=config["summary_jobs"], **params)
        matrices[(kind, label)] = S
        st = error_stats(S, classes)
        header.append(label)
        for k in ("miss", "wnn", "nn1"):
            stats[k].append(st[k])
        stats["acc"].append(knn_accuracy(S, classes))
        summary_rows.append([brdf, kind, label, st["miss"], st["wnn"], st["nn1"],
                             stats["acc"][-1]])
    rows = [["Miss", *stats["miss"]], ["WNN", *stats["wnn"]], ["NN1", *stats["nn1"]],
            ["1-NN acc.", *(f"{a:.2f}" for a in stats["acc"])]]
    ref = CLASSIFICATION.get((brdf, kind))
    if ref is not None:
        lookup = dict(zip(ref["columns"], range(len(ref["columns"]))))
        for k, shown in (("miss", "Miss"), ("wnn", "WNN"), ("nn1", "NN1")):
            rows.append([f"*thesis {shown}*",
                         *(f"*{ref[k][lookup[h]]}*" if h in lookup else "–"
                           for h in header[1:])])
    table_no = f" (thesis Table {ref['table']})" if ref else ""
    return (f"## {brdf}: {_TABLE_TITLES[kind]}{table_no}\n\n{len(posts)} specimens, "
            f"{len(set(classes.tolist()))} materials.\n\n" + markdown_table(header, rows))


def _similarity_figure(brdf: str, matrices: dict, classes: np.ndarray, out_dir: Path) -> str:
    """Heat-maps of the :data:`_PICTURED` similarity matrices; the PNG's file name."""
    from mrfpe.classify import plot_similarity

    picks = [p for p in _PICTURED if p in matrices]
    fig, axes = new_figure(1, len(picks), size=(4.6 * len(picks), 4.2))
    for ax, (kind, label) in zip(axes[0], picks):
        plot_similarity(_ranks(matrices[(kind, label)]), classes, ax=ax,
                        title=f"{kind}: {label}", colorbar=False)
    fig.suptitle(f"Similarity matrices, {brdf}, shown as ranks of the off-diagonal "
                 "entries (Tables 8.3-8.5 as pictures)", fontsize=9)
    return save_figure(fig, out_dir / f"similarity_{brdf}.png")


def _information_section(config: dict, uniform: bool, lam: float, ess_rows: list) -> str:
    """The report's section on how much information each feature set holds."""
    weights = config["evolved_weights"]
    if weights == "auto":  # name what it resolved to
        weights += f": {'uniform' if uniform else 'sampler'}"
    return ("## Information in the feature sets\n\nKish's ESS of each specimen's "
            "normalised weights (1 = one point carries all the weight) and the weighted "
            "standard deviation of its parameters (median over specimens of the mean "
            "over the three axes; a uniform cube gives 0.289). Where the ESS is about 1 "
            "the covariance-based distances (Chernoff, Bhattacharyya, KL, "
            "Patrick-Fisher, Mahalanobis) compare the spread of a few points, i.e. "
            "noise. Unevolved sets against the power λ on their target weights, "
            "evolved sets under their two weightings; ← marks the tables' setting "
            f"(`grid_power` = {lam:g}, `evolved_weights` = {weights}).\n\n"
            + markdown_table(["brdf", "set", "λ / weights", "median ESS", "min ESS",
                              f"ESS < {10 * _DIM}", "median sd"], ess_rows))


STUDY = Study(
    name="classification",
    # 2: sampler defaults and the thesis2 reading changed (old trials must not resume)
    version=2,
    doc=__doc__,
    config={"n_trials": 1, "seed": 824},
    settings=[
        *settings("brdf", "shape", "n_labels", "target", "target_options", n_labels=20),
        Setting("material", list(range(12)), "material indices (into materials), one grid "
                "column each"),
        Setting("specimen", [0, 1, 2, 3], "specimens per material: surface, light and noise "
                "level differ"),
        Setting("materials", MATERIALS, "unit-cube parameters of every material, per model",
                choices=_brdf_names),
        Setting("surface", "smooth", "surface type of every specimen", choices=SURFACES),
        Setting("noise_levels", [0.0, 0.01, 0.02, 0.04], "pixel noise per specimen, as a "
                "fraction of the noise-free image's 99th percentile", check=_non_negatives),
        Setting("pmc", {"n_samples": 1000, "n_iterations": 20, "variant": "thesis2"},
                "options of the PMC run giving the evolved set",
                check=lambda opts: check_sampler_options("pmc", opts)),
        Setting("grid_samples", 1000, "points of the unevolved grid set", check=positive),
        # ten iterations per seed (Table 8.12's header read literally), not the converged
        # reading lm_multiseed uses: converged LM costs 4-8 min per specimen (~10 core-hours
        # for the benchmark) for one column; --set 'lm={"n_seeds": 512}' runs it
        Setting("lm", {"n_seeds": 512, "max_iterations": 10},
                "options of the multiple-seed LM run",
                check=lambda opts: check_sampler_options("lm_multiseed", opts)),
        Setting("grid_power", 1e-4, "power λ on the unevolved grid set's target weights "
                "(p^λ on the uniform grid: an exact tempering; 1 is the thesis's weighting)",
                check=_unit_power, summary_only=True),
        Setting("evolved_weights", "auto", "weights of the final PMC cloud: uniform, the "
                "sampler's own (for PMC (II) its π, the thesis's sets), or auto (uniform for "
                "PMC (II), the sampler's importance weights for the other variants)",
                choices=EVOLVED_WEIGHTS, summary_only=True),
        Setting("agmmp_sigmas", list(AGMMP_SIGMAS), "kernel widths of the AGMMP distance "
                "columns", check=positive, summary_only=True),
        Setting("extra_distances", ["matusita", "sliced_wasserstein"],
                "further registered distances to tabulate", choices=_distance_names,
                summary_only=True),
        Setting("summary_jobs", -1, "joblib threads for the summary's pair loops (EMD, sliced "
                "Wasserstein; -1 = all cores); the numbers do not depend on it",
                check=lambda v: check_n_jobs("summary_jobs", v), summary_only=True),
    ],
    check=check_target_options,
    quick={"brdf": ["ward"], "material": [0, 1, 4], "specimen": [0, 1], "shape": [12, 12],
           "n_labels": 10, "pmc": {"n_samples": 64, "n_iterations": 5, "variant": "thesis2"},
           "grid_samples": 64, "lm": {"n_seeds": 8, "max_iterations": 10}},
    trial=trial,
    summarise=summarise,
    grid=("brdf", "material", "specimen"),
)
