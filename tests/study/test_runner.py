"""The runner's safety: one run per output directory, nothing partial, nothing stale.

Two real processes race for one ``--out``; a real process is SIGKILLed while
writing a trial; stray temporary files and truncated trial files are handled
on the next run.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import sys
import textwrap
import time
from pathlib import Path

import pytest
import xarray as xr

from mrfpe import study as S
from mrfpe.experiments import importance_sampling as toy
from mrfpe.netcdf import open_dataset

from .. import _processes as procs

SMALL = {"n_trials": 2, "n_samples": [10, 100]}

# A study whose trials wait for a file to appear, so the test decides when they finish,
# and whose fsync can be made to hang (the SIGKILL test kills the process there).
SLOW_STUDY = '''
"""Trials that wait for a go file.

Full run: instant.
"""
import os
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr
from mrfpe.study import Study

HANG_AT_FSYNC = os.environ.get("HANG_AT_FSYNC")
_fsync, _calls = os.fsync, []


def _hanging_fsync(fd):
    _calls.append(fd)
    if len(_calls) == int(HANG_AT_FSYNC):
        print("writing", flush=True)  # the trial file is half-way: tmp written, not replaced
        time.sleep(600)
    return _fsync(fd)


if HANG_AT_FSYNC:
    os.fsync = _hanging_fsync


def trial(config, repeat, seed):
    go = Path(os.environ["GO_FILE"])
    while not go.exists():
        time.sleep(0.02)
    return xr.Dataset({"u": (("i",), np.random.default_rng(seed).random(1000))})


def summarise(results, config, out_dir):
    (out_dir / "report.md").write_text("ok\\n")
    return "ok"


STUDY = Study(name="slow", doc=__doc__, config={"n_trials": 3, "seed": 3},
              trial=trial, summarise=summarise)
'''


def _wait_for(predicate, timeout: float = 120.0) -> None:
    """Poll until ``predicate()``; a generous timeout only guards against a hung test."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("timed out waiting")
        time.sleep(0.05)


@pytest.fixture
def slow_study(tmp_path):
    path = tmp_path / "slow_study.py"
    path.write_text(textwrap.dedent(SLOW_STUDY))
    return path


def _start(study: Path, out: Path, env: dict) -> procs.Child:
    return procs.Child([sys.executable, "-m", "mrfpe", "study", "run", study, "--out", out],
                       env={**os.environ, **env})


def test_two_processes_on_one_out_dir_never_interleave(slow_study, tmp_path):
    out, go = tmp_path / "out", tmp_path / "go"
    env = {"GO_FILE": str(go), "NUMBA_NUM_THREADS": "1"}
    with _start(slow_study, out, env) as first:
        _wait_for(lambda: (out / ".lock").exists() and (out / ".lock").read_text().strip())
        with _start(slow_study, out, env) as second:
            assert second.finish(timeout=120) == 2, second.stderr
        err = second.stderr
        assert "in use by another study run" in err and f"pid {first.pid}" in err
        assert "Traceback" not in err
        go.touch()
        assert first.finish(timeout=120) == 0, first.stderr
    names = sorted(p.name for p in (out / "trials").iterdir())
    assert names == [f"repeat={r:04d}.nc" for r in range(3)]
    for name in names:
        open_dataset(out / "trials" / name, "trial")
    # the lock is released with the process: a new run resumes (nothing to do)
    with _start(slow_study, out, env) as third:
        assert third.finish(timeout=120) == 0, third.stderr
    assert "0 computed, 3 already done" in third.stdout


def test_sigkill_while_writing_leaves_no_partial_result(slow_study, tmp_path):
    out, go = tmp_path / "out", tmp_path / "go"
    go.touch()
    # fsync calls: trial 0 file, its directory, then trial 1's file -> hang there
    with _start(slow_study, out, {"GO_FILE": str(go), "HANG_AT_FSYNC": "3",
                                  "NUMBA_NUM_THREADS": "1"}) as proc:
        proc.wait_for("stdout", lambda text: "writing" in text.split(), "'writing'",
                      timeout=120)
        proc.send_signal(signal.SIGKILL)
        assert proc.finish(timeout=60) == -signal.SIGKILL
    trials = out / "trials"
    assert sorted(p.name for p in trials.glob("*.nc")) == ["repeat=0000.nc"]
    assert len(list(trials.glob(".*.tmp"))) == 1  # the interrupted write, under a tmp name
    open_dataset(trials / "repeat=0000.nc", "trial")
    # the next run removes the stray file and computes the rest
    with _start(slow_study, out, {"GO_FILE": str(go), "NUMBA_NUM_THREADS": "1"}) as rerun:
        assert rerun.finish(timeout=120) == 0, rerun.stderr
    assert "removed 1 temporary file(s)" in rerun.stderr
    assert sorted(p.name for p in trials.iterdir()) == [f"repeat={r:04d}.nc" for r in range(3)]


def test_stray_tmp_files_are_removed(tmp_path):
    cfg = S.resolve_config(toy.STUDY, overrides=SMALL)
    trials = tmp_path / "trials"
    trials.mkdir(parents=True)
    (trials / ".n_samples=10,repeat=0000.nc.deadbeef.tmp").write_bytes(b"partial")
    (tmp_path / ".config.json.cafebabe.tmp").write_text("{")
    rep = S.run(toy.STUDY, cfg, tmp_path, progress=False)
    assert rep.ok and any("removed 2 temporary file(s)" in n for n in rep.notes)
    assert not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize("damage", ["truncate", "garbage"])
def test_unreadable_trial_file_is_reported_and_recomputed(tmp_path, damage):
    cfg = S.resolve_config(toy.STUDY, overrides=SMALL)
    assert S.run(toy.STUDY, cfg, tmp_path, progress=False).ok
    path = tmp_path / "trials" / "n_samples=100,repeat=0001.nc"
    good = xr.load_dataset(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2] if damage == "truncate" else b"not netcdf")
    notes: list[str] = []
    rep = S.run(toy.STUDY, cfg, tmp_path, progress=False, log=notes.append)
    assert rep.ok and rep.n_computed == 1 and rep.n_skipped == 3
    assert notes == rep.notes and len(notes) == 1
    assert str(path) in notes[0] and "not a readable netCDF trial file" in notes[0]
    xr.testing.assert_equal(xr.load_dataset(path)["error"], good["error"])


def test_output_dir_that_cannot_be_created_fails_before_any_trial(tmp_path):
    calls = []

    def trial(config, repeat, seed):
        calls.append(repeat)
        return toy.trial(config, repeat, seed)

    st = dataclasses.replace(toy.STUDY, trial=trial)
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match=r"--out .*cannot write there"):
        S.run(st, S.resolve_config(st, overrides=SMALL), blocker / "out", progress=False)
    assert calls == []


def test_unreachable_scheduler_is_one_clear_error(tmp_path):
    pytest.importorskip("distributed")
    cfg = S.resolve_config(toy.STUDY, overrides=SMALL)
    # port 9 (discard) on loopback: nothing listens, the connection is refused at once
    with pytest.raises(ValueError, match=r"--scheduler tcp://127.0.0.1:9: no dask scheduler"):
        S.run(toy.STUDY, cfg, tmp_path, scheduler="tcp://127.0.0.1:9", progress=False)
    assert not list((tmp_path / "trials").glob("*.nc"))
