"""Miss / WNN / NN1 with exp(PL_s) posteriors and with calibrated ones; what calibration moved.

Reads ``trials/`` (written by ``run.py``) and writes ``report.md``. Only specimens with both
clouds enter the classification tables (a refused calibration, or a calibrated target that
PMC could not sample, is listed, and the tables say how many specimens they cover); classes
are the materials, as in ``../classification``.
Each target's own moments are exp(PL_s)'s importance-sampled mean and covariance (which
the calibration maps) and the calibrated target's (θ_ML + δ, I⁻¹, by construction); the
distances compare :data:`SET_SIZE` equally weighted points drawn from each PMC cloud by
systematic resampling (the size of the classification study's sets; exact EMD between
4000-point sets would take hours), or from the normal with a target's own moments.

    python docs/results/calibrated_classification/report.py [--jobs 2]
    python docs/results/calibrated_classification/report.py --jobs 2 \
        --trials docs/results/calibrated_classification/trials_100x100 \
        --report docs/results/calibrated_classification/report_100x100.md
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.classify import error_stats, knn_accuracy, similarity_matrix
from mrfpe.experiments.classification import posterior_set
from mrfpe.experiments.writeup import markdown_table, write_report
from mrfpe.posterior import ess, weighted_cov, weighted_mean
from mrfpe.resampling import resample

HERE = Path(__file__).resolve().parent
#: Points per feature set in the distances.
SET_SIZE = 1000
#: The distance columns of the classification study's evolved-set tables (thesis 8.8-8.11).
COLUMNS = [("chernoff", "chernoff", {"alpha": 0.7}), ("bhattacharyya", "bhattacharyya", {}),
           ("kl", "kl", {}), ("symmetric_kl", "symmetric_kl", {}),
           ("patrick_fisher", "patrick_fisher", {}), ("mahalanobis", "mahalanobis", {}),
           ("map", "map_euclidean", {}), ("emd", "emd", {}), ("matusita", "matusita", {}),
           ("sliced_wasserstein", "sliced_wasserstein", {}),
           *[(f"agmmp:{s:g}", "agmmp", {"sigma": s}) for s in (0.1, 0.01, 0.005, 0.001)]]


def posterior(ds: xr.Dataset, prefix: str) -> xr.Dataset:
    return posterior_set(ds[f"{prefix}_theta"].values, ds[f"{prefix}_log_weight"].values,
                         [str(p) for p in ds["param"].values], ds[f"{prefix}_map"].values)


def feature_set(ds: xr.Dataset, prefix: str) -> xr.Dataset:
    """:data:`SET_SIZE` equally weighted points of the cloud (systematic resampling, seed 0)."""
    post = posterior(ds, prefix)
    idx = resample(post["log_weight"].values, SET_SIZE, "systematic", rng=0)
    return post.isel(sample=idx).assign(log_weight=("sample", np.zeros(SET_SIZE)))


def gaussian_set(ds: xr.Dataset, which: str) -> xr.Dataset:
    """:data:`SET_SIZE` points from the normal with the target's own centre and covariance
    (:func:`target_moments`), free of PMC's sampling error."""
    names = [str(p) for p in ds["param"].values]
    m = target_moments(ds)
    centre, cov = m[f"{which}_centre"], m[f"{which}_cov"]
    z = np.random.default_rng(0).standard_normal((SET_SIZE, centre.size))
    return posterior_set(centre + z @ np.linalg.cholesky(cov).T, np.zeros(SET_SIZE), names,
                         centre)


def load(trials: Path) -> list[xr.Dataset]:
    out = []
    for path in sorted(trials.glob("*.nc")):
        with xr.open_dataset(path) as ds:
            out.append(ds.load())
    return out


def target_moments(ds: xr.Dataset) -> dict[str, np.ndarray]:
    """Each target's own centre, covariance and sd: exp(PL_s)'s importance-sampled mean and
    covariance (``AdjustedPL.pl_covariance``) and the calibrated target's (θ_ML + δ, I⁻¹),
    which ``align="moments"`` gives it by construction."""
    out = {"pl_centre": ds["pl_mean"].values, "pl_cov": ds["pl_covariance"].values,
           "adj_centre": ds["theta_adjusted"].values,
           "adj_cov": np.linalg.inv(ds["fisher_information"].values)}
    out.update({f"{k}_sd": np.sqrt(np.diag(out[f"{k}_cov"])) for k in ("pl", "adj")})
    return out


def laplace_sd(ds: xr.Dataset) -> np.ndarray:
    """exp(PL_s)'s Laplace sd, from the PL's curvature at the MPLE (NaN where its negative
    Hessian is not positive definite)."""
    H = ds["pl_hessian"].values
    if not np.all(np.linalg.eigvalsh(H) > 0):
        return np.full(H.shape[0], np.nan)
    return np.sqrt(np.diag(np.linalg.inv(H)))


