"""The classification benchmark's specimens with calibrated posteriors beside exp(PL_s)'s.

For every specimen of ``../classification`` (12 materials x 4 specimens per BRDF model,
20 labels; the scene built by :func:`mrfpe.experiments.classification.specimen_scene` from
the committed trial file's seed, as the study builds it, but at :data:`SHAPE` pixels) this
computes

* ``pl``        PMC (:data:`PMC`) on the study's target ``pls`` (7.5-7.7): the
                pseudo-posterior exp(PL_s) itself, untempered;
* ``adjusted``  the BRDF model's ``"pl_adjusted"`` target with ``prior="range"`` (it
                calibrates the same ``pls``; :class:`mrfpe.models.calibration.AdjustedPL`)
                built with :data:`CALIBRATION`, and PMC (:data:`PMC`) on it.

The classification study's scenes are 100 x 100 pixels; there the label chain's
autocorrelation time was 29 sweeps (one Ward specimen), so one Monte Carlo MLE round of
100 draws took 4600 sweeps and ~5 minutes, about 16 core-hours for the 96 specimens.
At 50 x 50 a specimen took a median 1.5 minutes (at most 9).

It records both final clouds (particles, log weights, MAP), the calibration (MPLE, the
adjusted mode, ``W``, Fisher information, the PL's Hessian, the simulator's
autocorrelation time, sweeps), the PMC diagnostics and wall times. One netCDF per
specimen in ``trials/``; a file that exists is skipped, so an interrupted run resumes;
``--shard k n`` takes every n-th specimen from the k-th (``--reverse`` from the shard's end,
for a second process on an unfinished shard). A specimen whose calibration
is refused (an MPLE on the box's face, a singular Fisher information) is recorded
with the reason and its ``pl`` cloud; one whose calibrated target PMC could not sample
(``adjusted_failed``) with the reason, its ``pl`` cloud and its calibration.

    python docs/results/calibrated_classification/run.py --shard 0 2   # and --shard 1 2
    python docs/results/calibrated_classification/run.py --shape 100 100 --shard 0 2  # full size
    python docs/results/calibrated_classification/run.py --refresh-adjusted --shard 0 2  # after
        # a change to the calibrated target's density: its clouds, from the saved calibrations
    python docs/results/calibrated_classification/report.py
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import mrfpe
from mrfpe.experiments.classification import specimen_scene
from mrfpe.models.calibration import AdjustedPL
from mrfpe.netcdf import write_atomic

HERE = Path(__file__).resolve().parent
TRIALS = HERE / "trials"
SOURCE = HERE.parent / "classification"
#: Image size of every specimen (the classification study's is 100 x 100).
SHAPE = (50, 50)
#: ``pl_adjusted`` options: one Monte Carlo MLE round of 100 draws at the MPLE (the Fisher
#: information's sd ratios then carry ~7 % Monte Carlo error; a second round doubled the
#: cost), its pilot chain at least 500 sweeps (and 50 tau) long.
CALIBRATION = {"n_draws": 100, "max_rounds": 1, "pilot_sweeps": 500}
#: PMC options for both posteriors (1000 particles left a third of the exp(PL_s) runs
#: flagged unreliable at 50 x 50).
PMC = {"n_samples": 4000}


def specimens(config: dict) -> list[tuple[dict, int]]:
    """(cell, trial seed) of every committed classification trial, specimen by specimen: all
    materials and both models of specimen 0 first, so that a partial run covers every class."""
    out = []
    for path in sorted((SOURCE / "trials").glob("*.nc")):
        with xr.open_dataset(path) as ds:
            out.append((json.loads(ds.attrs["cell"]), int(ds.attrs["seed"])))
    return sorted(out, key=lambda cs: (cs[0]["specimen"], cs[0]["material"], cs[0]["brdf"]))


def cloud(post: xr.Dataset, prefix: str) -> dict:
    """A PMC posterior's final cloud and diagnostics as Dataset variables/attributes."""
    return {f"{prefix}_theta": (("sample", "param"), post["theta"].values),
            f"{prefix}_log_weight": (("sample",), post["log_weight"].values),
            f"{prefix}_map": (("param",), post["map_theta"].values[-1]),
            f"{prefix}_time_s": ((), float(post.attrs["wall_time_s"])),
            f"{prefix}_reliable": ((), bool(post.attrs.get("diag_reliable", True)))}


def adjusted_cloud(adj: AdjustedPL, seed: int, attrs: dict) -> dict:
    """PMC's cloud of the calibrated target; where PMC cannot sample it (e.g. a support
    its start does not meet), no cloud and the reason in ``attrs["adjusted_failed"]``."""
    attrs.pop("adjusted_failed", None)
    try:
        return cloud(mrfpe.sample("pmc", adj, seed=seed, **PMC), "adjusted")
    except ValueError as err:
        attrs["adjusted_failed"] = str(err)
        return {}


def trial_seeds(seed: int) -> tuple[int, int, int]:
    """The seeds of a trial's exp(PL_s) cloud, calibrated cloud and calibration."""
    return tuple(int(s) for s in np.random.SeedSequence([seed, 7]).generate_state(3))


def trial_path(trials: Path, cell: dict) -> Path:
    return trials / "brdf={brdf},material={material},specimen={specimen}.nc".format(**cell)


