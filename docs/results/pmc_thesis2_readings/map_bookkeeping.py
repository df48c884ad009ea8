"""Which particle is the thesis's MAP (7.4.1 step 6)? Ward 20 labels, ``thesis2``.

On the study's first scenes (same seeds as its trials), per iteration: the particle of
highest resampling weight c = G^n (lowest pi = 1/G), of highest pi, and our best-so-far
under the full PL. Usage: ``python map_bookkeeping.py 12 > map_bookkeeping.jsonl``.
"""

import json
import sys
import warnings

import numpy as np

from mrfpe.experiments.problems import child_seeds, distance, problem_from_config, sample_traced
from mrfpe.study import get, resolve_config, tasks

warnings.filterwarnings("ignore")
study = get("pmc_convergence")
cfg = resolve_config(study, overrides=['brdf=["ward"]', "n_labels=20"])
out = []
for task in tasks(study, cfg)[: int(sys.argv[1])]:
    c = {**task.config, "maximiser_grid": None}
    s_problem, s_runs = child_seeds(task.seed, 2)
    prob = problem_from_config(c, s_problem)
    run_seeds = child_seeds(s_runs, 2 * 3)
    row = {}
    for j, n in enumerate([1000, 125, 64]):  # variant index 0 = thesis2: same seeds as the study
        post, _ = sample_traced("pmc", prob.target, run_seeds[j], n_samples=n, n_iterations=20,
                                variant="thesis2", initial="grid", keep_history=True)
        lw = post["history_log_weight"].values
        th = post["history_theta"].values
        lo = np.argmin(np.where(np.isfinite(lw), lw, np.inf), axis=1)
        hi = np.argmax(np.where(np.isfinite(lw), lw, -np.inf), axis=1)
        r = np.arange(lw.shape[0])
        row[n] = {"cmap": distance(th[r, lo], prob.truth).tolist(),
                  "pimap": distance(th[r, hi], prob.truth).tolist(),
                  "best": distance(post["map_theta"].values, prob.truth).tolist()}
    out.append(row)
    print(json.dumps(row), flush=True)
