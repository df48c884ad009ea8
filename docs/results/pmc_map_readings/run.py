"""Which particle is 7.4.1 step 6's "MAP sample"? Four readings on the study's own scenes.

The thesis takes, at every iteration, "the sample θ with the highest probability weight π"
(7.4.1 step 6) and says (7.4.2) "we could easily adjust the PMC sampler to store the best MAP
sample through all the iterations": its MAP was *not* best-so-far. During the iterations its
PMC evaluates only the sub-lattice PLs ("the PMC method uses the pseudolikelihood over all
sites on the lattice (Eqn. 7.7) only at the end of 20 iterations"). This script reruns PMC (II)
(``variant="thesis2"``, from the grid from face to face) on the scenes of
``../pmc_convergence_faces/trials`` with the same run seeds and records, per iteration, the
distance to the truth of

* ``best_so_far``: our MAP, best under the full PL over the iterations' candidates (must equal
  the committed trial's ``map_to_truth``, a check of the pairing);
* ``top_pi``: the highest π = 1/G^n (the study's ``pimap``; the final iteration ePL/G);
* ``top_g``: the highest G^n among the current particles, i.e. the highest resampling weight
  (the final iteration: the highest ePL/G, the thesis's final π);
* ``top_pl``: the highest full PL among the current particles (not best-so-far).

Writes one netCDF per scene to ``scenes/`` (resumes), then prints the mean per reading beside
the thesis's Table 7.1 column. Usage (from the repository root)::

    python docs/results/pmc_map_readings/run.py [n_scenes] [brdf] [n_labels]
"""

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import mrfpe
from mrfpe.experiments._thesis import PMC_TABLES
from mrfpe.experiments.pmc_convergence import variant_options
from mrfpe.experiments.problems import child_seeds, distance, highest_weight, problem_from_config

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parent / "pmc_convergence_faces" / "trials"
READINGS = ("best_so_far", "top_pi", "top_g", "top_pl")
ITERATIONS = (1, 5, 10, 15, 20)


def mean_se(values: np.ndarray, iterations: tuple[int, ...], sign: str = "") -> str:
    """Table cells ``mean ± standard error`` over scenes (axis 0) at the given iterations."""
    m = values.mean(axis=0)
    se = values.std(axis=0, ddof=1) / np.sqrt(values.shape[0])
    return " | ".join(f"{m[i - 1]:{sign}.3f} ± {se[i - 1]:.3f}" for i in iterations)


def one_scene(path: Path) -> xr.Dataset:
    """Rerun the trial at ``path`` (its PMC (II) runs only) and score the four readings."""
    with xr.open_dataset(path) as ds:
        config, seed = json.loads(ds.attrs["trial_config"]), int(ds.attrs["seed"])
        committed = ds["map_to_truth"].sel(variant="thesis2").values
    variants, sizes, T = config["variants"], config["n_samples"], config["n_iterations"]
    i = variants.index("thesis2")
    s_problem, s_runs = child_seeds(seed, 2)
    prob = problem_from_config({**config, "maximiser_grid": None}, s_problem)
    run_seeds = child_seeds(s_runs, len(variants) * len(sizes))
    out = np.full((len(READINGS), len(sizes), T), np.nan)
    for j, n in enumerate(sizes):
        post = mrfpe.sample("pmc", prob.target, seed=run_seeds[i * len(sizes) + j],
                            n_samples=n, n_iterations=T, variant="thesis2", keep_history=True,
                            **variant_options(config["pmc_options"], "thesis2"))
        x, lw = post["history_theta"].values, post["history_log_weight"].values
        steps = np.arange(T)
        top_pi = highest_weight(post)
        # iterations before the last: π = 1/G, so the highest G is the lowest finite π;
        # the last iteration's π is already ePL/G (the thesis's final weights)
        top_g = x[steps, np.argmin(np.where(np.isfinite(lw), lw, np.inf), axis=1)]
        top_g[-1] = top_pi[-1]
        pl = prob.target.log_prob(x.reshape(-1, x.shape[-1])).reshape(x.shape[:2])
        top_pl = x[steps, np.argmax(np.where(np.isnan(pl), -np.inf, pl), axis=1)]
        for r, theta in enumerate((post["map_theta"].values, top_pi, top_g, top_pl)):
            out[r, j] = distance(theta, prob.truth)
    if not np.allclose(out[0], committed, atol=1e-9):
        raise RuntimeError(f"{path.name}: best-so-far differs from the committed trial")
    return xr.Dataset({"map_to_truth": (("reading", "n_samples", "iteration"), out)},
                      coords={"reading": list(READINGS), "n_samples": sizes,
                              "iteration": np.arange(1, T + 1)},
                      attrs={"source": path.name, "seed": seed,
                             "trial_config": json.dumps(config, sort_keys=True)})


def main() -> None:
    warnings.simplefilter("ignore", mrfpe.PosteriorWarning)  # ESS ≈ 1 is PMC (II)'s, known
    n_scenes = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    brdf = sys.argv[2] if len(sys.argv) > 2 else "ward"
    labels = int(sys.argv[3]) if len(sys.argv) > 3 else 20
    (HERE / "scenes").mkdir(exist_ok=True)
    sources = sorted(SOURCE.glob(f"brdf={brdf},n_labels={labels},repeat=*.nc"))[:n_scenes]
    results = []
    for path in sources:
        dest = HERE / "scenes" / path.name
        if not dest.exists():
            tmp = dest.with_suffix(".tmp")
            one_scene(path).to_netcdf(tmp)
            tmp.rename(dest)
            print("done", path.name, flush=True)
        with xr.open_dataset(dest) as ds:
            results.append(ds["map_to_truth"].values)
            sizes = [int(n) for n in ds["n_samples"].values]
    res = np.array(results)
    print(f"\n{brdf}, {labels} labels, {len(results)} scenes: mean MAP → truth "
          "(± standard error over scenes)\n")
    print("| N | reading | " + " | ".join(f"it {i}" for i in ITERATIONS) + " |")
    print("|---|---|" + "---|" * len(ITERATIONS))
    for j, n in enumerate(sizes):
        ref = PMC_TABLES[(brdf, labels, n)][0]
        print(f"| {n} | thesis | " + " | ".join(f"{ref[i - 1]:.3f}" for i in ITERATIONS) + " |")
        for r, name in enumerate(READINGS):
            print(f"| {n} | {name} | {mean_se(res[:, r, j], ITERATIONS)} |")
    print("\nPaired difference top_g − best_so_far (mean ± standard error over scenes)\n")
    print("| N | " + " | ".join(f"it {i}" for i in ITERATIONS[1:]) + " |")
    print("|---|" + "---|" * len(ITERATIONS[1:]))
    for j, n in enumerate(sizes):
        print(f"| {n} | {mean_se(res[:, 2, j] - res[:, 0, j], ITERATIONS[1:], '+')} |")

if __name__ == "__main__":
    main()
