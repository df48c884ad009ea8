"""Every built-in study in ``--quick`` mode: trial files, report, figures and sanity checks."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from scipy.special import logsumexp

from mrfpe import study as S

BUILTIN = sorted(S.available())


@pytest.fixture
def one_numba_thread():
    """One numba thread per test process: with ``pytest -n 2`` on two cores, two-thread
    kernels oversubscribe the machine and single-point evaluations slow down ~10×."""
    numba = pytest.importorskip("numba")
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def triangle(ds: xr.Dataset, to_truth: str, to_max: str) -> None:
    """|d(MAP, truth) − d(MAP, max)| ≤ d(max, truth): the two distances are consistent."""
    gap = np.abs(ds[to_truth] - ds[to_max]).values
    # trials may store the distances in float32 (unit-cube distances < 2: rounding < 2.4e-7)
    slack = 5e-7 if ds[to_truth].dtype == np.float32 else 1e-9
    assert np.all(gap <= float(ds["maximiser_to_truth"]) + slack)


def check_importance_sampling(results, cfg):
    from mrfpe.experiments.importance_sampling import asymptotic_rmse

    for n in cfg["n_samples"]:
        err = np.stack([ds["error"].values for ds in results
                        if json.loads(ds.attrs["cell"])["n_samples"] == n])
        ratio = np.sqrt((err**2).sum(1).mean()) / asymptotic_rmse(
            np.asarray(cfg["mu"]), cfg["sigma"], cfg["proposal_sigma"], n)
        assert 0.5 < ratio < 2.0


def check_pmc_convergence(results, cfg):
    for ds in results:
        assert ds.sizes["iteration"] == cfg["n_iterations"]
        assert np.all((ds["map_to_truth"] >= 0) & (ds["map_to_truth"] <= np.sqrt(3)))
        assert np.all(ds["weight_var"] >= 0)
        assert np.all(np.diff(ds["n_target_evals"].values, axis=-1) > 0)
        triangle(ds, "map_to_truth", "map_to_maximiser")
        # the reference really is the global maximiser: no run found a better point
        assert np.all(ds["final_log_target"] <= ds["maximiser_log_prob"] + 1e-6)


def check_lm_multiseed(results, cfg):
    for ds in results:
        best = int(np.argmin(ds["lm_cost"].values))  # the full subset holds every optimum
        d = np.linalg.norm(ds["optimum"].values[best] - ds["truth"].values)
        assert ds["best_to_truth"].sel(ranking="lm_cost", subset_size=cfg["n_seeds"]) == \
            pytest.approx(d)
        triangle(ds, "best_to_truth", "best_to_maximiser")
        # every seed's MINPACK outcome: a scipy status, and at least its first evaluation
        assert set(np.unique(ds["status"].values)) <= {0, 1, 2, 3, 4}
        assert np.all(ds["n_evals"].values >= 1)


def check_dw_convergence(results, cfg):
    for ds in results:
        assert ds["step"].values[-1] == cfg["n_steps"]
        assert np.all(np.diff(ds["n_target_evals"].values, axis=-1) >= 0)
        triangle(ds, "map_to_truth", "map_to_maximiser")


def check_runtime(results, cfg):
    for ds in results:
        assert np.all(ds["wall_time_s"] > 0)
        reached = np.isfinite(ds["evals_to_truth"])
        assert np.all(ds["evals_to_truth"].values[reached] <= ds["n_target_evals"].values[reached])


def check_classification(results, cfg):
    for ds in results:
        assert logsumexp(ds["grid_log_weight"].values) == pytest.approx(0.0, abs=1e-9)
        assert ds.sizes["evolved_sample"] == cfg["pmc"]["n_samples"]


def check_target_bias(results, cfg):
    for ds in results:
        for t in ds["target"].values:
            gap = np.abs(ds["map_to_truth"] - ds["map_to_maximiser"]).sel(target=t).values
            assert np.all(gap <= float(ds["maximiser_to_truth"].sel(target=t)) + 1e-9)


def check_posterior_slices(results, cfg):
    for ds in results:
        vol = ds["log_pl"].values
        peak = np.unravel_index(int(np.argmax(vol)), vol.shape)
        np.testing.assert_allclose(ds["grid_max"].values, ds["u0"].values[list(peak)])
        assert np.allclose(logsumexp(ds["log_weight"].values, axis=1), 0.0, atol=1e-9)


CHECKS = {name[len("check_"):]: fn for name, fn in globals().items()
          if name.startswith("check_")}


def test_every_builtin_study_has_a_check():
    assert set(BUILTIN) == set(CHECKS)


@pytest.mark.slow
@pytest.mark.parametrize("name", BUILTIN)
def test_quick_study(name, tmp_path, one_numba_thread):
    st = S.get(name)
    cfg = S.resolve_config(st, quick=True)
    rep = S.run(st, cfg, tmp_path, progress=False)
    assert rep.ok, rep.text()
    n = len(S.tasks(st, cfg))
    assert rep.n_computed == n and len(list((tmp_path / "trials").glob("*.nc"))) == n
    report = (tmp_path / "report.md").read_text()
    pngs = sorted(tmp_path.glob("*.png"))
    assert pngs and all(f"]({p.name})" in report for p in pngs)
    assert rep.table.strip() and "nan" not in rep.table.lower()
    results = [xr.load_dataset(p) for p in sorted((tmp_path / "trials").glob("*.nc"))]
    CHECKS[name](results, cfg)
