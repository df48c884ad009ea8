"""The study runner: trial files, resume, config hashing, seeds, --set, dask."""

from __future__ import annotations

import dataclasses
import json
import os
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mrfpe import study as S
from mrfpe.cli import main
from mrfpe.experiments import importance_sampling as toy

SMALL = {"n_trials": 3, "n_samples": [10, 100]}


def counting(calls: list, fail_when=None) -> S.Study:
    """The toy study with a trial function that records its calls (and may fail)."""

    def trial(config, repeat, seed):
        calls.append((config["n_samples"], repeat))
        if fail_when is not None and fail_when(config, repeat):
            raise RuntimeError("boom")
        return toy.trial(config, repeat, seed)

    return dataclasses.replace(toy.STUDY, trial=trial)


def files(out: Path) -> list[str]:
    """Every file in ``out/trials`` (results, error files, temporaries)."""
    return sorted(p.name for p in (out / "trials").iterdir())


def results(out: Path) -> list[str]:
    return [f for f in files(out) if f.endswith(".nc")]


def test_one_netcdf_per_trial_with_provenance(tmp_path):
    calls = []
    st = counting(calls)
    cfg = S.resolve_config(st, overrides=SMALL)
    rep = S.run(st, cfg, tmp_path, progress=False)
    assert rep.ok and rep.n_computed == 6 and rep.n_skipped == 0
    assert len(calls) == 6
    assert files(tmp_path) == sorted(f"n_samples={n},repeat={r:04d}.nc"
                                     for n in (10, 100) for r in range(3))
    ds = xr.load_dataset(tmp_path / "trials" / "n_samples=100,repeat=0002.nc")
    assert json.loads(ds.attrs["trial_config"])["n_samples"] == 100
    assert json.loads(ds.attrs["study_config"])["n_samples"] == [10, 100]
    assert ds.attrs["repeat"] == 2
    assert ds.attrs["seed"] == S.trial_seed(cfg["seed"], 2, {"n_samples": 100})
    for key in ("mrfpe_version", "numpy_version", "xarray_version", "python_version",
                "config_hash", "trial_wall_time_s"):
        assert key in ds.attrs
    assert (tmp_path / "report.md").is_file() and (tmp_path / "rmse.png").is_file()
    assert json.loads((tmp_path / "config.json").read_text())["config"] == cfg
    assert not [p for p in (tmp_path / "trials").iterdir() if p.name.startswith(".")]


def test_second_run_skips_everything(tmp_path):
    calls = []
    st = counting(calls)
    cfg = S.resolve_config(st, overrides=SMALL)
    S.run(st, cfg, tmp_path, progress=False)
    before = {n: (tmp_path / "trials" / n).stat().st_mtime_ns for n in files(tmp_path)}
    calls.clear()
    rep = S.run(st, cfg, tmp_path, progress=False)
    assert calls == []
    assert rep.n_skipped == 6 and rep.n_computed == 0 and rep.ok
    assert {n: (tmp_path / "trials" / n).stat().st_mtime_ns for n in files(tmp_path)} == before
    assert "RMSE" in rep.table


def test_resume_after_kill_recomputes_only_missing(tmp_path):
    calls = []
    st = counting(calls)
    cfg = S.resolve_config(st, overrides=SMALL)
    S.run(st, cfg, tmp_path, progress=False)
    first = {n: xr.load_dataset(tmp_path / "trials" / n)["error"].values for n in files(tmp_path)}
    killed = ["n_samples=10,repeat=0001.nc", "n_samples=100,repeat=0002.nc"]
    for name in killed:
        (tmp_path / "trials" / name).unlink()
    # a stray temporary file from a write in flight must not count as a result
    (tmp_path / "trials" / ".n_samples=10,repeat=0001.nc.dead.tmp").write_bytes(b"partial")
    calls.clear()
    rep = S.run(st, cfg, tmp_path, progress=False)
    assert sorted(calls) == [(10, 1), (100, 2)]
    assert rep.n_computed == 2 and rep.n_skipped == 4
    for name in killed:  # recomputed trials are bit-identical (seeded per trial)
        np.testing.assert_array_equal(
            xr.load_dataset(tmp_path / "trials" / name)["error"].values, first[name])


