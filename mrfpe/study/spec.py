"""What a study is: its declared settings, its trial and summary functions, its grid."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import xarray as xr

from mrfpe.study.config import coerce_like, kind_of

__all__ = ["Setting", "Study", "SummariseFn", "TrialFn"]

TrialFn = Callable[[dict, int, int], xr.Dataset]
SummariseFn = Callable[[list[xr.Dataset], dict, Path], str]
_RESERVED = ("n_trials", "seed")
_BUILTIN_HELP = {"n_trials": "repetitions per grid cell (each a new scene and seed)",
                 "seed": "study seed; every trial's seed is derived from it (--set seed=1 "
                         "gives an independent replicate)"}


@dataclass(frozen=True)
class Setting:
    """One declared setting of a study: what ``--set NAME=VALUE`` accepts.

    Parameters
    ----------
    name
        The key in the study's config.
    default
        The thesis's value; its JSON type is the setting's type (an integer
        default also accepts whole floats, a float default integers).
    help
        One line for ``mrfpe study show``.
    choices
        Allowed values -- for a list setting, of each element; for an object
        setting, of each key -- or a function returning them (called when a
        value is checked, so registries are read lazily).
    check
        ``check(value)`` raising ``ValueError`` for a value of the right type
        that is still wrong (e.g. a non-positive size).
    summary_only
        Read by the summary alone (a reweighting, a table's reading): left out of
        every trial's config and hash, so that changing it re-summarises the
        trials on disk instead of computing them again.
    """

    name: str
    default: Any
    help: str = ""
    choices: Sequence[Any] | Callable[[], Iterable[Any]] | None = None
    check: Callable[[Any], None] | None = field(default=None, compare=False)
    summary_only: bool = False

    @property
    def kind(self) -> str:
        """The accepted type, in words."""
        return kind_of(self.default)

    def valid_choices(self) -> tuple[Any, ...] | None:
        """The allowed values (elements, keys), or ``None`` for any value of the type."""
        if self.choices is None:
            return None
        return tuple(self.choices() if callable(self.choices) else self.choices)

    def coerce(self, value: Any) -> Any:
        """``value`` converted to the setting's type and checked; else ``ValueError``."""
        value = coerce_like(self.name, value, self.default)
        allowed = self.valid_choices()
        if allowed is not None and value is not None:
            items = (list(value) if isinstance(value, list | dict) else [value])
            bad = [v for v in items if v not in allowed]
            if bad:
                raise ValueError(f"setting {self.name!r}: {bad[0]!r} is not one of "
                                 f"{', '.join(map(str, allowed))}")
        if self.check is not None and value is not None:
            try:
                self.check(value)
            except ValueError as exc:
                raise ValueError(f"setting {self.name!r}: {exc}") from None
        return value


def _declared(name: str, settings: Sequence[Setting],
              config: Mapping[str, Any] | None) -> tuple[Setting, ...]:
    """Every setting of a study: the declared ones, then ``config``'s plain defaults."""
    declared = {s.name: s for s in settings}
    if len(declared) != len(settings):
        raise ValueError(f"study {name!r}: a setting is declared twice")
    for key, value in dict(config or {}).items():
        if key in declared and json.dumps(declared[key].default, sort_keys=True) \
                != json.dumps(value, sort_keys=True):
            raise ValueError(f"study {name!r}: config[{key!r}] = {value!r} disagrees "
                             f"with its declared default {declared[key].default!r}")
        declared.setdefault(key, Setting(key, value, _BUILTIN_HELP.get(key, "")))
    return tuple(declared.values())


@dataclass(frozen=True)
class _StudyFields:
    """What a :class:`Study` holds, as its constructor completes and checks it."""

    name: str
    doc: str
    trial: TrialFn
    summarise: SummariseFn
    settings: tuple[Setting, ...]
    config: Mapping[str, Any]
    quick: Mapping[str, Any]
    grid: tuple[str, ...]
    shared_seed: tuple[str, ...]
    version: int
    check: Callable[[dict], None] | None = field(compare=False)
    source: str = field(compare=False)


class Study(_StudyFields):
    """One reproducible experiment.

    Parameters
    ----------
    name
        Identifier used on the command line.
    doc
        Description; its first line is the summary shown by ``mrfpe study
        list``, and it must contain a line starting ``Full run:`` that states
        the full run's expected time.
    trial
        ``trial(config, repeat, seed) -> xarray.Dataset``: one trial, given the
        config specialised to its cell, its repetition index and its own seed.
    summarise
        ``summarise(results, config, out_dir) -> str``: writes ``report.md``
        and figures into ``out_dir`` from all trial Datasets (in task order)
        and returns a short markdown table to print.
    settings
        The declared settings (:class:`Setting`: default, help, choices,
        check). Must include ``n_trials`` (repetitions per cell) and ``seed``
        (the study seed), or have them in ``config``.
    config
        Plain defaults, ``{name: value}``, JSON-serialisable and flat: a
        shorthand for settings without help or choices. Keys in both must
        agree; after construction ``settings`` holds every setting (the
        declared ones, then those of ``config``) and ``config`` every
        setting's default.
    quick
        Overrides of the defaults for ``--quick`` (reduced size, same code path).
    grid
        Config keys whose list values are crossed to form the cells.
    shared_seed
        Grid keys across which trials of the same repetition share their seed
        (common random numbers: e.g. the same surface for every label count).
    version
        Bump when the trial function's meaning changes: it enters the config
        hash, so old trial files are not reused.
    check
        ``check(config)`` raising ``ValueError`` for settings that are wrong
        together (e.g. sampler options a listed sampler does not take); called
        on the resolved config, before any trial runs.
    source
        Where the study was found (a module, a file); set by discovery
        (:func:`mrfpe.study.get`), recorded in ``config.json``.

    A study is immutable: :func:`dataclasses.replace` makes a changed copy
    (checked as the constructor checks).
    """

    def __init__(self, name: str, doc: str, trial: TrialFn, summarise: SummariseFn,
                 settings: Sequence[Setting] = (), config: Mapping[str, Any] | None = None,
                 quick: Mapping[str, Any] | None = None, grid: tuple[str, ...] = (),
                 shared_seed: tuple[str, ...] = (), version: int = 1,
                 check: Callable[[dict], None] | None = None, source: str = "") -> None:
        declared = _declared(name, settings, config)
        super().__init__(name, doc, trial, summarise, declared,
                         {s.name: s.default for s in declared},
                         {} if quick is None else quick, grid, shared_seed, version, check,
                         source)
        self._check_fields()

    def _check_fields(self) -> None:
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

    def setting(self, name: str) -> Setting:
        """The declared :class:`Setting` called ``name`` (``KeyError`` if none)."""
        for s in self.settings:
            if s.name == name:
                return s
        raise KeyError(name)

    @property
    def summary_keys(self) -> frozenset[str]:
        """Names of the :attr:`Setting.summary_only` settings (not part of a trial's config)."""
        return frozenset(s.name for s in self.settings if s.summary_only)

    @property
    def summary(self) -> str:
        return next((ln.strip() for ln in self.doc.splitlines() if ln.strip()), "")

    @property
    def full_run(self) -> str:
        """The first sentence after ``Full run:`` (the expected time of the full run)."""
        text = " ".join(self.doc.split("Full run:", 1)[1].split("\n\n", 1)[0].split())
        return text.split(". ", 1)[0].rstrip(".")
