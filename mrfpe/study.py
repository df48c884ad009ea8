"""Reproducible studies: a config, a seed, and independent trials saved as they finish.

A :class:`Study` is a default configuration (the thesis's settings), a reduced
``quick`` configuration, a *trial* function and a *summary* function. Its
trials are the cartesian product of the config keys named in ``grid`` (each a
list, e.g. ``n_labels = [10, 20, 30, 40]``) with ``range(n_trials)``
repetitions. A trial sees the config *specialised to its cell*: the grid keys
hold one value each (``config["n_labels"] == 20``).

The runner (:func:`run`, ``mrfpe study run``)

- gives each trial its own seed, ``SeedSequence(config["seed"],
  spawn_key=(repeat, *cell_words))`` -- for a study without a grid this is
  exactly ``SeedSequence(seed).spawn(n_trials)[repeat]`` -- so results depend
  neither on the order in which trials run nor on which worker runs them, nor
  on which other cells are in the grid (``--set n_labels=20`` reproduces the
  20-label trials of the full run);
- writes every trial as netCDF (``<out>/trials/<cell>,repeat=NNNN.nc``) the
  moment it finishes, atomically (temporary file + ``os.replace``), with the
  trial's config, its hash, seed, timing and the package versions in the
  attributes;
- skips trials whose file exists with the same config hash, so rerunning a
  command resumes it (a kill loses at most the trials in flight); a file with
  a *different* hash is never silently reused: the run stops and says which
  settings differ (``mismatch="recompute"`` overwrites instead);
- runs in-process by default, or on an existing ``dask.distributed`` cluster
  (``scheduler=ADDRESS``), writing each result on the client as it arrives
  (``as_completed``), so workers need no shared file system;
- calls the study's summary once every trial is on disk (``report.md`` and
  PNGs in the output directory) and prints its table.

Where studies come from (:func:`available`): the built-in studies are the
modules of the :mod:`mrfpe.studies` package (so they ship with every install
and dask workers import them by name); a user's own study is a file
``studies/<name>/study.py`` under the current directory (DESIGN.md's layout),
or any ``.py`` path given as the name. A study module defines ``STUDY``.
"""

from __future__ import annotations

import copy
import hashlib
import importlib
import importlib.util
import json
import os
import pkgutil
import platform
import socket
import sys
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from itertools import product
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import xarray as xr

__all__ = [
    "RunReport",
    "Study",
    "Task",
    "apply_overrides",
    "available",
    "by_cell",
    "cli",
    "config_hash",
    "get",
    "load_file",
    "resolve_config",
    "run",
    "tasks",
    "trial_seed",
]

TrialFn = Callable[[dict, int, int], xr.Dataset]
SummariseFn = Callable[[list[xr.Dataset], dict, Path], str]
_RESERVED = ("n_trials", "seed")
_SCALARS = (str, int, float, bool)


@dataclass(frozen=True)
class Study:
    """One reproducible experiment.

    Parameters
    ----------
    name
        Identifier used on the command line.
    doc
        Description; its first line is the summary shown by ``mrfpe study
        list``, and it must contain a line starting ``Full run:`` that states
        the full run's expected time.
    config
        Default settings (the thesis's), JSON-serialisable and flat. Must hold
        ``n_trials`` (repetitions per cell) and ``seed`` (the study seed).
    quick
        Overrides of ``config`` for ``--quick`` (reduced size, same code path).
    trial
        ``trial(config, repeat, seed) -> xarray.Dataset``: one trial, given the
        config specialised to its cell, its repetition index and its own seed.
    summarise
        ``summarise(results, config, out_dir) -> str``: writes ``report.md``
        and figures into ``out_dir`` from all trial Datasets (in task order)
        and returns a short markdown table to print.
    grid
        Config keys whose list values are crossed to form the cells.
    shared_seed
        Grid keys across which trials of the same repetition share their seed
        (common random numbers: e.g. the same surface for every label count).
    version
        Bump when the trial function's meaning changes: it enters the config
        hash, so old trial files are not reused.
    """

    name: str
    doc: str
    config: Mapping[str, Any]
    quick: Mapping[str, Any]
    trial: TrialFn
    summarise: SummariseFn
    grid: tuple[str, ...] = ()
    shared_seed: tuple[str, ...] = ()
    version: int = 1
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        for key in _RESERVED:
            if key not in self.config:
                raise ValueError(f"study {self.name!r}: config must define {key!r}")
        unknown = sorted(set(self.quick) - set(self.config))
        if unknown:
            raise ValueError(f"study {self.name!r}: quick sets unknown keys {unknown}")
        for key in self.grid:
            if key not in self.config or not isinstance(self.config[key], list):
                raise ValueError(f"study {self.name!r}: grid key {key!r} must be a list in config")
        if not set(self.shared_seed) <= set(self.grid):
            raise ValueError(f"study {self.name!r}: shared_seed must be grid keys")
        if "Full run:" not in self.doc:
            raise ValueError(f"study {self.name!r}: doc must state the full run's expected time "
                             "in a line 'Full run: ...'")
        json.dumps(dict(self.config))  # must be JSON-serialisable

    @property
    def summary(self) -> str:
        return next((ln.strip() for ln in self.doc.splitlines() if ln.strip()), "")

    @property
    def full_run(self) -> str:
        """The first sentence after ``Full run:`` (the expected time of the full run)."""
        text = " ".join(self.doc.split("Full run:", 1)[1].split("\n\n", 1)[0].split())
        return text.split(". ", 1)[0].rstrip(".")


