"""The classification study's summary: ESS of the feature sets and the grid tempering."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import xarray as xr

from mrfpe.experiments.classification import STUDY, summarise


def _fake_trial(material: int, specimen: int, rng: np.random.Generator) -> xr.Dataset:
    centre = np.array([0.2, 0.5, 0.8])[material] * np.ones(3)
    grid = np.random.default_rng(1).random((200, 3))  # one grid for all, as the study
    lt = -5e3 * np.sum((grid - centre) ** 2, axis=1)  # a sharp, PL-like peak: ESS ~ 1
    lw = lt - np.logaddexp.reduce(lt)
    ev = centre + 0.01 * rng.normal(size=(100, 3))
    pi = np.where(np.arange(100) == 0, 0.0, -50.0)  # PMC (II)'s pi: one particle dominates
    ds = xr.Dataset(
        {"evolved_theta": (("evolved_sample", "param"), ev),
         "evolved_log_weight": (("evolved_sample",), pi - np.logaddexp.reduce(pi)),
         "evolved_map": (("param",), ev[0]),
         "grid_theta": (("grid_sample", "param"), grid),
         "grid_log_weight": (("grid_sample",), lw),
         "lm_best": (("param",), centre), "truth": (("param",), centre)},
        coords={"param": ["a", "b", "c"]})
    ds.attrs["cell"] = json.dumps({"brdf": "ward", "material": material, "specimen": specimen})
    return ds


def _ess_row(report: str, kind: str, setting: str) -> list[str]:
    """The ESS table's row of set ``kind`` under ``setting`` (a power or a weighting)."""
    for line in report.splitlines():
        cols = [c.strip() for c in line.strip("|").split("|")]
        if cols[:2] == ["ward", kind] and cols[2].removesuffix(" ←") == setting:
            return cols
    raise AssertionError(f"no row {kind} / {setting}")


@pytest.mark.parametrize("lam", [1.0, 0.001])
def test_summary_reports_feature_ess_and_tempers_the_grid(tmp_path, lam):
    rng = np.random.default_rng(0)
    results = [_fake_trial(m, s, rng) for m in range(3) for s in range(2)]
    from mrfpe.study import resolve_config

    config = {**resolve_config(STUDY), "brdf": ["ward"], "grid_power": lam,
              "agmmp_sigmas": [0.1], "extra_distances": []}
    summarise(results, config, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "## Information in the feature sets" in report
    row = _ess_row(report, "unevolved", f"{lam:g}")
    assert row[2].endswith("←")  # the tables' setting is marked
    median = float(row[3])
    # independent route: Kish's ESS of the tempered, renormalised grid weights
    want = []
    for ds in results:
        w = np.exp(lam * ds["grid_log_weight"].values)
        want.append(w.sum() ** 2 / np.sum(w ** 2))
    assert median == pytest.approx(np.median(want), abs=0.06)
    assert (median < 2.0) if lam == 1.0 else (median > 50.0)
    assert re.fullmatch(r"\d+ / 6", row[5])
    for power in (1.0, 1e-2, 1e-3, 3e-4, 1e-4):  # the sweep is always there
        _ess_row(report, "unevolved", f"{power:g}")
    uniform = _ess_row(report, "evolved", "uniform")
    own = _ess_row(report, "evolved", "sampler (π)")
    assert float(uniform[3]) == pytest.approx(100.0) and uniform[2].endswith("←")
    assert float(own[3]) == pytest.approx(1.0, abs=1e-6)
    assert float(uniform[6]) == pytest.approx(0.01, rel=0.2)  # the cloud's own spread


def test_defaults_temper_the_grid_and_flatten_the_cloud():
    from mrfpe.study import resolve_config, tasks

    cfg = resolve_config(STUDY)
    assert cfg["grid_power"] == 1e-4 and cfg["evolved_weights"] == "auto"
    from mrfpe.experiments.classification import _uniform_cloud

    assert _uniform_cloud(cfg)  # PMC (II): its pi are not importance weights
    assert not _uniform_cloud({**cfg, "pmc": {"variant": "mixture"}})
    assert not _uniform_cloud({**cfg, "pmc": {"n_samples": 10}})  # the sampler's default
    assert not _uniform_cloud({**cfg, "evolved_weights": "sampler"})
    summary = {"grid_power", "evolved_weights", "agmmp_sigmas", "extra_distances", "summary_jobs"}
    assert STUDY.summary_keys == summary
    assert not summary & set(tasks(STUDY, cfg)[0].config)  # trial files serve every choice


def test_grid_power_and_jobs_are_checked():
    from mrfpe.study import resolve_config

    with pytest.raises(ValueError, match="grid_power"):
        resolve_config(STUDY, overrides=["grid_power=1.5"])
    with pytest.raises(ValueError, match="summary_jobs"):
        resolve_config(STUDY, overrides=["summary_jobs=0"])