def test_interrupt_keeps_finished_trials(tmp_path):
    calls = []

    def trial(config, repeat, seed):
        calls.append(repeat)
        if len(calls) == 3:
            raise KeyboardInterrupt  # a kill in the middle of the third trial
        return toy.trial(config, repeat, seed)

    st = dataclasses.replace(toy.STUDY, trial=trial)
    cfg = S.resolve_config(st, overrides=SMALL)
    with pytest.raises(KeyboardInterrupt):
        S.run(st, cfg, tmp_path, progress=False)
    assert len(files(tmp_path)) == 2
    calls.clear()
    rep = S.run(counting(calls), cfg, tmp_path, progress=False)
    assert len(calls) == 4 and rep.n_skipped == 2 and rep.ok


def test_changed_config_is_not_reused(tmp_path):
    calls = []
    st = counting(calls)
    cfg = S.resolve_config(st, overrides=SMALL)
    S.run(st, cfg, tmp_path, progress=False)
    changed = S.resolve_config(st, overrides={**SMALL, "sigma": 0.6})
    calls.clear()
    with pytest.raises(ValueError, match=r"sigma: 0\.5 -> 0\.6"):
        S.run(st, changed, tmp_path, progress=False)
    assert calls == []
    rep = S.run(st, changed, tmp_path, progress=False, mismatch="recompute")
    assert len(calls) == 6 and rep.n_computed == 6
    ds = xr.load_dataset(tmp_path / "trials" / "n_samples=10,repeat=0000.nc")
    assert json.loads(ds.attrs["trial_config"])["sigma"] == 0.6
    # a new study version also invalidates (the trial's meaning changed)
    v2 = dataclasses.replace(st, version=2)
    with pytest.raises(ValueError, match="different configuration"):
        S.run(v2, changed, tmp_path, progress=False)


def test_more_trials_and_grid_subsets_reuse_existing(tmp_path):
    calls = []
    st = counting(calls)
    S.run(st, S.resolve_config(st, overrides=SMALL), tmp_path, progress=False)
    calls.clear()
    rep = S.run(st, S.resolve_config(st, overrides=SMALL, n_trials=4), tmp_path, progress=False)
    assert sorted(calls) == [(10, 3), (100, 3)] and rep.n_skipped == 6
    calls.clear()
    sub = S.resolve_config(st, overrides={"n_samples": 100}, n_trials=2)
    rep = S.run(st, sub, tmp_path, progress=False)
    assert calls == [] and rep.n_skipped == 2 and rep.n_trials == 2


def test_failed_trials_are_reported_and_retried(tmp_path):
    calls = []
    st = counting(calls, fail_when=lambda c, r: c["n_samples"] == 100 and r == 1)
    cfg = S.resolve_config(st, overrides=SMALL)
    rep = S.run(st, cfg, tmp_path, progress=False)
    assert not rep.ok and [f[0] for f in rep.failures] == ["n_samples=100,repeat=0001"]
    assert "RuntimeError: boom" in rep.failures[0][1]
    assert len(results(tmp_path)) == 5 and not (tmp_path / "report.md").exists()
    error = tmp_path / "trials" / "n_samples=100,repeat=0001.error.txt"
    assert "RuntimeError: boom" in error.read_text() and "Traceback" in error.read_text()
    assert "FAILED n_samples=100,repeat=0001" in rep.text() and str(error) in rep.text()
    calls.clear()
    rep = S.run(counting(calls), cfg, tmp_path, progress=False)
    assert calls == [(100, 1)] and rep.ok and (tmp_path / "report.md").exists()
    assert not error.exists()  # the retry succeeded: no stale error file


def test_unserialisable_result_leaves_no_partial_file(tmp_path):
    def bad(config, repeat, seed):
        return xr.Dataset({"x": ("a", np.array([object(), object()], dtype=object))})

    st = dataclasses.replace(toy.STUDY, trial=bad)
    rep = S.run(st, S.resolve_config(st, overrides=SMALL, n_trials=1), tmp_path, progress=False)
    assert len(rep.failures) == 2
    assert results(tmp_path) == []  # no partial result
    assert all(f.endswith(".error.txt") for f in files(tmp_path))  # and no temporary file


