"""The LM budget of Table 8.12 ("512 seeds, 10 iterations"): 10 iterations or convergence?

Reruns committed ``lm_multiseed`` trials (same scene, same seeds) with each seed's LM run to
convergence (``lm_options = {}``) and prints, per scene, the best-of-512 distances to the
truth under both budgets, the target evaluations and the time. Usage (from the repository
root)::

    python docs/results/lm_multiseed/readings/budget.py 'brdf=ward,n_labels=20' 6 >> \
        docs/results/lm_multiseed/readings/budget.jsonl
"""

import glob
import json
import sys
import time
import warnings

import xarray as xr

from mrfpe.experiments import lm_multiseed as m

warnings.filterwarnings("ignore")
cell, n = sys.argv[1], int(sys.argv[2])
files = sorted(glob.glob(f"docs/results/lm_multiseed/trials/{cell},repeat=*.nc"))[:n]
for f in files:
    old = xr.open_dataset(f)
    cfg = json.loads(old.attrs["trial_config"])
    cfg["lm_options"] = {}
    t0 = time.perf_counter()
    new = m.trial(cfg, int(old.attrs["repeat"]), int(old.attrs["seed"]))
    row = {"cell": cell, "repeat": int(old.attrs["repeat"]),
           "maximiser_to_truth": float(old["maximiser_to_truth"])}
    for name, ds in (("10_iterations", old), ("converged", new)):
        for r in ("lm_cost", "pseudolikelihood"):
            row[f"{name}_{r}_512"] = float(ds["best_to_truth"].sel(ranking=r)[-1])
            row[f"{name}_{r}_64"] = float(ds["best_to_truth"].sel(ranking=r)[63])
        row[f"{name}_evals"] = float(ds["n_target_evals"])
    row["converged_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(row), flush=True)
