"""How often scipy's default LM budget binds: one scene, a few seeds, MINPACK's outcome per seed.

Wraps ``scipy.optimize.least_squares`` to keep each seed's ``nfev``, ``njev`` and
``status`` (0: the budget of 100·d residual evaluations ran out), runs the study's
``lm_multiseed`` on one ``lm_multiseed`` scene (problem seed 12345) with ``n_seeds``
evenly spaced seeds, and prints the counts and every seed's optimum, best LM error first.

Usage::

    NUMBA_NUM_THREADS=1 python docs/results/lm_multiseed/readings/budget_probe.py phong 10 64
    # the same with a budget of 3000 evaluations (max_nfev) in place of scipy's 300:
    NUMBA_NUM_THREADS=1 python docs/results/lm_multiseed/readings/budget_probe.py phong 10 64 3000
"""

from __future__ import annotations

import sys
import time

import numpy as np
import scipy.optimize as so

import mrfpe
from mrfpe.experiments.problems import problem_from_config
from mrfpe.study import get, resolve_config


def main(brdf: str, labels: int, n_seeds: int, max_nfev: int = 0) -> None:
    """Print the budget statistics of one scene (module docstring)."""
    cfg = resolve_config(get("lm_multiseed"), quick=False,
                         overrides=[f'brdf=["{brdf}"]', f"n_labels={labels}"])
    prob = problem_from_config(dict(cfg, brdf=brdf, n_labels=labels), 12345)
    stats = []
    least_squares = so.least_squares

    def recording(fun, z0, *args, **kwargs):
        res = least_squares(fun, z0, *args, **kwargs)
        stats.append((np.sin(z0).copy(), res.nfev, res.njev, res.status))
        return res

    so.least_squares = recording  # multiseed imports it from scipy.optimize at call time
    try:
        t0 = time.perf_counter()
        post = mrfpe.sample("lm_multiseed", prob.target, seed=1, n_seeds=n_seeds,
                            max_nfev=max_nfev)
        wall = time.perf_counter() - t0
    finally:
        so.least_squares = least_squares
    # concurrent seeds finish out of order: match each record to its seed by the start,
    # sin z0 = 2 (theta0 - lo) / (hi - lo) - 1 (the sine transform)
    lo, hi = prob.target.bounds[:, 0], prob.target.bounds[:, 1]
    start = 2.0 * (post["seed_theta"].values - lo) / (hi - lo) - 1.0
    s = np.empty((n_seeds, 3))
    for sz, *rest in stats:
        s[np.argmin(np.abs(start - sz).sum(axis=1))] = rest
    assert np.array_equal(s[:, 2], post["status"].values)  # the sampler's own record agrees
    status, counts = np.unique(s[:, 2].astype(int), return_counts=True)
    print(f"{brdf}, {labels} labels, {n_seeds} seeds, max_nfev {max_nfev or 'scipy default'}: "
          f"{wall:.1f} s, "
          f"{wall / s[:, 0].sum() * 1e3:.2f} ms per residual-and-Jacobian pass")
    print(f"evaluations per seed: median {np.median(s[:, 0]):.0f}, mean {s[:, 0].mean():.1f}; "
          f"Jacobians: median {np.median(s[:, 1]):.0f}; status counts "
          f"{dict(zip(status.tolist(), counts.tolist()))} (0: at the budget)")
    theta, cost = post["theta"].values, post["lm_cost"].values
    for i in np.argsort(cost):
        print(f"status {int(s[i, 2])}  evals {int(s[i, 0]):3d}  theta {np.round(theta[i], 4)}  "
              f"seed {np.round(post['seed_theta'].values[i], 3)}  lm error {cost[i]:.6g}  "
              f"-> truth {np.linalg.norm(theta[i] - prob.truth):.3f}")
    print("truth", np.round(prob.truth, 4))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), *map(int, sys.argv[4:5]))