def test_trial_must_return_a_dataset(tmp_path):
    st = dataclasses.replace(toy.STUDY, trial=lambda c, r, s: {"error": 1.0})
    rep = S.run(st, S.resolve_config(st, overrides=SMALL, n_trials=1), tmp_path, progress=False)
    assert "must return an xarray.Dataset" in rep.failures[0][1]


def test_set_parsing_and_validation():
    st = toy.STUDY
    cfg = S.resolve_config(st, overrides=["n_samples=100", "sigma=1", "mu=[0.1, 0.2]",
                                          "seed=7"], n_trials=5)
    assert cfg["n_samples"] == [100]  # a grid key given one value
    assert cfg["sigma"] == 1.0 and isinstance(cfg["sigma"], float)
    assert cfg["mu"] == [0.1, 0.2] and cfg["seed"] == 7 and cfg["n_trials"] == 5
    quick = S.resolve_config(st, quick=True)
    assert quick["n_trials"] == st.quick["n_trials"]
    assert S.resolve_config(st, quick=True, overrides=["n_trials=2"])["n_trials"] == 2
    with pytest.raises(ValueError, match="unknown setting 'sigm'"):
        S.resolve_config(st, overrides=["sigm=1"])
    with pytest.raises(ValueError, match="setting 'sigma' expects"):
        S.resolve_config(st, overrides=["sigma=abc"])
    with pytest.raises(ValueError, match="n_samples"):
        S.resolve_config(st, overrides=["n_samples=1.5"])
    with pytest.raises(ValueError, match="key=value"):
        S.resolve_config(st, overrides=["sigma"])
    with pytest.raises(ValueError, match="n_trials"):
        S.resolve_config(st, n_trials=0)
    with pytest.raises(ValueError, match="duplicate"):
        S.resolve_config(st, overrides=["n_samples=[10, 10]"])


def test_seeds_depend_only_on_study_seed_repeat_and_cell():
    st = toy.STUDY
    # without a cell, trial r gets child r of SeedSequence(seed).spawn(n)
    children = np.random.SeedSequence(5).spawn(4)
    for r, child in enumerate(children):
        expected = int(child.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))
        assert S.trial_seed(5, r) == expected
    full = {(t.cell["n_samples"], t.repeat): t.seed
            for t in S.tasks(st, S.resolve_config(st, n_trials=3))}
    sub = S.tasks(st, S.resolve_config(st, overrides=["n_samples=[1000, 10]"], n_trials=2))
    assert all(full[(t.cell["n_samples"], t.repeat)] == t.seed for t in sub)
    assert len(set(full.values())) == len(full)  # independent streams per trial
    shared = dataclasses.replace(st, shared_seed=("n_samples",))
    tks = S.tasks(shared, S.resolve_config(shared, n_trials=2))
    assert {t.seed for t in tks if t.repeat == 0} == {S.trial_seed(st.config["seed"], 0)}


def test_study_definition_is_validated():
    kw = dict(name="x", doc="X.\n\nFull run: 1 s.", config={"n_trials": 1, "seed": 0, "a": [1]},
              quick={}, trial=toy.trial, summarise=toy.summarise, grid=("a",))
    S.Study(**kw)
    with pytest.raises(ValueError, match="Full run"):
        S.Study(**{**kw, "doc": "X."})
    with pytest.raises(ValueError, match="must be a list"):
        S.Study(**{**kw, "config": {"n_trials": 1, "seed": 0, "a": 1}})
    with pytest.raises(ValueError, match="must define 'seed'"):
        S.Study(**{**kw, "config": {"n_trials": 1, "a": [1]}})
    with pytest.raises(ValueError, match="unknown keys"):
        S.Study(**{**kw, "quick": {"b": 2}})