# -- configuration -------------------------------------------------------------------------


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _coerce(key: str, value: Any, default: Any) -> Any:
    """``value`` in the type of ``default`` (int -> float widening allowed), else ValueError."""
    if default is None or value is None:
        return value
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(default, int) and not isinstance(value, bool):
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif isinstance(default, float) and not isinstance(value, bool):
        if isinstance(value, (int, float)):
            return float(value)
    elif isinstance(default, str):
        if isinstance(value, str):
            return value
    elif isinstance(default, list):
        if isinstance(value, list):
            if not default or len({type(d) for d in default}) > 1:
                return value  # no single element type to check against
            return [_coerce(key, v, default[0]) for v in value]
    elif isinstance(default, dict):
        if isinstance(value, dict):
            return value
    raise ValueError(f"setting {key!r} expects a value like {default!r}; got {value!r}")


def apply_overrides(study: Study, config: Mapping[str, Any],
                    overrides: Mapping[str, Any] | Sequence[str]) -> dict:
    """``config`` with ``overrides`` applied and checked against the study's defaults.

    ``overrides`` is a mapping or a list of ``key=value`` strings (values read
    as JSON where possible, as ``--set`` does). A grid key given one scalar
    becomes a one-element list. Unknown keys and values of the wrong type
    raise ``ValueError``.
    """
    if not isinstance(overrides, Mapping):
        from mrfpe.cli import parse_assignments

        bad = [s for s in overrides if "=" not in s]
        if bad:
            raise ValueError(f"--set expects key=value; got {bad[0]!r}")
        overrides = parse_assignments(overrides)
    out = copy.deepcopy(dict(config))
    for key, value in overrides.items():
        if key not in study.config:
            raise ValueError(f"unknown setting {key!r} for study {study.name!r}; "
                             f"settings: {', '.join(sorted(study.config))}")
        if key in study.grid and not isinstance(value, list):
            value = [value]
        out[key] = _coerce(key, value, study.config[key])
    return out


def resolve_config(study: Study, *, quick: bool = False,
                   overrides: Mapping[str, Any] | Sequence[str] = (),
                   n_trials: int | None = None) -> dict:
    """The effective config: defaults, then ``quick``, then ``overrides``, then ``n_trials``."""
    cfg = copy.deepcopy(dict(study.config))
    if quick:
        cfg = apply_overrides(study, cfg, dict(study.quick))
    cfg = apply_overrides(study, cfg, overrides)
    if n_trials is not None:
        cfg = apply_overrides(study, cfg, {"n_trials": n_trials})
    if isinstance(cfg["n_trials"], bool) or not isinstance(cfg["n_trials"], int) \
            or cfg["n_trials"] < 1:
        raise ValueError(f"n_trials must be an integer >= 1; got {cfg['n_trials']!r}")
    if isinstance(cfg["seed"], bool) or not isinstance(cfg["seed"], int) or cfg["seed"] < 0:
        raise ValueError(f"seed must be an integer >= 0; got {cfg['seed']!r}")
    for key in study.grid:
        vals = cfg[key]
        if not vals:
            raise ValueError(f"grid setting {key!r} must be a non-empty list")
        if not all(isinstance(v, _SCALARS) for v in vals):
            raise ValueError(f"grid setting {key!r} must list scalars; got {vals!r}")
        if len({_canonical(v) for v in vals}) != len(vals):
            raise ValueError(f"grid setting {key!r} has duplicate values: {vals!r}")
    return cfg