def cloud_against_target(ds: xr.Dataset, prefix: str) -> tuple[np.ndarray, np.ndarray]:
    """A PMC cloud (``"pl"`` or ``"adjusted"``) against its target's own moments
    (:func:`target_moments`): |weighted mean − centre| / sd, and weighted sd / sd."""
    m, cloud = target_moments(ds), posterior(ds, prefix)
    which = "pl" if prefix == "pl" else "adj"
    sd = m[f"{which}_sd"]
    return (np.abs(weighted_mean(cloud) - m[f"{which}_centre"]) / sd,
            np.sqrt(np.diag(weighted_cov(cloud))) / sd)


def span(v: np.ndarray) -> str:
    return f"{np.nanmedian(v):.2f} [{np.nanmin(v):.2f}, {np.nanmax(v):.2f}]"


def shifts(group: list[xr.Dataset]) -> list[list]:
    """Per parameter: the calibrated target's centre move and sd ratio against exp(PL_s)'s,
    each target's distance from the truth in its own sd, and each PMC cloud's weighted sd
    against its target's sd, and exp(PL_s)'s Laplace sd against its sd."""
    names = [str(p) for p in group[0]["param"].values]
    cols: dict[str, list] = {k: [] for k in ("move", "ratio", "err_pl", "err_adj", "pmc_pl",
                                              "pmc_adj", "laplace")}
    for ds in group:
        m, truth = target_moments(ds), ds["truth"].values
        cols["laplace"].append(laplace_sd(ds) / m["pl_sd"])
        cols["move"].append((m["adj_centre"] - m["pl_centre"]) / m["pl_sd"])
        cols["ratio"].append(m["adj_sd"] / m["pl_sd"])
        cols["err_pl"].append(np.abs(m["pl_centre"] - truth) / m["pl_sd"])
        cols["err_adj"].append(np.abs(m["adj_centre"] - truth) / m["adj_sd"])
        for prefix, key in (("pl", "pmc_pl"), ("adjusted", "pmc_adj")):
            cols[key].append(cloud_against_target(ds, prefix)[1])
    a = {k: np.array(v) for k, v in cols.items()}
    return [[n, *(span(a[k][:, j]) for k in cols)] for j, n in enumerate(names)]


def disagreements(group: list[xr.Dataset]) -> tuple[int, list[str]]:
    """Specimens whose exp(PL_s) cloud PMC calls reliable, and those among them whose cloud
    disagrees with the importance-sampled moments the calibration mapped: a weighted mean
    more than 0.5 of their sd away, or a weighted sd outside 0.77-1.3 times theirs (a mode
    the importance sampler, started at the MPLE, did not meet)."""
    rows = []
    reliable = [ds for ds in group if bool(ds["pl_reliable"])]
    for ds in reliable:
        z, r = cloud_against_target(ds, "pl")
        if z.max() > 0.5 or np.any((r < 0.77) | (r > 1.3)):
            rows.append(f"{json.loads(ds.attrs['cell'])}: mean {z.round(2).tolist()} sd off, "
                        f"sd ratio {r.round(2).tolist()}")
    return len(reliable), rows


def covered(group: list[xr.Dataset]) -> tuple[int, int]:
    """Specimens whose true parameters lie within 2 sd of the centre in every parameter,
    for exp(PL_s) and for the calibrated target."""
    hits = np.array([[np.all(np.abs(m["pl_centre"] - t) <= 2 * m["pl_sd"]),
                      np.all(np.abs(m["adj_centre"] - t) <= 2 * m["adj_sd"])]
                     for m, t in ((target_moments(ds), ds["truth"].values) for ds in group)])
    return int(hits[:, 0].sum()), int(hits[:, 1].sum())


def classification(group: list[xr.Dataset], jobs: int) -> str:
    """Miss / WNN / NN1 and 1-NN accuracy per distance, both kinds of posterior, from the PMC
    clouds and from each target's own moments; materials left with fewer than two calibrated
    specimens cannot be classified and are left out."""
    classes = np.array([json.loads(ds.attrs["cell"])["material"] for ds in group])
    keep = np.isin(classes, [c for c in set(classes.tolist()) if np.sum(classes == c) >= 2])
    group, classes = [ds for ds, k in zip(group, keep, strict=True) if k], classes[keep]
    out = [f"{len(group)} specimens of {len(set(classes.tolist()))} materials (materials with "
           f"fewer than two calibrated specimens left out); lower Miss / WNN / NN1 is better."]
    kinds = {"the PMC clouds": (lambda ds: feature_set(ds, "pl"),
                            lambda ds: feature_set(ds, "adjusted")),
             "each target's own moments (normal sets)": (lambda ds: gaussian_set(ds, "pl"),
                                                          lambda ds: gaussian_set(ds, "adj"))}
    for kind, makers in kinds.items():
        sets = [[make(ds) for ds in group] for make in makers]
        rows = []
        for label, name, params in COLUMNS:
            row = [label]
            for posts in sets:
                S = similarity_matrix(posts, name, n_jobs=jobs, **params)
                st = error_stats(S, classes)
                row += [f"{st['miss']} / {st['wnn']} / {st['nn1']}",
                        f"{knn_accuracy(S, classes):.2f}"]
            rows.append(row)
        out.append(f"### From {kind}\n\n" + markdown_table(
            ["distance", "exp(PL_s): Miss / WNN / NN1", "1-NN acc.",
             "calibrated: Miss / WNN / NN1", "1-NN acc."], rows))
    return "\n\n".join(out)