def refresh_adjusted(config: dict, path: Path) -> bool:
    """Sample a trial's calibrated target again from its saved calibration (the map
    ``pl_mean``, ``W``, ``theta_adjusted``, ``theta_mple``), without simulating; False if
    the trial has no calibration."""
    ds = xr.load_dataset(path)
    if "refused" in ds.attrs:
        return False
    cell, seed = json.loads(ds.attrs["cell"]), int(ds.attrs["seed"])
    scene, _, _ = specimen_scene({**config, **cell}, seed, shape=tuple(json.loads(
        ds.attrs["shape"])))
    # the PL that pl_adjusted(prior="range") calibrated, mapped as it was saved
    pl = mrfpe.models.get("brdf").joint_pl(scene, prior="range")
    adj = AdjustedPL.restore(pl, centre=ds["pl_mean"].values, W=ds["W"].values,
                             theta_ml=ds["theta_adjusted"].values,
                             theta_pl=ds["theta_mple"].values)
    _, s_adj, _ = trial_seeds(seed)
    for name, (dims, value) in adjusted_cloud(adj, s_adj, ds.attrs).items():
        ds[name] = (dims, value)
    ds.attrs["adjusted_sampled_at"] = library_commit()
    write_atomic(ds, path)
    return True


def library_commit() -> str:
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, text=True,
                          capture_output=True, check=True).stdout.strip()


def run_one(config: dict, cell: dict, seed: int,
            shape: tuple[int, int] = SHAPE) -> xr.Dataset:
    scene, u, _ = specimen_scene({**config, **cell}, seed, shape=shape)
    s_pl, s_adj, s_cal = trial_seeds(seed)
    pl = mrfpe.targets.get(config["target"], scene, **config["target_options"])
    data = cloud(mrfpe.sample("pmc", pl, seed=s_pl, **PMC), "pl")
    attrs: dict = {"cell": json.dumps(cell), "seed": seed, "calibration": json.dumps(CALIBRATION),
                   "pmc": json.dumps(PMC), "shape": json.dumps(list(shape)),
                   "mrfpe_version": mrfpe.__version__}
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            adj = mrfpe.models.get("brdf").target("pl_adjusted", scene, prior="range",
                                                  seed=s_cal, **CALIBRATION)
    except ValueError as err:  # refused: recorded, not hidden
        attrs["refused"] = str(err)
    else:
        build_s = time.perf_counter() - t0
        data.update(adjusted_cloud(adj, s_adj, attrs))
        attrs["adjusted_sampled_at"] = library_commit()
        mle = adj.mle
        d2 = ("param", "param2")
        data.update({
            "theta_mple": (("param",), adj.theta_pl), "theta_adjusted": (("param",), adj.theta_ml),
            "W": (d2, adj.W), "fisher_information": (d2, adj.fisher_information),
            "pl_hessian": (d2, adj.pl_hessian), "pl_mean": (("param",), adj.centre),
            "pl_covariance": (d2, adj.pl_covariance), "build_time_s": ((), build_s),
            "simulation_sweeps": ((), adj.n_simulation_sweeps),
            "tau": ((), mle.draws.tau), "mle_rounds": ((), mle.n_iterations),
            "mle_converged": ((), mle.converged)})
    data["truth"] = (("param",), u)
    names = list(pl.param_names)
    return xr.Dataset(data, coords={"param": names, "param2": names}, attrs=attrs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shard", nargs=2, type=int, default=(0, 1), metavar=("K", "N"))
    ap.add_argument("--shape", nargs=2, type=int, default=SHAPE, metavar=("H", "W"),
                    help=f"image size (default {SHAPE[0]} {SHAPE[1]})")
    ap.add_argument("--trials", type=Path, default=None,
                    help="where the trial files go (default trials/, or trials_HxW/ for "
                         "another --shape)")
    ap.add_argument("--refresh-adjusted", action="store_true",
                    help="sample the calibrated targets of existing trials again from their "
                         "saved calibration (after a library change to the target's density)")
    ap.add_argument("--limit", type=int, default=None, help="at most this many specimens")
    ap.add_argument("--reverse", action="store_true",
                    help="take the shard from its end (a second process on an unfinished shard)")
    args = ap.parse_args()
    config = json.loads((SOURCE / "config.json").read_text())["config"]
    shape = tuple(args.shape)
    if args.trials is None:
        args.trials = TRIALS if shape == SHAPE else HERE / f"trials_{shape[0]}x{shape[1]}"
    args.trials.mkdir(exist_ok=True)
    todo = specimens(config)[args.shard[0]::args.shard[1]]
    todo = (todo[::-1] if args.reverse else todo)[:args.limit]
    if args.refresh_adjusted:
        head = library_commit()
        for cell, _ in todo:
            path = trial_path(args.trials, cell)
            with xr.open_dataset(path) as ds:
                if ds.attrs.get("adjusted_sampled_at") == head:
                    continue
            t0 = time.perf_counter()
            if refresh_adjusted(config, path):
                print(f"{path.name}: calibrated cloud sampled again at {head} in "
                      f"{time.perf_counter() - t0:.0f} s", flush=True)
        return
    for cell, seed in todo:
        path = trial_path(args.trials, cell)
        if path.exists():
            continue
        t0 = time.perf_counter()
        ds = run_one(config, cell, seed, shape)
        ds.attrs["wall_time_s"] = time.perf_counter() - t0
        write_atomic(ds, path)
        print(f"{path.name}: {ds.attrs['wall_time_s']:.0f} s"
              + (f" (refused: {ds.attrs['refused']})" if "refused" in ds.attrs else ""),
              flush=True)


if __name__ == "__main__":
    sys.exit(main())
