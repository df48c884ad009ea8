"""``mrfpe study verify``: committed trials replayed and compared bit for bit."""

from __future__ import annotations

import dataclasses
import textwrap

import netCDF4
import pytest

from mrfpe import cli
from mrfpe import study as S
from mrfpe.netcdf import open_dataset, write_atomic

# A tiny study: random numbers from the seed, a timing, and a trial that reads its
# config's dict in order (as the runtime study spawns one seed per run, in order).
TINY = '''
"""A tiny study for the replay check.

Full run: instant.
"""
import time

import numpy as np
import xarray as xr
from mrfpe.study import Study

RUNS = {"b": 2.0, "a": 1.0, "c": 3.0}  # not in sorted order: a replay must keep this one


def trial(config, repeat, seed):
    rng = np.random.default_rng(seed)
    runs = list(config["runs"])
    scale = np.array([config["runs"][r] for r in runs])
    ds = xr.Dataset({"u": (("i",), rng.random(5) * config["size"]),
                     "per_run": (("run",), rng.random(len(runs)) * scale),
                     "wall_time_s": ((), time.perf_counter())},
                    coords={"run": runs})
    ds["u"].attrs["units"] = "1"
    ds.attrs["note"] = f"cell {config['size']}"
    return ds


def summarise(results, config, out_dir):
    (out_dir / "report.md").write_text("ok\\n")
    return "ok"


STUDY = Study(name="tiny", doc=__doc__, trial=trial, summarise=summarise,
              config={"n_trials": 2, "seed": 5, "size": [1, 3], "runs": RUNS},
              grid=("size",))
'''


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.py"
    path.write_text(textwrap.dedent(TINY))
    study = S.load_file(path)
    out = tmp_path / "out"
    report = S.run(study, S.resolve_config(study), out, progress=False)
    assert report.ok and report.n_computed == 4
    return path, study, out


def _rewrite(path, change):
    """Rewrite a trial file with ``change(ds)`` applied, sealed again (as a commit would be)."""
    ds = open_dataset(path, "trial")
    change(ds)
    write_atomic(ds, path, "trial")


def test_identical_replay_passes(tiny):
    _, study, out = tiny
    report = S.verify(study, out)
    assert report.ok and len(report.verdicts) == 4
    assert {v.status for v in report.verdicts} == {"identical"}
    assert all(v.not_compared == ["wall_time_s"] for v in report.verdicts)
    assert "4 of 4 trial(s) replayed bit for bit" in report.text()
    assert "timings, not compared: wall_time_s" in report.text()


def test_a_tampered_value_is_reported_naming_the_variable(tiny, capsys):
    path, study, out = tiny
    victim = out / "trials" / "size=3,repeat=0001.nc"

    def nudge(ds):
        ds["u"].values[2] = float(ds["u"].values[2]) * (1 + 1e-15)

    _rewrite(victim, nudge)
    report = S.verify(study, out)
    assert not report.ok
    bad = [v for v in report.verdicts if not v.ok]
    assert [v.stem for v in bad] == ["size=3,repeat=0001"]
    assert bad[0].status == "differs"
    assert any(d.startswith("variable 'u': 1 of 5 value(s) differ") and "first at (2,)" in d
               for d in bad[0].differences)
    # the command line: a verdict per trial, the variable named, exit status 1
    assert cli.main(["study", "verify", str(path), "--out", str(out)]) == 1
    text = capsys.readouterr().out
    assert "FAIL size=3,repeat=0001: DIFFERS" in text and "variable 'u'" in text
    assert "ok   size=1,repeat=0000: replays bit for bit" in text


def test_attributes_are_compared_but_not_timings_or_provenance(tiny):
    _, study, out = tiny
    trials = out / "trials"

    def restamp(ds):
        ds.attrs.update(host="elsewhere", pid=1, numpy_version="0.0", finished_utc="then",
                        trial_wall_time_s=99.0)

    _rewrite(trials / "size=1,repeat=0000.nc", restamp)
    _rewrite(trials / "size=1,repeat=0001.nc", lambda ds: ds.attrs.update(note="edited"))
    _rewrite(trials / "size=3,repeat=0000.nc",
             lambda ds: ds["u"].attrs.update(units="m"))
    verdicts = {v.stem: v for v in S.verify(study, out).verdicts}
    assert verdicts["size=1,repeat=0000"].ok
    assert verdicts["size=1,repeat=0001"].differences == [
        "attribute 'note': 'edited' in the file, 'cell 1' in the replay"]
    assert verdicts["size=3,repeat=0000"].differences == [
        "variable 'u': attribute 'units': 'm' in the file, '1' in the replay"]


def test_cheapest_and_count_choose_the_trials(tiny):
    _, study, out = tiny
    times = {"size=1,repeat=0000": 4.0, "size=3,repeat=0000": 1.0,
             "size=1,repeat=0001": 3.0, "size=3,repeat=0001": 2.0}
    for stem, t in times.items():
        with netCDF4.Dataset(out / "trials" / f"{stem}.nc", "a") as nc:  # unsealed: accepted
            nc.setncattr("trial_wall_time_s", t)
    report = S.verify(study, out, count=2, cheapest=True)
    assert [v.stem for v in report.verdicts] == ["size=3,repeat=0000", "size=3,repeat=0001"]
    assert [v.recorded_wall_time_s for v in report.verdicts] == [1.0, 2.0]
    assert [v.stem for v in S.verify(study, out, trials=["size=1,repeat=0001"]).verdicts] \
        == ["size=1,repeat=0001"]
    with pytest.raises(ValueError, match="no trial file"):
        S.verify(study, out, trials=["size=9,repeat=0000"])
    with pytest.raises(ValueError, match="--count"):
        S.verify(study, out, count=0)


def test_a_trial_of_another_version_is_stale_not_replayed(tiny):
    _, study, out = tiny
    newer = dataclasses.replace(study, version=2)
    report = S.verify(newer, out, count=1)
    (verdict,) = report.verdicts
    assert verdict.status == "stale" and not report.ok
    assert "config hash" in verdict.differences[0]
    assert "not replayed" in verdict.text()


def test_a_setting_run_with_another_value_replays(tmp_path):
    path = tmp_path / "tiny.py"
    path.write_text(textwrap.dedent(TINY))
    study = S.load_file(path)
    # a value other than the default is replayed as recorded (JSON with sorted keys)
    cfg = S.resolve_config(study, overrides=['runs={"a": 1.0, "z": 0.5}', "size=2"])
    S.run(study, cfg, tmp_path / "out", progress=False)
    report = S.verify(study, tmp_path / "out")
    assert report.ok, [v.differences for v in report.verdicts]


def test_refuses_another_study_s_directory(tiny):
    _, study, out = tiny
    other = dataclasses.replace(study, name="other")
    with pytest.raises(ValueError, match="holds study 'tiny'"):
        S.verify(other, out)
    with pytest.raises(ValueError, match="no trial files"):
        S.verify(study, out / "nowhere")
