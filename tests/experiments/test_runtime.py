"""The runtime study's time column and its LM ÷ PMC ratios over scenes."""

from __future__ import annotations

import json

import numpy as np
import xarray as xr

from mrfpe.experiments.runtime import _with_range, ratio_table
from mrfpe.study import by_cell

RUNS = ["pmc", "pmc_thesis2", "dw_r", "lm_multiseed"]


def _trial(labels: int, seconds: list[float]) -> xr.Dataset:
    return xr.Dataset({"wall_time_s": (("run",), np.array(seconds))}, coords={"run": RUNS},
                      attrs={"cell": json.dumps({"n_labels": labels})})


def test_time_column_gives_the_mean_and_the_range_in_the_means_unit():
    assert _with_range(np.array([7.0])) == "7 s"
    assert _with_range(np.array([6.0, 8.0, 10.0])) == "8 s (6–10)"
    assert _with_range(np.array([180.0, 240.0])) == "3.5 min (3–4)"


def test_ratio_table_takes_ratios_per_scene_beside_the_theses_columns():
    cells = by_cell([_trial(10, [4, 8, 30, 160]), _trial(10, [5, 10, 20, 300])], "n_labels")
    rows = [[c.strip() for c in r.strip("|").split("|")]
            for r in ratio_table(cells, RUNS, thesis_size=True).splitlines()[2:]]
    lm_pmc2, lm_pmc, dw_pmc2 = rows
    # per scene: 160/8 = 20 and 300/10 = 30 -> mean 25 (not 460/18 = 25.6 of the means)
    assert lm_pmc2 == ["lm_multiseed ÷ pmc_thesis2", "10", "2", "25× (20–30)", "19.5×"]
    assert lm_pmc[3] == "50× (40–60)" and dw_pmc2[3] == "2.88× (2–3.75)"
    assert dw_pmc2[4] == "2.25×"  # the thesis's 9 min / 4 min
    no_ref = ratio_table(cells, RUNS, thesis_size=False).splitlines()[2]
    assert no_ref.rstrip(" |").endswith("–")
