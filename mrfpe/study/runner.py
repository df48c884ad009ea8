"""Running (or resuming) a study into an output directory, safely.

The output directory is claimed with an exclusive ``fcntl.flock`` on
``OUT/.lock`` for the whole run, so a second ``mrfpe study run`` on the same
directory stops at once instead of interleaving files with the first. Under
the lock, temporary files left by a killed run are removed, trial files that
cannot be read are reported and computed again, and each new result is
written atomically (:func:`mrfpe.netcdf.write_atomic`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import xarray as xr

from mrfpe.netcdf import (
    TMP_SUFFIX,
    DiskFullError,
    open_dataset,
    read_attrs,
    tmp_path_for,
    write_text_atomic,
)
from mrfpe.study.config import canonical
from mrfpe.study.seeds import Task, tasks
from mrfpe.study.spec import Study
from mrfpe.study.trial import (
    error_path,
    execute,
    result_path,
    trial_attrs,
    versions,
    warnings_in_one_line,
    write_error,
    write_result,
)

__all__ = ["LOCK_NAME", "RunReport", "run"]

LOCK_NAME = ".lock"


@dataclass
class RunReport:
    """What :func:`run` did."""

    study: str
    out_dir: Path
    n_trials: int
    n_skipped: int = 0
    n_computed: int = 0
    failures: list[tuple[str, str]] = field(default_factory=list)
    wall_time_s: float = 0.0
    table: str = ""
    notes: list[str] = field(default_factory=list)
    #: trials whose traceback file was written (a full disk may have prevented it)
    error_files: set[str] = field(default_factory=set)

    @property
    def ok(self) -> bool:
        return not self.failures

    def text(self) -> str:
        lines = [f"study {self.study}: {self.n_trials} trials "
                 f"({self.n_computed} computed, {self.n_skipped} already done, "
                 f"{len(self.failures)} failed) in {self.wall_time_s:.1f} s -> {self.out_dir}"]
        lines += self.notes
        trials_dir = self.out_dir / "trials"
        for stem, err in self.failures[:10]:
            last = (err.strip().splitlines() or ["(no message)"])[-1]
            where = (f"traceback: {error_path(trials_dir, stem)}" if stem in self.error_files
                     else "traceback not saved")
            lines.append(f"FAILED {stem}: {last} ({where})")
        if len(self.failures) > 10:
            lines.append(f"... and {len(self.failures) - 10} more failures "
                         f"(tracebacks: {trials_dir}/*.error.txt)")
        if self.table:
            lines += ["", self.table]
        return "\n".join(lines)


def _prepare(out: Path) -> Path:
    """Create ``out/trials`` and prove a file can be written there; else ``ValueError``."""
    trials_dir = out / "trials"
    try:
        trials_dir.mkdir(parents=True, exist_ok=True)
        probe = tmp_path_for(trials_dir / "probe")
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"--out {out}: cannot write there ({exc.strerror or exc})") from None
    return trials_dir


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``out`` for the block; ``ValueError`` if another run has it."""
    import fcntl

    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            raise ValueError(f"--out {out} is in use by another study run ({holder}); wait for "
                             "it to finish or choose another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock; the file stays (unlinking would race a waiter)


def _remove_stray_tmp(out: Path, trials_dir: Path) -> int:
    """Delete temporary files of an interrupted run (safe: we hold the lock)."""
    n = 0
    for directory in (out, trials_dir):
        for p in directory.glob(f".*{TMP_SUFFIX}"):
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
                n += 1
    return n


def _diff(old: Mapping, new: Mapping) -> str:
    keys = sorted(set(old) | set(new))
    parts = [f"{k}: {old.get(k, '(unset)')!r} -> {new.get(k, '(unset)')!r}"
             for k in keys if canonical(old.get(k)) != canonical(new.get(k))]
    return "; ".join(parts) or "(same settings; study version or code changed)"


def _check_existing(study: Study, todo: list[Task], trials_dir: Path, mismatch: str,
                    notes: list[str]) -> tuple[list[Task], int]:
    pending, done, stale = [], 0, []
    for task in todo:
        path = result_path(trials_dir, task.stem)
        if not path.exists():
            pending.append(task)
            continue
        try:
            attrs = read_attrs(path, "trial")
            _check_json_attrs(attrs, path)
        except ValueError as exc:  # truncated or corrupt: say so, then compute it again
            notes.append(f"{exc}; computing it again")
            pending.append(task)
            continue
        if attrs.get("config_hash") == task.hash:
            done += 1
        else:
            stale.append((task, attrs))
            pending.append(task)
    if stale and mismatch == "error":
        task, attrs = stale[0]
        try:
            old = json.loads(attrs.get("trial_config", "{}"))
        except json.JSONDecodeError:
            old = {}
        raise ValueError(
            f"{trials_dir} holds {len(stale)} trial(s) of study {study.name!r} computed with a "
            f"different configuration ({_diff(old, task.config)}); they are not reused. "
            "Choose another --out, or delete those files to recompute them.")
    return pending, done


def _check_json_attrs(attrs: dict, path: Path) -> None:
    """ValueError naming ``path`` when a trial's JSON attribute does not parse.

    A sealed trial file is checked by its checksum; this catches a file without
    one (an earlier version's, or one edited in place) whose attributes were damaged.
    """
    for key in ("cell", "trial_config"):
        if key in attrs:
            try:
                json.loads(attrs[key])
            except (TypeError, json.JSONDecodeError):
                raise ValueError(f"{path}: damaged trial file: its {key!r} attribute is not "
                                 f"JSON") from None


def _check_owner(study: Study, out: Path, force: bool) -> None:
    """Refuse (without ``force``) an ``out`` whose ``config.json`` belongs to another study."""
    manifest = out / "config.json"
    if force or not manifest.is_file():
        return
    try:
        other = json.loads(manifest.read_text()).get("study")
    except (OSError, ValueError, AttributeError):
        other = None
    if other is None:
        raise ValueError(f"--out {out} holds a config.json that is not a study manifest; "
                         "choose another --out, or pass --force to write there anyway")
    if other != study.name:
        raise ValueError(f"--out {out} holds study {other!r}; running {study.name!r} there "
                         "would replace its config.json and report.md and mix the trial "
                         "files: choose another --out, or pass --force")


def _write_manifest(study: Study, config: Mapping[str, Any], out: Path, n_tasks: int,
                    provenance: Mapping[str, str]) -> None:
    manifest = {"study": study.name, "version": study.version, "source": study.source,
                "config": dict(config), "n_tasks": n_tasks,
                "started_utc": datetime.now(UTC).isoformat(timespec="seconds"), **provenance}
    write_text_atomic(json.dumps(manifest, indent=2, sort_keys=True) + "\n",
                      out / "config.json", "study manifest")


def run(study: Study, config: Mapping[str, Any], out_dir: str | os.PathLike, *,
        scheduler: str | None = None, progress: bool = True, mismatch: str = "error",
        summarise: bool = True, log: Callable[[str], None] | None = None,
        force: bool = False) -> RunReport:
    """Run (or resume) every trial of ``study`` under ``config``, then summarise.

    Parameters
    ----------
    config
        A resolved config (:func:`mrfpe.study.resolve_config`).
    out_dir
        Output directory: ``trials/*.nc``, ``config.json``, ``report.md``, PNGs.
    scheduler
        Address of a running ``dask.distributed`` scheduler; ``None`` runs the
        trials one after another in this process.
    mismatch
        ``"error"`` (default): stop if a trial file exists with another config
        hash; ``"recompute"``: overwrite such files.
    summarise
        Call the study's summary once all trials are on disk.
    log
        Called with one-line notes as they arise (stray files removed, unreadable
        trial files recomputed); they are also in :attr:`RunReport.notes`.
    force
        Run even if ``out_dir`` holds another study (its ``config.json`` names it);
        trial files of the same name but another configuration are recomputed.

    Raises
    ------
    ValueError
        Before any trial runs: ``out_dir`` not writable, in use by another run or
        holding another study (without ``force``), scheduler unreachable, trial
        files of another configuration.
    DiskFullError
        When a file cannot be written for lack of space: the run stops there (the
        trials written so far are kept; rerun to resume).
    """
    if mismatch not in ("error", "recompute"):
        raise ValueError(f"mismatch must be 'error' or 'recompute'; got {mismatch!r}")
    if force:  # overwriting is what was asked for: trial files of the same name are replaced
        mismatch = "recompute"
    t0 = time.perf_counter()
    out = Path(out_dir)
    todo = tasks(study, config)  # first: a trial count beyond the budget creates nothing
    trials_dir = _prepare(out)
    report = RunReport(study.name, out, len(todo))

    def note(msg: str) -> None:
        report.notes.append(msg)
        if log is not None:
            log(msg)

    with contextlib.ExitStack() as stack:
        stack.enter_context(_locked(out))
        _check_owner(study, out, force)
        client = None
        if scheduler is not None:
            from mrfpe.study.cluster import connect

            client = stack.enter_context(connect(scheduler))
        n_tmp = _remove_stray_tmp(out, trials_dir)
        if n_tmp:
            note(f"removed {n_tmp} temporary file(s) left by an interrupted run")
        notes: list[str] = []
        pending, report.n_skipped = _check_existing(study, todo, trials_dir, mismatch, notes)
        for msg in notes:
            note(msg)
        provenance = versions()
        _write_manifest(study, config, out, len(todo), provenance)
        with warnings_in_one_line(progress and client is None and bool(pending),
                                   report.notes.append):
            _run_pending(study, config, pending, trials_dir, provenance, report, client,
                         progress)
        if report.ok and summarise:
            results = [open_dataset(result_path(trials_dir, t.stem), "trial") for t in todo]
            report.table = study.summarise(results, dict(config), out) or ""
    report.wall_time_s = time.perf_counter() - t0
    return report


def _run_pending(study: Study, config: Mapping[str, Any], pending: list[Task], trials_dir: Path,
                 provenance: Mapping[str, str], report: RunReport, client: Any,
                 progress: bool) -> None:
    def finish(task: Task, ds: xr.Dataset) -> None:
        write_result(ds, result_path(trials_dir, task.stem), {
            **trial_attrs(study, task, config),
            "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"), **provenance})
        report.n_computed += 1

    def fail(task: Task, tb: str) -> None:
        report.failures.append((task.stem, tb))
        header = (f"study {study.name!r}, trial {task.stem} (seed {task.seed}) failed.\n"
                  f"trial config: {canonical(task.config)}")
        try:
            write_error(error_path(trials_dir, task.stem), header, tb)
            report.error_files.add(task.stem)
        except DiskFullError:
            raise
        except OSError:  # the failure itself is still reported
            pass

    from tqdm.auto import tqdm

    bar = tqdm(total=report.n_trials, initial=report.n_skipped, desc=study.name, unit="trial",
               disable=not progress or not pending, dynamic_ncols=True)

    def tick() -> None:
        bar.update(1)
        bar.set_postfix(failed=len(report.failures), refresh=False)

    try:
        if client is None:
            for task in pending:
                try:
                    finish(task, execute(study.trial, study.name, task.config, task.repeat,
                                         task.seed))
                except DiskFullError:
                    raise  # every further trial would be lost too: stop here
                except Exception:
                    fail(task, traceback.format_exc())
                tick()
        else:
            from mrfpe.study.cluster import run_on_cluster

            run_on_cluster(study, pending, client, finish, fail, tick)
    finally:
        bar.close()
