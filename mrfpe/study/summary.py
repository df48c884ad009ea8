"""Summarising the trial files already in an output directory, without running any.

A full-size study can take longer than one sitting; its trial files are
committed as they finish and the run resumes later. :func:`summarise_existing`
writes the study's report from the trials on disk meanwhile: by default only
the grid cells whose every repetition is there (so each table is a whole
column), or every trial found with ``partial=True``. It takes no lock, so it
may run beside a ``mrfpe study run`` on the same directory (whose own summary,
at its end, then replaces this one).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mrfpe.netcdf import open_dataset, read_attrs
from mrfpe.study.config import canonical
from mrfpe.study.seeds import tasks
from mrfpe.study.spec import Study
from mrfpe.study.trial import result_path

__all__ = ["Summary", "summarise_existing"]


@dataclass
class Summary:
    """What :func:`summarise_existing` found and wrote."""

    cells: list[dict]       # the grid cells summarised
    n_trials: int           # trial files used
    n_missing: int          # trials of the config not (yet) on disk, or of another config
    table: str              # the study's summary table

    def text(self) -> str:
        cells = ", ".join(canonical(c) for c in self.cells)
        return (f"summarised {self.n_trials} trial(s) in {len(self.cells)} cell(s): {cells}; "
                f"{self.n_missing} trial(s) of the configuration not on disk")


def summarise_existing(study: Study, config: Mapping[str, Any], out_dir: str | os.PathLike,
                       *, partial: bool = False) -> Summary:
    """Write ``out_dir``'s report from its trial files of ``config`` (resolved).

    Parameters
    ----------
    partial : bool
        Also summarise cells with only some repetitions on disk (default: only
        complete cells).

    Raises
    ------
    ValueError
        If no trial file of ``config`` (no complete cell, unless ``partial``) is there.
    """
    trials_dir = Path(out_dir) / "trials"
    found: dict[str, list] = {}
    todo = tasks(study, config)
    for task in todo:
        path = result_path(trials_dir, task.stem)
        ok = path.exists()
        if ok:
            try:
                ok = read_attrs(path, "trial").get("config_hash") == task.hash
            except ValueError:  # unreadable: a later run computes it again
                ok = False
        found.setdefault(canonical(task.cell), []).append((task, ok))
    keep = [key for key, rows in found.items()
            if (any(ok for _, ok in rows) if partial else all(ok for _, ok in rows))]
    if not keep:
        what = "trial files" if partial else "complete cells (every repetition on disk)"
        raise ValueError(f"{trials_dir} holds no {what} of study {study.name!r} under this "
                         "configuration; run it first ('mrfpe study run'), or pass --partial")
    used = [task for key in keep for task, ok in found[key] if ok]
    cells = [task.cell for key in keep for task, _ in found[key][:1]]
    # the grid lists narrowed to the cells summarised, so tables and figures skip the rest
    narrowed = {**config, **{k: [v for v in config[k] if any(c[k] == v for c in cells)]
                             for k in study.grid}}
    results = [open_dataset(result_path(trials_dir, t.stem), "trial") for t in used]
    table = study.summarise(results, dict(narrowed), Path(out_dir)) or ""
    return Summary(cells, len(used), len(todo) - len(used), table)