def config_hash(study: Study, trial_config: Mapping[str, Any]) -> str:
    """Hash of what determines a trial's result: study name, version and trial config."""
    blob = _canonical({"study": study.name, "version": study.version,
                       "config": dict(trial_config)})
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _cell_words(cell: Mapping[str, Any]) -> tuple[int, ...]:
    if not cell:
        return ()
    digest = hashlib.sha256(_canonical(dict(cell)).encode()).digest()
    return tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))


def trial_seed(study_seed: int, repeat: int, cell: Mapping[str, Any] = ()) -> int:
    """The integer seed of one trial (63 bits).

    ``SeedSequence(study_seed, spawn_key=(repeat, *words(cell)))``, with
    ``words`` four 32-bit words of a hash of the cell; for an empty cell this
    is child ``repeat`` of ``SeedSequence(study_seed).spawn(n)``.
    """
    ss = np.random.SeedSequence(study_seed, spawn_key=(int(repeat), *_cell_words(dict(cell))))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))


@dataclass(frozen=True)
class Task:
    """One trial of a resolved study: its cell, repetition, config, seed and file."""

    index: int
    cell: dict
    repeat: int
    config: dict
    seed: int
    hash: str
    stem: str


def _stem(cell: Mapping[str, Any], repeat: int) -> str:
    def clean(v: Any) -> str:
        s = str(v)
        return "".join(c if c.isalnum() or c in ".+-" else "_" for c in s)

    return "".join(f"{k}={clean(v)}," for k, v in cell.items()) + f"repeat={repeat:04d}"


def tasks(study: Study, config: Mapping[str, Any]) -> list[Task]:
    """Every trial of ``config`` (resolved), repetition-major, cells in grid order."""
    base = {k: v for k, v in config.items() if k not in study.grid and k != "n_trials"}
    cells = [dict(zip(study.grid, vals)) for vals in product(*(config[k] for k in study.grid))]
    out = []
    for repeat in range(config["n_trials"]):
        for cell in cells:
            tcfg = {**base, **cell}
            seed_cell = {k: v for k, v in cell.items() if k not in study.shared_seed}
            out.append(Task(len(out), cell, repeat, tcfg,
                            trial_seed(config["seed"], repeat, seed_cell),
                            config_hash(study, tcfg), _stem(cell, repeat)))
    return out


# -- discovery -----------------------------------------------------------------------------


def _study_of(module: ModuleType, where: str) -> Study:
    study = getattr(module, "STUDY", None)
    if not isinstance(study, Study):
        raise ValueError(f"{where} does not define STUDY = mrfpe.study.Study(...)")
    object.__setattr__(study, "source", where)
    return study