def reasons(group: list[xr.Dataset], key: str) -> str:
    """A markdown list of the specimens' cells and their ``key`` attribute."""
    return "".join(f"\n- {json.loads(ds.attrs['cell'])}: {ds.attrs[key]}" for ds in group)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1, help="processes for the pair loops")
    ap.add_argument("--trials", type=Path, default=HERE / "trials", help="the trial files")
    ap.add_argument("--report", type=Path, default=HERE / "report.md", help="the page written")
    args = ap.parse_args()
    trials = load(args.trials)
    sections = []
    for brdf in ("ward", "phong"):
        group = [ds for ds in trials if json.loads(ds.attrs["cell"])["brdf"] == brdf]
        refused = [ds for ds in group if "refused" in ds.attrs]
        failed = [ds for ds in group if "adjusted_failed" in ds.attrs]
        both = sorted((ds for ds in group if not {"refused", "adjusted_failed"} & set(ds.attrs)),
                      key=lambda ds: (json.loads(ds.attrs["cell"])["material"],
                                      json.loads(ds.attrs["cell"])["specimen"]))
        if not both:
            continue
        cost = np.array([[ds["build_time_s"].item(), ds["simulation_sweeps"].item(),
                          ds["tau"].item(), ds["mle_rounds"].item()] for ds in both])
        ess_pl = np.median([ess(posterior(ds, "pl")) for ds in both])
        ess_adj = np.median([ess(posterior(ds, "adjusted")) for ds in both])
        n_rel, off = disagreements(both)
        unreliable = sum(not bool(ds[f"{p}_reliable"]) for ds in both for p in ("pl", "adjusted"))
        sections.append(
            f"## {brdf}\n\n{len(group)} specimens computed, {len(both)} calibrated, "
            f"{len(refused)} refused" + reasons(refused, "refused")
            + (f"\n\n{len(failed)} calibrated, but PMC could not sample the calibrated target"
               + reasons(failed, "adjusted_failed") if failed else "")
            + f"\n\nCalibration per specimen (median [min, max]): build "
            f"{np.median(cost[:, 0]):.0f} s [{cost[:, 0].min():.0f}, {cost[:, 0].max():.0f}], "
            f"{np.median(cost[:, 1]):.0f} simulation sweeps, autocorrelation time "
            f"{np.median(cost[:, 2]):.1f} [{cost[:, 2].min():.1f}, {cost[:, 2].max():.1f}] "
            f"sweeps, Monte Carlo MLE rounds {np.median(cost[:, 3]):.0f}. Kish ESS of the "
            f"clouds (median, of {both[0].sizes['sample']} particles): exp(PL_s) {ess_pl:.0f}, "
            f"calibrated "
            f"{ess_adj:.0f}; PMC runs flagged unreliable: {unreliable} of {2 * len(both)}.\n\n"
            "What calibration changed, per parameter (median [min, max] over specimens), "
            "measured on the targets themselves: the centre's move in exp(PL_s) sd, the sd "
            "ratio calibrated / exp(PL_s), each target's distance from the material's true "
            "parameters in its own sd, each PMC cloud's weighted sd over its target's "
            "sd, and exp(PL_s)'s Laplace sd (the PL's curvature at the MPLE) over its sd "
            "(blank where the curvature is not negative definite).\n\n"
            + markdown_table(["param", "centre move (PL sd)", "sd ratio",
                              "|exp(PL_s) mean − truth| / its sd",
                              "|calibrated − truth| / its sd", "PMC sd / sd, exp(PL_s)",
                              "PMC sd / sd, calibrated", "Laplace sd / sd, exp(PL_s)"],
                             shifts(both))
            + "\n\nReliable exp(PL_s) clouds disagreeing with the moments the calibration "
            "mapped (a mean more than 0.5 sd off, or an sd ratio outside 0.77-1.3): "
            f"{len(off)} of {n_rel}" + "".join(f"\n- {r}" for r in off)
            + "\n\nTrue parameters within 2 sd of the centre in every parameter: "
            "exp(PL_s) {} of {n}, calibrated {} of {n}.".format(*covered(both), n=len(both))
            + "\n\nClassification: " + classification(both, args.jobs))
    write_report(args.report.parent, "Classification with calibrated posteriors", sections,
                 name=args.report.name)


if __name__ == "__main__":
    main()
