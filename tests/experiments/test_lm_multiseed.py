"""The lm_multiseed study's summaries over trials with and without per-seed MINPACK stats."""

from __future__ import annotations

import numpy as np
import xarray as xr

from mrfpe.experiments.lm_multiseed import budget_share, mean_over_scenes


def _trial(dist: float, status: list[int] | None) -> xr.Dataset:
    ds = xr.Dataset({"best_to_truth": (("subset_size",), np.full(3, dist))},
                    coords={"subset_size": [1, 2, 3]})
    if status is not None:
        ds["status"] = ("seed", np.array(status, dtype=np.int8))
        ds["n_evals"] = ("seed", np.full(len(status), 7, dtype=np.int32))
    return ds


def test_mean_over_scenes_mixes_trials_with_and_without_seed_stats():
    old, new = _trial(0.2, None), _trial(0.4, [0, 2, 3, 0])
    mean = mean_over_scenes([old, new])
    np.testing.assert_allclose(mean["best_to_truth"].values, 0.3)
    assert "status" not in mean


def test_budget_share_counts_status_zero_over_the_scenes_that_record_it():
    group = [_trial(0.1, None), _trial(0.1, [0, 2, 3, 0]), _trial(0.1, [1, 0, 2, 2])]
    assert budget_share(group) == "37.5 % (2 scenes)"
    assert budget_share([_trial(0.1, [0, 2])]) == "50.0 % (1 scene)"
    assert budget_share([_trial(0.1, None)]) == "—"
