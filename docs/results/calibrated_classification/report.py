"""Miss / WNN / NN1 with exp(PL_s) posteriors and with calibrated ones; what calibration moved.

Reads ``trials/`` (written by ``run.py``) and writes ``report.md``. Only specimens with both
clouds enter the classification tables (a refused calibration is listed, and the tables say
how many specimens they cover); classes are the materials, as in ``../classification``.
Moments (mean, sd) come from the weighted PMC clouds; the distances compare
:data:`SET_SIZE` equally weighted points drawn from each cloud by systematic resampling
(the size of the classification study's sets; exact EMD between 4000-point sets would
take hours).

    python docs/results/calibrated_classification/report.py [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.classify import error_stats, knn_accuracy, similarity_matrix
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
    names = [str(p) for p in ds["param"].values]
    return xr.Dataset({"theta": (("sample", "param"), ds[f"{prefix}_theta"].values),
                       "log_weight": (("sample",), ds[f"{prefix}_log_weight"].values),
                       "map_theta": (("step", "param"), ds[f"{prefix}_map"].values[None])},
                      coords={"param": names})


def feature_set(ds: xr.Dataset, prefix: str) -> xr.Dataset:
    """:data:`SET_SIZE` equally weighted points of the cloud (systematic resampling, seed 0)."""
    post = posterior(ds, prefix)
    idx = resample(post["log_weight"].values, SET_SIZE, "systematic", rng=0)
    return post.isel(sample=idx).assign(log_weight=("sample", np.zeros(SET_SIZE)))


def load() -> list[xr.Dataset]:
    out = []
    for path in sorted((HERE / "trials").glob("*.nc")):
        with xr.open_dataset(path) as ds:
            out.append(ds.load())
    return out


def shifts(group: list[xr.Dataset]) -> list[list]:
    """Per parameter: how far calibration moved the mean (in exp(PL) sd) and scaled the sd."""
    names = [str(p) for p in group[0]["param"].values]
    z, ratio, err_pl, err_adj = [], [], [], []
    for ds in group:
        a, b = posterior(ds, "pl"), posterior(ds, "adjusted")
        sd_a, sd_b = np.sqrt(np.diag(weighted_cov(a))), np.sqrt(np.diag(weighted_cov(b)))
        z.append((weighted_mean(b) - weighted_mean(a)) / sd_a)
        ratio.append(sd_b / sd_a)
        truth = ds["truth"].values
        err_pl.append(np.abs(weighted_mean(a) - truth) / sd_a)
        err_adj.append(np.abs(weighted_mean(b) - truth) / sd_b)
    z, ratio, err_pl, err_adj = map(np.array, (z, ratio, err_pl, err_adj))

    def span(v: np.ndarray) -> str:
        return f"{np.median(v):.2f} [{v.min():.2f}, {v.max():.2f}]"

    return [[n, span(z[:, j]), span(ratio[:, j]), span(err_pl[:, j]), span(err_adj[:, j])]
            for j, n in enumerate(names)]


def classification(group: list[xr.Dataset], jobs: int) -> str:
    classes = np.array([json.loads(ds.attrs["cell"])["material"] for ds in group])
    rows = []
    for label, name, params in COLUMNS:
        row = [label]
        for prefix in ("pl", "adjusted"):
            S = similarity_matrix([feature_set(ds, prefix) for ds in group], name,
                                  n_jobs=jobs, **params)
            st = error_stats(S, classes)
            row += [f"{st['miss']} / {st['wnn']} / {st['nn1']}",
                    f"{knn_accuracy(S, classes):.2f}"]
        rows.append(row)
    return markdown_table(["distance", "exp(PL_s): Miss / WNN / NN1", "1-NN acc.",
                           "calibrated: Miss / WNN / NN1", "1-NN acc."], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1, help="processes for the pair loops")
    args = ap.parse_args()
    trials = load()
    sections = []
    for brdf in ("ward", "phong"):
        group = [ds for ds in trials if json.loads(ds.attrs["cell"])["brdf"] == brdf]
        refused = [ds for ds in group if "refused" in ds.attrs]
        both = sorted((ds for ds in group if "refused" not in ds.attrs),
                      key=lambda ds: (json.loads(ds.attrs["cell"])["material"],
                                      json.loads(ds.attrs["cell"])["specimen"]))
        if not both:
            continue
        cost = np.array([[ds["build_time_s"].item(), ds["simulation_sweeps"].item(),
                          ds["tau"].item(), ds["mle_rounds"].item()] for ds in both])
        ess_pl = np.median([ess(posterior(ds, "pl")) for ds in both])
        ess_adj = np.median([ess(posterior(ds, "adjusted")) for ds in both])
        unreliable = sum(not bool(ds[f"{p}_reliable"]) for ds in both for p in ("pl", "adjusted"))
        sections.append(
            f"## {brdf}\n\n{len(group)} specimens computed, {len(both)} calibrated, "
            f"{len(refused)} refused"
            + "".join(f"\n- {json.loads(ds.attrs['cell'])}: {ds.attrs['refused']}"
                      for ds in refused)
            + f"\n\nCalibration per specimen (median [min, max]): build "
            f"{np.median(cost[:, 0]):.0f} s [{cost[:, 0].min():.0f}, {cost[:, 0].max():.0f}], "
            f"{np.median(cost[:, 1]):.0f} simulation sweeps, autocorrelation time "
            f"{np.median(cost[:, 2]):.1f} [{cost[:, 2].min():.1f}, {cost[:, 2].max():.1f}] "
            f"sweeps, Monte Carlo MLE rounds {np.median(cost[:, 3]):.0f}. Kish ESS of the "
            f"clouds (median of 1000 particles): exp(PL_s) {ess_pl:.0f}, calibrated "
            f"{ess_adj:.0f}; PMC runs flagged unreliable: {unreliable} of {2 * len(both)}.\n\n"
            "What calibration changed, per parameter (median [min, max] over specimens): the "
            "mean's move in exp(PL_s) posterior sd, the sd ratio calibrated / exp(PL_s), and "
            "each posterior's distance from the material's true parameters in its own sd.\n\n"
            + markdown_table(["param", "mean move (PL sd)", "sd ratio", "|PL mean - truth| / sd",
                              "|calibrated mean - truth| / sd"], shifts(both))
            + f"\n\nClassification of the {len(both)} calibrated specimens "
            f"({len(set(json.loads(ds.attrs['cell'])['material'] for ds in both))} materials; "
            "lower Miss / WNN / NN1 is better):\n\n" + classification(both, args.jobs))
    write_report(HERE, "Classification with calibrated posteriors", sections)


if __name__ == "__main__":
    main()
