"""The dw_convergence study's spread table over scenes."""

from __future__ import annotations

import json

import numpy as np
import xarray as xr

from mrfpe.experiments.dw_convergence import spread_table


def _trial(final: tuple[float, float]) -> xr.Dataset:
    trace = np.stack([np.full(2, 0.6), np.array(final)], axis=1)  # (sampler, step)
    return xr.Dataset({"map_to_truth": (("sampler", "step"), trace)},
                      coords={"sampler": ["dw_r", "dw_q"], "step": [1, 50]},
                      attrs={"cell": json.dumps({"brdf": "ward", "n_labels": 10})})


def test_spread_table_gives_median_quartiles_and_share_within_the_thesis_level():
    finals = [0.02, 0.05, 0.08, 0.5]  # one stuck chain: mean 0.1625, median 0.065
    results = [_trial((d, 0.3)) for d in finals]
    config = {"n_steps": 50, "samplers": ["dw_r", "dw_q"]}
    rows = spread_table(results, config).splitlines()[2:]
    r = [c.strip() for c in rows[0].strip("|").split("|")]
    assert r[:4] == ["dw_r", "ward", "10", "4"]
    assert r[4] == f"0.16 ± {np.std(finals, ddof=1):.2f}"
    q1, med, q3 = np.percentile(finals, [25, 50, 75])
    assert r[5] == f"{med:.3f}" and r[6] == f"{q1:.3f}–{q3:.3f}"
    assert r[7] == "3 / 4"
    q = [c.strip() for c in rows[1].strip("|").split("|")]
    assert q[0] == "dw_q" and q[7] == "0 / 4"
