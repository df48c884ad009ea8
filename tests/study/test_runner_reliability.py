"""Study runs that once lost or mixed files, kept computing on a full disk, or crashed late."""

from __future__ import annotations

import dataclasses
import errno
import json
import socket
import threading

import numpy as np
import pytest
import xarray as xr

from mrfpe import cli
from mrfpe import study as S
from mrfpe.experiments import importance_sampling as toy
from mrfpe.netcdf import DiskFullError, open_dataset
from mrfpe.study import runner, trial

SMALL = ["n_trials=2", "n_samples=[10,100]"]
#: Attributes that record when, where and how fast a trial ran, not what it computed.
PROVENANCE = {"finished_utc", "trial_wall_time_s", "host", "pid", "numba_threads"}


def _cfg():
    return S.resolve_config(toy.STUDY, overrides=SMALL)


def test_a_second_study_in_one_directory_is_refused_unless_forced(tmp_path):
    assert S.run(toy.STUDY, _cfg(), tmp_path, progress=False).ok
    before = {p.name: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    other = dataclasses.replace(toy.STUDY, name="other_study")
    with pytest.raises(ValueError, match=r"holds study 'importance_sampling'.*--force"):
        S.run(other, S.resolve_config(other, overrides=SMALL), tmp_path, progress=False)
    assert {p.name: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    assert S.run(other, S.resolve_config(other, overrides=SMALL), tmp_path, progress=False,
                 force=True).ok
    assert json.loads((tmp_path / "config.json").read_text())["study"] == "other_study"


def test_cli_second_study_is_one_line(tmp_path, capsys):
    (tmp_path / "config.json").write_text(json.dumps({"study": "pmc_convergence"}))
    rc = cli.main(["study", "run", "importance_sampling", "--quick", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc == 2 and "holds study 'pmc_convergence'" in err


def test_disk_full_stops_the_run_and_names_it(tmp_path, monkeypatch, capsys):
    calls = []

    def full(ds, path, what="output", **kw):
        calls.append(path)
        raise DiskFullError(f"{path}: no space left on the device to write the {what} file")

    monkeypatch.setattr(trial, "write_atomic", full)
    with pytest.raises(DiskFullError, match="no space left"):
        S.run(toy.STUDY, _cfg(), tmp_path, progress=False)
    assert len(calls) == 1  # stopped at the first write: no further trial computed
    rc = cli.main(["study", "run", "importance_sampling", "--set", SMALL[0], "--set", SMALL[1],
                   "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 1 and "no space left on the device" in err and "rerun the same command" in err
    assert not list((tmp_path / "trials").glob("*.error.txt"))


def test_failures_never_point_to_traceback_files_that_were_not_written(tmp_path, monkeypatch):
    def broken(*a, **k):
        raise RuntimeError("trial failed")

    def unwritable(path, header, tb):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(runner, "execute", broken)
    monkeypatch.setattr(runner, "write_error", unwritable)
    rep = S.run(toy.STUDY, _cfg(), tmp_path, progress=False)
    assert not rep.ok and "traceback not saved" in rep.text()
    assert ".error.txt" not in rep.text().split("\n", 1)[1]


def test_a_trial_count_beyond_the_budget_is_refused_before_anything(tmp_path, capsys):
    out = tmp_path / "out"
    rc = cli.main(["study", "run", "importance_sampling", "--quick", "--trials", "1000000000",
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "1000000000 repetitions" in err and "memory budget" in err
    assert not out.exists()


def _values(directory):
    out = {}
    for p in sorted((directory / "trials").glob("*.nc")):
        ds = open_dataset(p, "trial")
        ds.attrs = {k: v for k, v in ds.attrs.items() if k not in PROVENANCE}
        out[p.name] = ds
    return out


def test_a_resumed_run_equals_an_uninterrupted_one_value_by_value(tmp_path, monkeypatch):
    whole, resumed = tmp_path / "whole", tmp_path / "resumed"
    assert S.run(toy.STUDY, _cfg(), whole, progress=False).ok
    real, n = runner.execute, []

    def interrupted(*a, **k):
        if len(n) == 2:
            raise KeyboardInterrupt
        n.append(1)
        return real(*a, **k)

    monkeypatch.setattr(runner, "execute", interrupted)
    with pytest.raises(KeyboardInterrupt):
        S.run(toy.STUDY, _cfg(), resumed, progress=False)
    monkeypatch.setattr(runner, "execute", real)
    rep = S.run(toy.STUDY, _cfg(), resumed, progress=False)
    assert rep.ok and rep.n_skipped == 2 and rep.n_computed == rep.n_trials - 2
    a, b = _values(whole), _values(resumed)
    assert a.keys() == b.keys() and len(a) == rep.n_trials
    for name in a:
        xr.testing.assert_identical(a[name], b[name])


def test_a_damaged_trial_is_named_and_recomputed(tmp_path):
    import netCDF4

    assert S.run(toy.STUDY, _cfg(), tmp_path, progress=False).ok
    victim = sorted((tmp_path / "trials").glob("*.nc"))[0]
    with netCDF4.Dataset(victim, "r+") as nc:  # attributes damaged, file still parses
        nc.setncattr("cell", "{not json")
    notes = []
    rep = S.run(toy.STUDY, _cfg(), tmp_path, progress=False, log=notes.append)
    assert rep.ok and rep.n_computed == 1
    assert any(str(victim) in n and "damaged" in n for n in notes)


def test_study_files_that_exit_or_do_not_parse_are_named(tmp_path, monkeypatch, capsys):
    bad = tmp_path / "bad.py"
    bad.write_text("def broken(:\n")
    assert cli.main(["study", "show", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: cannot load the study file: SyntaxError" in err
    monkeypatch.chdir(tmp_path)
    (tmp_path / "studies" / "quits").mkdir(parents=True)
    (tmp_path / "studies" / "quits" / "study.py").write_text("import sys\nsys.exit(3)\n")
    assert cli.main(["study", "list"]) == 0
    out = capsys.readouterr().out
    assert "quits" in out and "BROKEN" in out and "importance_sampling" in out


def test_a_scheduler_that_is_not_dask_is_one_line(tmp_path):
    """A server that answers with garbage (a huge frame length): no MemoryError."""
    pytest.importorskip("distributed")
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    stop = threading.Event()

    def serve():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            conn.sendall(np.full(64, 0xFF, dtype=np.uint8).tobytes())

    threading.Thread(target=serve, daemon=True).start()
    try:
        with pytest.raises(ValueError, match=r"^--scheduler tcp://127.0.0.1:\d+: no dask "):
            S.run(toy.STUDY, _cfg(), tmp_path, progress=False,
                  scheduler=f"tcp://127.0.0.1:{server.getsockname()[1]}")
    finally:
        stop.set()
        server.close()
    # the failed client left nothing behind that later dask computations would use
    import dask
    from distributed.client import _global_clients

    assert dask.config.get("scheduler", None) is None and not _global_clients
