"""Replaying committed trials: does each trial file still come out bit for bit?

A trial file records everything that determines its result: the trial's config
(``trial_config``), its cell, repetition and seed, the study's name and version
and the hash of them all. :func:`verify` runs chosen trials of a results
directory again, from those records, through the runner's own path -- the
config resolved against the study's declared settings (a setting left at its
default keeps the default's key order, which a trial may read), the seed
derived from the study seed, the result written by
:func:`~mrfpe.study.trial.write_result` and read back -- on the numba thread
count the file records, and compares the replay with the file:

* every variable (data and coordinates): name, dimensions, dtype and the bytes of
  its values, and its attributes;
* every global attribute but the timings and the provenance of the run (names
  ending ``time_s`` or ``_utc``, the host, process, thread count, platform and
  package versions), which a replay cannot reproduce and need not;
* before running anything: the config hash and the seed the current code derives
  for the trial against those recorded (a difference means the code no longer
  reads the file's settings as they were meant, so there is nothing to replay).

Variables whose name ends ``time_s`` are timings: reported as not compared. A
setting whose value is not the default is replayed as the file records it, a JSON
object with its keys sorted: a trial that reads such an object in the order it was
given on the command line (``--set 'runs={"b": ..., "a": ...}'``) is replayed in the
sorted order (the config hash does not tell the two apart either).
Nothing in the results directory is written; the replays go to a temporary
directory. ``mrfpe study verify NAME --out DIR`` is the command line.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.netcdf import open_dataset, read_attrs
from mrfpe.study.config import canonical
from mrfpe.study.resolve import resolve_config
from mrfpe.study.seeds import Task, tasks
from mrfpe.study.spec import Study
from mrfpe.study.trial import (
    execute,
    result_path,
    trial_attrs,
    warnings_in_one_line,
    write_result,
)

__all__ = ["TrialVerdict", "VerifyReport", "compare_trials", "is_timing", "verify"]

#: Global attributes that record where and when a trial ran, not what it computed.
PROVENANCE_ATTRS = frozenset({"host", "pid", "numba_threads", "platform"})


def is_timing(name: str) -> bool:
    """A name that holds a time: a duration (``...time_s``) or a timestamp (``..._utc``)."""
    return name.endswith("time_s") or name.endswith("_utc")


def _compared_attr(name: str) -> bool:
    """A global attribute a replay must reproduce: not a time, nor the run's provenance
    (where it ran, on how many threads, with which package versions)."""
    versions = name.endswith("_version") and name != "study_version"
    return not (is_timing(name) or name in PROVENANCE_ATTRS or versions)


@dataclass
class TrialVerdict:
    """What replaying one trial file found."""

    stem: str
    status: str                     # "identical", "differs", "stale", "failed"
    differences: list[str] = field(default_factory=list)
    not_compared: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # the replay's warnings, in one line
    wall_time_s: float = float("nan")           # the replay's
    recorded_wall_time_s: float = float("nan")  # the committed trial's

    @property
    def ok(self) -> bool:
        return self.status == "identical"

    def text(self) -> str:
        times = (f"replayed in {self.wall_time_s:.1f} s, recorded {self.recorded_wall_time_s:.1f} s"
                 if np.isfinite(self.wall_time_s) else "not replayed")
        head = {"identical": "replays bit for bit", "differs": "DIFFERS",
                "stale": "STALE (not replayed)", "failed": "FAILED"}[self.status]
        lines = [f"{'ok  ' if self.ok else 'FAIL'} {self.stem}: {head} ({times})"]
        lines += [f"       {d}" for d in self.differences[:20]]
        if len(self.differences) > 20:
            lines.append(f"       ... and {len(self.differences) - 20} more differences")
        lines += [f"       ({n})" for n in self.notes]
        return "\n".join(lines)


@dataclass
class VerifyReport:
    """What :func:`verify` did: one verdict per trial replayed."""

    study: str
    out_dir: Path
    n_available: int
    verdicts: list[TrialVerdict] = field(default_factory=list)
    wall_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return bool(self.verdicts) and all(v.ok for v in self.verdicts)

    def text(self) -> str:
        n_ok = sum(v.ok for v in self.verdicts)
        skipped = sorted({n for v in self.verdicts for n in v.not_compared})
        lines = [f"study {self.study}: {n_ok} of {len(self.verdicts)} trial(s) replayed bit for "
                 f"bit ({self.n_available} in {self.out_dir / 'trials'}) in "
                 f"{self.wall_time_s:.1f} s"]
        if skipped:
            lines.append(f"timings, not compared: {', '.join(skipped)}")
        return "\n".join(lines)


# -- comparing two trial Datasets --------------------------------------------------------


def _value_difference(name: str, a: np.ndarray, b: np.ndarray) -> str | None:
    """How ``a`` (committed) and ``b`` (replayed) differ in their bytes, or ``None``."""
    if a.dtype != b.dtype:
        return f"variable {name!r}: dtype {a.dtype} in the file, {b.dtype} in the replay"
    if a.shape != b.shape:
        return f"variable {name!r}: shape {a.shape} in the file, {b.shape} in the replay"
    if a.dtype.kind in "biufcmM":
        width = a.dtype.itemsize
        raw_a = np.ascontiguousarray(a).view(np.uint8).reshape(-1, width)
        raw_b = np.ascontiguousarray(b).view(np.uint8).reshape(-1, width)
        differ = (raw_a != raw_b).any(axis=1)
    else:  # strings, objects: element by element
        differ = np.asarray(a != b).reshape(-1)
    n = int(differ.sum())
    if n == 0:
        return None
    msg = f"variable {name!r}: {n} of {differ.size} value(s) differ"
    if a.dtype.kind in "fc":
        with np.errstate(invalid="ignore", over="ignore"):
            gap = np.abs(a.reshape(-1)[differ] - b.reshape(-1)[differ])
        if np.isfinite(gap).any():
            msg += f" (largest difference {np.nanmax(gap):.3g})"
    first = int(np.flatnonzero(differ)[0])
    index = np.unravel_index(first, a.shape) if a.shape else ()
    return msg + (f"; first at {tuple(int(i) for i in index)}: {a.reshape(-1)[first]!r} "
                  f"in the file, {b.reshape(-1)[first]!r} in the replay")


def _attr_differences(where: str, a: Mapping[str, Any], b: Mapping[str, Any],
                      compared: Callable[[str], bool]) -> list[str]:
    out = []
    for key in sorted(set(a) | set(b)):
        if not compared(key):
            continue
        if key not in b:
            out.append(f"{where}attribute {key!r} only in the file")
        elif key not in a:
            out.append(f"{where}attribute {key!r} only in the replay")
        elif not _same_attr(a[key], b[key]):
            out.append(f"{where}attribute {key!r}: {_short(a[key])} in the file, "
                       f"{_short(b[key])} in the replay")
    return out


def _same_attr(a: Any, b: Any) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "O" or b.dtype.kind == "O":
        return a.shape == b.shape and bool(np.all(a == b))
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _short(value: Any, width: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= width else text[:width - 3] + "..."


def compare_trials(committed: xr.Dataset, replayed: xr.Dataset) -> tuple[list[str], list[str]]:
    """``(differences, not_compared)`` between a committed trial and its replay.

    Every variable is compared bitwise (name, dimensions, dtype, values, attributes) but
    the timings (:func:`is_timing`), which are listed in ``not_compared``; the global
    attributes are compared but for the timings and the run's provenance.
    """
    diffs: list[str] = []
    skipped: list[str] = []
    for name in sorted(set(committed.variables) | set(replayed.variables), key=str):
        if name not in replayed.variables:
            diffs.append(f"variable {name!r} only in the file")
            continue
        if name not in committed.variables:
            diffs.append(f"variable {name!r} only in the replay")
            continue
        if is_timing(str(name)):
            skipped.append(str(name))
            continue
        a, b = committed.variables[name], replayed.variables[name]
        if a.dims != b.dims:
            diffs.append(f"variable {name!r}: dimensions {a.dims} in the file, {b.dims} in "
                         "the replay")
            continue
        value = _value_difference(str(name), a.values, b.values)
        if value:
            diffs.append(value)
        diffs += _attr_differences(f"variable {name!r}: ", a.attrs, b.attrs,
                                   lambda k: not is_timing(k))
    diffs += _attr_differences("", committed.attrs, replayed.attrs, _compared_attr)
    return diffs, skipped


# -- replaying one trial --------------------------------------------------------------------


def replay_task(study: Study, attrs: Mapping[str, Any]) -> Task:
    """The trial a file's attributes describe, as the runner would run it today.

    The recorded trial config is resolved against the study's declared settings:
    settings at their default take the default (and its key order), the others the
    recorded value, the grid keys the file's cell. ``ValueError`` if the study no
    longer has one of the recorded settings or refuses a value.
    """
    recorded = json.loads(attrs["trial_config"])
    cell = json.loads(attrs["cell"])
    repeat = int(attrs["repeat"])
    gone = sorted(set(recorded) - set(study.config))
    if gone:
        raise ValueError(f"the study has no setting(s) {', '.join(map(repr, gone))} any more")
    overrides = {k: v for k, v in recorded.items()
                 if k not in study.grid and canonical(v) != canonical(study.config[k])}
    overrides.update({k: [cell[k]] for k in study.grid})
    config = resolve_config(study, overrides=overrides, n_trials=repeat + 1)
    return next(t for t in tasks(study, config) if t.repeat == repeat)


def _replay_one(study: Study, path: Path, scratch: Path) -> TrialVerdict:
    stem = path.name[:-len(".nc")]
    try:
        committed = open_dataset(path, "trial")
    except ValueError as exc:
        return TrialVerdict(stem, "failed", [f"the trial file cannot be read: {exc}"])
    attrs = committed.attrs
    verdict = TrialVerdict(stem, "stale",
                           recorded_wall_time_s=float(attrs.get("trial_wall_time_s", np.nan)))
    if attrs.get("study") != study.name:
        verdict.differences.append(f"a trial of study {attrs.get('study')!r}, not "
                                   f"{study.name!r}")
        return verdict
    try:
        task = replay_task(study, attrs)
    except (KeyError, ValueError, json.JSONDecodeError) as exc:
        verdict.differences.append(f"its config cannot be replayed: {exc}")
        return verdict
    if task.hash != attrs.get("config_hash"):
        verdict.differences.append(
            f"config hash {task.hash} today, {attrs.get('config_hash')} in the file: the study's "
            "version or settings changed since (bump and rerun, or replay with the code of "
            "then)")
    if task.seed != int(attrs.get("seed", -1)):
        verdict.differences.append(f"seed {task.seed} derived today, {attrs.get('seed')} in "
                                   "the file")
    if verdict.differences:
        return verdict
    threads = int(attrs.get("numba_threads", 0)) or None
    try:
        with warnings_in_one_line(True, verdict.notes.append):
            fresh = execute(study.trial, study.name, task.config, task.repeat, task.seed,
                            threads)
    except Exception as exc:
        verdict.status = "failed"
        verdict.differences.append(f"the trial raised {type(exc).__name__}: {exc}")
        return verdict
    verdict.wall_time_s = float(fresh.attrs["trial_wall_time_s"])
    study_config = json.loads(attrs.get("study_config") or canonical(task.config))
    replay_path = result_path(scratch, stem)
    write_result(fresh, replay_path, trial_attrs(study, task, study_config))
    verdict.differences, verdict.not_compared = compare_trials(
        committed, open_dataset(replay_path, "trial replay"))
    replay_path.unlink()
    verdict.status = "differs" if verdict.differences else "identical"
    return verdict


# -- choosing and replaying trials ------------------------------------------------------------


def _wall_time(path: Path) -> float:
    try:
        return float(read_attrs(path, "trial").get("trial_wall_time_s", np.inf))
    except ValueError:
        return np.inf


def _choose(files: list[Path], count: int | None, cheapest: bool,
            stems: Sequence[str]) -> list[Path]:
    if stems:
        by_stem = {p.name[:-len(".nc")]: p for p in files}
        missing = [s for s in stems if s.removesuffix(".nc") not in by_stem]
        if missing:
            raise ValueError(f"no trial file {missing[0]!r} in the results directory")
        files = [by_stem[s.removesuffix(".nc")] for s in stems]
    if cheapest:
        files = sorted(files, key=lambda p: (_wall_time(p), p.name))
    return files if count is None else files[:count]


def _check_manifest(study: Study, out: Path) -> None:
    manifest = out / "config.json"
    if not manifest.is_file():
        return
    try:
        owner = json.loads(manifest.read_text()).get("study")
    except (OSError, ValueError, AttributeError):
        return
    if owner is not None and owner != study.name:
        raise ValueError(f"--out {out} holds study {owner!r}, not {study.name!r}")


def verify(study: Study, out_dir: str | os.PathLike, *, count: int | None = None,
           cheapest: bool = False, trials: Sequence[str] = (),
           log: Callable[[TrialVerdict], None] | None = None) -> VerifyReport:
    """Replay trial files of ``out_dir`` and compare each with its replay, bit for bit.

    Parameters
    ----------
    out_dir
        A results directory of ``study`` (``trials/*.nc``, e.g. ``docs/results/NAME``).
    count
        Replay at most this many trials (default: every one chosen).
    cheapest
        Choose the trials with the smallest recorded ``trial_wall_time_s`` first
        (default: in file-name order).
    trials
        Replay these trials only (file stems, as ``brdf=ward,n_labels=10,repeat=0003``).
    log
        Called with each verdict as it is reached (the command line prints it).

    Raises
    ------
    ValueError
        Before anything runs: no trial files there, ``out_dir`` holding another study,
        a bad ``count`` or an unknown trial.
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    if count is not None and (isinstance(count, bool) or count < 1):
        raise ValueError(f"--count must be an integer >= 1; got {count!r}")
    _check_manifest(study, out)
    files = sorted((out / "trials").glob("*.nc"))
    if not files:
        raise ValueError(f"no trial files in {out / 'trials'}")
    chosen = _choose(files, count, cheapest, trials)
    report = VerifyReport(study.name, out, len(files))
    with tempfile.TemporaryDirectory(prefix="mrfpe-verify-") as scratch:
        for path in chosen:
            verdict = _replay_one(study, path, Path(scratch))
            report.verdicts.append(verdict)
            if log is not None:
                log(verdict)
    report.wall_time_s = time.perf_counter() - t0
    return report
