"""One trial: run it (in-process or on a worker), stamp provenance, write it atomically.

A trial's result is ``trials/<stem>.nc``; a trial that raised leaves its
traceback in ``trials/<stem>.error.txt`` instead (removed once it succeeds).
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import platform
import socket
import time
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.netcdf import write_atomic, write_text_atomic
from mrfpe.study.config import canonical
from mrfpe.study.seeds import Task
from mrfpe.study.spec import Study, TrialFn

__all__ = ["error_path", "execute", "result_path", "trial_attrs", "versions",
           "warnings_in_one_line", "write_error", "write_result"]


def result_path(trials_dir: Path, stem: str) -> Path:
    """Where a trial's result lives."""
    return trials_dir / f"{stem}.nc"


def error_path(trials_dir: Path, stem: str) -> Path:
    """Where a failed trial's traceback lives."""
    return trials_dir / f"{stem}.error.txt"


def versions() -> dict[str, str]:
    """Versions of mrfpe, its main dependencies, Python and the platform (provenance)."""
    import scipy

    from mrfpe._version import __version__

    return {"mrfpe_version": __version__, "numpy_version": np.__version__,
            "scipy_version": scipy.__version__, "xarray_version": xr.__version__,
            "python_version": platform.python_version(), "platform": platform.platform()}


def trial_attrs(study: Study, task: Task, study_config: Mapping[str, Any]) -> dict[str, Any]:
    """What a trial file records of its trial besides the result: the study, the trial's
    config and its hash, its cell, repetition and seed, and the whole run's config."""
    return {"study": study.name, "study_version": study.version, "config_hash": task.hash,
            "trial_config": canonical(task.config), "study_config": canonical(dict(study_config)),
            "cell": canonical(task.cell), "repeat": task.repeat, "seed": task.seed,
            "study_seed": study_config["seed"]}


def _netcdf_attr(value: Any) -> Any:
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, str | int | float | np.integer | np.floating):
        return value
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf" and value.ndim == 1:
        return value
    return json.dumps(value, default=str, sort_keys=True)


def execute(trial: TrialFn, study_name: str, config: dict, repeat: int, seed: int,
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


def write_result(ds: xr.Dataset, path: Path, attrs: Mapping[str, Any]) -> None:
    """Write a trial's Dataset with ``attrs`` added, atomically (tmp, fsync, replace)."""
    ds = ds.copy()
    ds.attrs = {k: _netcdf_attr(v) for k, v in {**ds.attrs, **attrs}.items()}
    for var in ds.variables.values():
        var.attrs = {k: _netcdf_attr(v) for k, v in var.attrs.items()}
    write_atomic(ds, path, "trial")
    error = path.with_name(path.name[:-len(".nc")] + ".error.txt")
    if error.exists():  # an earlier failure of this trial is history now
        error.unlink()


@contextlib.contextmanager
def warnings_in_one_line(active: bool, note: Callable[[str], None]) -> Iterator[None]:
    """Hold the trials' warnings while a progress bar is drawn, then note them as one
    line per run, counted by category and cause (the text before the first colon)."""
    if not active:
        yield
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    if caught:
        causes = Counter((w.category.__name__, str(w.message).split(":", 1)[0])
                         for w in caught)
        note(f"{len(caught)} warning(s) during the trials: " + "; ".join(
            f"{cat} ×{n} ({cause})" for (cat, cause), n in causes.most_common()))


def write_error(path: Path, header: str, tb: str) -> None:
    """Save a failed trial's traceback (atomically, like the results)."""
    write_text_atomic(f"{header}\n\n{tb}", path, "trial traceback")
