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
- checks every setting against the study's declared :class:`Setting` s (type,
  choices, check) and the output directory and scheduler before any trial;
- holds an exclusive lock on the output directory, removes temporary files a
  killed run left, recomputes (and reports) unreadable trial files, and saves
  a failed trial's traceback as ``trials/<stem>.error.txt``;
- skips trials whose file exists with the same config hash, so rerunning a
  command resumes it (a kill loses at most the trials in flight); a file with
  a *different* hash is never silently reused: the run stops and says which
  settings differ (``mismatch="recompute"`` overwrites instead);
- runs in-process by default, or on an existing ``dask.distributed`` cluster
  (``scheduler=ADDRESS``), writing each result on the client as it arrives
  (``as_completed``), so workers need no shared file system;
- calls the study's summary once every trial is on disk (``report.md`` and
  PNGs in the output directory) and prints its table.

Where studies come from (:func:`available`, :func:`get`): installed studies are
registered under the entry-point group ``mrfpe.studies`` -- mrfpe's own, the
thesis's experiments in :mod:`mrfpe.experiments` (so they ship with every install
and dask workers import them by name), and any other distribution's the same way
-- and are read from the entry points without importing this package's content;
a user's own study is a file ``studies/<name>/study.py`` under the current
directory (DESIGN.md's layout), or any ``.py`` path given as the name. A study
module defines ``STUDY``.

``mrfpe study verify NAME --out DIR`` (:func:`verify`) replays trial files of a
results directory and compares them with the files bit for bit.

The package, one idea a module: :mod:`~mrfpe.study.spec` (:class:`Study`,
:class:`Setting`), :mod:`~mrfpe.study.config` (setting values: ``--set`` parsing,
coercion, canonical JSON), :mod:`~mrfpe.study.resolve` (a study's effective
config and its hash), :mod:`~mrfpe.study.seeds` (trials and their seeds),
:mod:`~mrfpe.study.discovery`, :mod:`~mrfpe.study.trial` (one trial, written
atomically), :mod:`~mrfpe.study.runner` (:func:`run`, lock, resume),
:mod:`~mrfpe.study.cluster` (dask), :mod:`~mrfpe.study.results` (:func:`by_cell`),
:mod:`~mrfpe.study.summary` (:func:`summarise_existing`),
:mod:`~mrfpe.study.verification` (:func:`verify`) and :mod:`~mrfpe.study.command`
(``mrfpe study ...``).
"""

from mrfpe.study.command import cli, default_out_dir
from mrfpe.study.config import parse_assignment, parse_assignments, parse_value
from mrfpe.study.discovery import available, get, load_file
from mrfpe.study.resolve import apply_overrides, config_hash, resolve_config
from mrfpe.study.results import by_cell
from mrfpe.study.runner import RunReport, run
from mrfpe.study.seeds import Task, tasks, trial_seed
from mrfpe.study.spec import Setting, Study
from mrfpe.study.summary import Summary, summarise_existing
from mrfpe.study.verification import TrialVerdict, VerifyReport, verify

__all__ = [
    "RunReport",
    "Setting",
    "Study",
    "Summary",
    "Task",
    "TrialVerdict",
    "VerifyReport",
    "apply_overrides",
    "available",
    "by_cell",
    "cli",
    "config_hash",
    "default_out_dir",
    "get",
    "load_file",
    "parse_assignment",
    "parse_assignments",
    "parse_value",
    "resolve_config",
    "run",
    "summarise_existing",
    "tasks",
    "trial_seed",
    "verify",
]