def load_file(path: str | os.PathLike) -> Study:
    """Load a study from a Python file that defines ``STUDY``."""
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"no study file {path}")
    mod_name = "mrfpe_user_study_" + hashlib.sha256(str(path).encode()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(mod_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module  # so pickling and dataclasses can find it
    try:
        spec.loader.exec_module(module)
    except Exception:
        sys.modules.pop(mod_name, None)
        raise
    return _study_of(module, str(path))


def _local_dir() -> Path:
    return Path.cwd() / "studies"


def available(broken: dict[str, str] | None = None) -> dict[str, Study]:
    """Built-in studies, then ``./studies/<name>/study.py`` (a local one shadows a built-in).

    A study that fails to load is left out; pass a dict as ``broken`` to
    receive ``{name: error}`` for those.
    """
    import mrfpe.studies as pkg

    found: dict[str, Study] = {}

    def add(name: str, load: Callable[[], Study]) -> None:
        try:
            found[name] = load()
        except Exception as exc:  # one broken study must not hide the others
            if broken is not None:
                broken[name] = f"{type(exc).__name__}: {exc}"

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if not info.name.startswith("_"):
            mod = f"{pkg.__name__}.{info.name}"
            add(info.name, lambda mod=mod: _study_of(importlib.import_module(mod), mod))
    local = _local_dir()
    if local.is_dir():
        for path in sorted(local.glob("*/study.py")):
            add(path.parent.name, lambda path=path: load_file(path))
    return found


def get(name: str) -> Study:
    """The study called ``name``, or loaded from ``name`` if it is a path to a ``.py`` file."""
    if name.endswith(".py") or os.sep in name:
        return load_file(name)
    local = _local_dir() / name / "study.py"
    if local.is_file():
        return load_file(local)
    try:
        module = importlib.import_module(f"mrfpe.studies.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"mrfpe.studies.{name}":
            raise
        names = ", ".join(sorted(available())) or "(none)"
        raise ValueError(f"unknown study {name!r}; available: {names}") from None
    return _study_of(module, f"mrfpe.studies.{name}")


# -- one trial -----------------------------------------------------------------------------


def _versions() -> dict[str, str]:
    import scipy

    from mrfpe import __version__

    return {"mrfpe_version": __version__, "numpy_version": np.__version__,
            "scipy_version": scipy.__version__, "xarray_version": xr.__version__,
            "python_version": platform.python_version(), "platform": platform.platform()}


def _netcdf_attr(value: Any) -> Any:
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, str | int | float | np.integer | np.floating):
        return value
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf" and value.ndim == 1:
        return value
    return json.dumps(value, default=str, sort_keys=True)


def _execute(trial: TrialFn, study_name: str, config: dict, repeat: int, seed: int,
             numba_threads: int | None = None) -> xr.Dataset:
    """Run one trial (in-process or on a dask worker) and stamp its provenance.

    ``numba_threads`` caps the kernels' threads for this trial (restored after):
    on a cluster, the host's cores divided among the tasks it runs at once.
    """
    import numba

    from mrfpe.threads import limit_threads

    cap = numba.get_num_threads() if numba_threads is None else numba_threads
    with limit_threads(cap) as used:
        t0 = time.perf_counter()
        ds = trial(copy.deepcopy(config), repeat, seed)
        wall = time.perf_counter() - t0
    if not isinstance(ds, xr.Dataset):
        raise TypeError(f"study {study_name!r}: trial must return an xarray.Dataset, "
                        f"got {type(ds).__name__}")
    ds = ds.load()
    ds.attrs.update({"trial_wall_time_s": wall, "host": socket.gethostname(),
                     "pid": os.getpid(), "numba_threads": used})
    return ds


def _execute_pickled(blob: bytes, study_name: str, config: dict, repeat: int, seed: int,
                     threads_by_host: Mapping[str, int] | None = None) -> xr.Dataset:
    import cloudpickle

    threads = None
    if threads_by_host:
        from distributed import get_worker

        threads = threads_by_host.get(get_worker().address.rsplit(":", 1)[0])
    return _execute(cloudpickle.loads(blob), study_name, config, repeat, seed, threads)


def _threads_by_host(client: Any) -> dict[str, int]:
    """Kernel threads per task on each host: its cores over the task slots it runs.

    Two workers of one thread each on a two-core machine give one numba thread
    per trial, not two (which would run four busy threads on two cores).
    """
    workers = client.scheduler_info(n_workers=-1)["workers"]
    cores = client.run(os.cpu_count)
    slots: dict[str, int] = {}
    host_cores: dict[str, int] = {}
    for address, info in workers.items():
        host = address.rsplit(":", 1)[0]
        slots[host] = slots.get(host, 0) + int(info.get("nthreads", 1))
        host_cores[host] = int(cores.get(address) or 1)
    return {h: max(1, host_cores[h] // max(1, n)) for h, n in slots.items()}


def _write(ds: xr.Dataset, path: Path) -> None:
    """Write ``ds`` to ``path`` atomically: a temporary file in the same directory, then replace."""
    ds = ds.copy()
    ds.attrs = {k: _netcdf_attr(v) for k, v in ds.attrs.items()}
    for var in ds.variables.values():
        var.attrs = {k: _netcdf_attr(v) for k, v in var.attrs.items()}
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        ds.to_netcdf(tmp, engine="netcdf4")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _read_attrs(path: Path) -> dict | None:
    """Global attributes of a trial file (netCDF4 directly: ~10× faster than xarray)."""
    import netCDF4

    try:
        with netCDF4.Dataset(path) as nc:
            return {k: nc.getncattr(k) for k in nc.ncattrs()}
    except Exception:  # unreadable (e.g. a disk error): treat as missing
        return None


# -- the run -------------------------------------------------------------------------------


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

    @property
    def ok(self) -> bool:
        return not self.failures

    def text(self) -> str:
        lines = [f"study {self.study}: {self.n_trials} trials "
                 f"({self.n_computed} computed, {self.n_skipped} already done, "
                 f"{len(self.failures)} failed) in {self.wall_time_s:.1f} s -> {self.out_dir}"]
        for stem, err in self.failures[:10]:
            lines.append(f"FAILED {stem}: {err.strip().splitlines()[-1]}")
        if len(self.failures) > 10:
            lines.append(f"... and {len(self.failures) - 10} more failures")
        if self.table:
            lines += ["", self.table]
        return "\n".join(lines)


def _diff(old: Mapping, new: Mapping) -> str:
    keys = sorted(set(old) | set(new))
    parts = [f"{k}: {old.get(k, '(unset)')!r} -> {new.get(k, '(unset)')!r}"
             for k in keys if _canonical(old.get(k)) != _canonical(new.get(k))]
    return "; ".join(parts) or "(same settings; study version or code changed)"


def _check_existing(study: Study, todo: list[Task], trials_dir: Path,
                    mismatch: str) -> tuple[list[Task], int]:
    pending, done, stale = [], 0, []
    for task in todo:
        path = trials_dir / f"{task.stem}.nc"
        attrs = _read_attrs(path) if path.exists() else None
        if attrs is None:
            pending.append(task)
        elif attrs.get("config_hash") == task.hash:
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


def run(study: Study, config: Mapping[str, Any], out_dir: str | os.PathLike, *,
        scheduler: str | None = None, progress: bool = True, mismatch: str = "error",
        summarise: bool = True) -> RunReport:
    """Run (or resume) every trial of ``study`` under ``config``, then summarise.

    Parameters
    ----------
    config
        A resolved config (:func:`resolve_config`).
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
    """
    if mismatch not in ("error", "recompute"):
        raise ValueError(f"mismatch must be 'error' or 'recompute'; got {mismatch!r}")
    t0 = time.perf_counter()
    out = Path(out_dir)
    trials_dir = out / "trials"
    trials_dir.mkdir(parents=True, exist_ok=True)
    todo = tasks(study, config)
    pending, n_done = _check_existing(study, todo, trials_dir, mismatch)
    report = RunReport(study.name, out, len(todo), n_skipped=n_done)
    versions = _versions()
    manifest = {"study": study.name, "version": study.version, "source": study.source,
                "config": dict(config), "n_tasks": len(todo),
                "started_utc": datetime.now(UTC).isoformat(timespec="seconds"), **versions}
    tmp = out / f".config.json.{uuid.uuid4().hex[:8]}.tmp"
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, out / "config.json")

    def finish(task: Task, ds: xr.Dataset) -> None:
        ds.attrs.update({
            "study": study.name, "study_version": study.version,
            "config_hash": task.hash, "trial_config": _canonical(task.config),
            "study_config": _canonical(dict(config)), "cell": _canonical(task.cell),
            "repeat": task.repeat, "seed": task.seed, "study_seed": config["seed"],
            "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"), **versions})
        _write(ds, trials_dir / f"{task.stem}.nc")
        report.n_computed += 1

    from tqdm.auto import tqdm

    bar = tqdm(total=len(todo), initial=n_done, desc=study.name, unit="trial",
               disable=not progress or not pending, dynamic_ncols=True)
    try:
        if scheduler is None:
            for task in pending:
                try:
                    finish(task, _execute(study.trial, study.name, task.config, task.repeat,
                                          task.seed))
                except Exception:
                    report.failures.append((task.stem, traceback.format_exc()))
                bar.update(1)
                bar.set_postfix(failed=len(report.failures), refresh=False)
        else:
            _run_dask(study, pending, scheduler, finish, report, bar)
    finally:
        bar.close()
    if report.ok and summarise:
        results = [xr.load_dataset(trials_dir / f"{t.stem}.nc", engine="netcdf4") for t in todo]
        report.table = study.summarise(results, dict(config), out) or ""
    report.wall_time_s = time.perf_counter() - t0
    return report


def _run_dask(study: Study, pending: list[Task], address: str,
              finish: Callable[[Task, xr.Dataset], None], report: RunReport, bar: Any) -> None:
    try:
        import cloudpickle
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ValueError("--scheduler needs dask.distributed: pip install 'mrfpe[dist]'") from exc
    # The trial function travels as cloudpickle bytes, unpickled inside the task: a study
    # loaded from a file is not importable on the workers, so its module goes by value,
    # and any unpickling error becomes a failed trial instead of a stuck worker.
    module = sys.modules.get(study.trial.__module__)
    by_value = module is not None and not study.trial.__module__.startswith("mrfpe.")
    if by_value:
        cloudpickle.register_pickle_by_value(module)
    try:
        blob = cloudpickle.dumps(study.trial)
    finally:
        if by_value:
            cloudpickle.unregister_pickle_by_value(module)
    with Client(address) as client:
        threads = _threads_by_host(client)
        futures = {}
        for task in pending:
            key = f"{study.name}-{task.stem}-{task.hash}-{uuid.uuid4().hex[:8]}"
            fut = client.submit(_execute_pickled, blob, study.name, task.config, task.repeat,
                                task.seed, threads, pure=False, key=key)
            futures[fut] = task
        try:
            for fut in as_completed(list(futures)):
                task = futures.pop(fut)
                try:
                    finish(task, fut.result())
                except Exception:
                    report.failures.append((task.stem, traceback.format_exc()))
                fut.release()
                bar.update(1)
                bar.set_postfix(failed=len(report.failures), refresh=False)
        except BaseException:
            client.cancel(list(futures))
            raise


# -- summaries -----------------------------------------------------------------------------


def by_cell(results: Iterable[xr.Dataset], *keys: str) -> dict[tuple, list[xr.Dataset]]:
    """Group trial Datasets by the values of grid ``keys`` in their cell (insertion order)."""
    groups: dict[tuple, list[xr.Dataset]] = {}
    for ds in results:
        cell = json.loads(ds.attrs["cell"])
        groups.setdefault(tuple(cell[k] for k in keys), []).append(ds)
    return groups


# -- command line --------------------------------------------------------------------------


def _list_text() -> str:
    broken: dict[str, str] = {}
    studies = available(broken)
    rows = [(s.name, str(len(tasks(s, resolve_config(s)))), s.full_run, s.summary)
            for s in studies.values()]
    rows += [(name, "–", "–", f"BROKEN: {err}") for name, err in broken.items()]
    if not rows:
        return "no studies found"
    head = ("name", "trials", "full run", "description")
    w = [max(len(r[i]) for r in [*rows, head]) for i in range(3)]
    lines = [f"{head[0]:<{w[0]}}  {head[1]:>{w[1]}}  {head[2]:<{w[2]}}  {head[3]}"]
    lines.append("-" * len(lines[0]))
    lines += [f"{a:<{w[0]}}  {b:>{w[1]}}  {c:<{w[2]}}  {d}" for a, b, c, d in rows]
    return "\n".join(lines)


def default_out_dir(study: Study, quick: bool) -> Path:
    """``studies/<name>/out`` (``out-quick`` with ``--quick``) under the current directory."""
    return Path("studies") / study.name / ("out-quick" if quick else "out")


def cli(args: Any) -> int:
    """Entry point of ``mrfpe study list|run`` (arguments parsed by :mod:`mrfpe.cli`)."""
    if args.study_command == "list":
        print(_list_text())
        return 0
    study = get(args.name)
    config = resolve_config(study, quick=args.quick, overrides=args.set, n_trials=args.trials)
    out = Path(args.out) if args.out else default_out_dir(study, args.quick)
    print(f"study {study.name} ({study.source}); full run: {study.full_run}")
    try:
        report = run(study, config, out, scheduler=args.scheduler, progress=True)
    except KeyboardInterrupt:
        done = len(list((out / "trials").glob("*.nc")))
        print(f"interrupted: {done} trial file(s) in {out / 'trials'}; "
              "rerun the same command to resume", file=sys.stderr)
        return 130
    print(report.text())
    if report.ok:
        print(f"report: {out / 'report.md'}")
    return 0 if report.ok else 1