USER_STUDY = '''
"""A user's own study: the square of a seeded uniform.

Full run: instant.
"""
import numpy as np
import xarray as xr
from mrfpe.study import Study


def trial(config, repeat, seed):
    return xr.Dataset({"u": ((), np.random.default_rng(seed).random() * config["scale"])})


def summarise(results, config, out_dir):
    total = sum(float(ds["u"]) for ds in results)
    (out_dir / "report.md").write_text(f"total {total}\\n")
    return f"total {total:.6f}"


STUDY = Study(name="mine", doc=__doc__, config={"n_trials": 4, "seed": 3, "scale": 2.0},
              quick={"n_trials": 2}, trial=trial, summarise=summarise)
'''


@pytest.fixture
def user_study(tmp_path, monkeypatch):
    path = tmp_path / "studies" / "mine" / "study.py"
    path.parent.mkdir(parents=True)
    path.write_text(textwrap.dedent(USER_STUDY))
    monkeypatch.chdir(tmp_path)
    return path


def test_user_study_found_under_cwd_and_by_path(user_study, tmp_path, capsys):
    bad = tmp_path / "studies" / "bad" / "study.py"
    bad.parent.mkdir()
    bad.write_text("raise RuntimeError('cannot load')\n")
    broken = {}
    assert {"mine", "importance_sampling"} <= set(S.available(broken))
    assert broken == {"bad": "RuntimeError: cannot load"}
    # named with the reason (one line on the command line), not a bare RuntimeError
    with pytest.raises(ValueError, match=r"bad/study\.py: cannot load the study file: "
                                         "RuntimeError: cannot load"):
        S.get("bad")
    assert S.get("mine").name == "mine"
    assert S.get(str(user_study)).name == "mine"
    with pytest.raises(ValueError, match=r"unknown study 'nope'.*importance_sampling"):
        S.get("nope")
    assert main(["study", "list"]) == 0
    listing = capsys.readouterr().out
    assert "mine" in listing and "importance_sampling" in listing and "instant" in listing
    assert "BROKEN: RuntimeError: cannot load" in listing
    assert main(["study", "run", "mine", "--quick"]) == 0  # default --out: studies/mine/out-quick
    assert len(list((tmp_path / "studies/mine/out-quick/trials").glob("*.nc"))) == 2
    assert main(["study", "run", "nope"]) == 2


def test_cli_run_and_rerun(tmp_path, capsys):
    argv = ["study", "run", "importance_sampling", "--quick", "--trials", "2",
            "--set", "n_samples=[10, 100]", "--out", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "4 computed, 0 already done" in out and "| n |" in out
    assert main(argv) == 0
    assert "0 computed, 4 already done" in capsys.readouterr().out
    assert main([*argv, "--set", "sigma=0.7"]) == 2  # refuses to mix configurations
    assert "different configuration" in capsys.readouterr().err


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=40) as lc:
        yield lc


@pytest.mark.slow
def test_dask_scheduler_matches_in_process(cluster, tmp_path, user_study, capsys):
    local, remote = tmp_path / "local", tmp_path / "remote"
    args = ["--quick", "--trials", "3", "--set", "n_samples=[10, 100]"]
    assert main(["study", "run", "importance_sampling", *args, "--out", str(local)]) == 0
    assert main(["study", "run", "importance_sampling", *args, "--out", str(remote),
                 "--scheduler", cluster.scheduler_address]) == 0
    assert files(local) == files(remote) and len(files(remote)) == 6
    pids = set()
    for name in files(local):
        a = xr.load_dataset(local / "trials" / name)
        b = xr.load_dataset(remote / "trials" / name)
        np.testing.assert_array_equal(a["error"].values, b["error"].values)
        assert a.attrs["seed"] == b.attrs["seed"]
        # two one-thread workers share this machine's cores: no oversubscription
        assert b.attrs["numba_threads"] == max(1, (os.cpu_count() or 1) // 2)
        pids.add(b.attrs["pid"])
    assert os.getpid() not in pids  # computed on the workers
    # a study loaded from a file (not importable on the workers) is shipped by value
    out = tmp_path / "user"
    assert main(["study", "run", str(user_study), "--out", str(out),
                 "--scheduler", cluster.scheduler_address]) == 0
    assert len(files(out)) == 4
    capsys.readouterr()
