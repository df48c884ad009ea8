"""``mrfpe study list|show|run|report|verify``: the study side of the command line.

The arguments are parsed in :mod:`mrfpe.cli`.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path
from typing import Any

from mrfpe._terminal import WIDTH, plain, shorten, table
from mrfpe.netcdf import DiskFullError
from mrfpe.study.config import canonical
from mrfpe.study.discovery import available, get
from mrfpe.study.resolve import resolve_config
from mrfpe.study.runner import run
from mrfpe.study.seeds import tasks
from mrfpe.study.spec import Study

__all__ = ["cli", "default_out_dir", "list_text", "settings_text"]


def list_text(verbose: bool = False) -> str:
    """The table of ``mrfpe study list``: name, trials, full-run time, description.

    At most :data:`~mrfpe._terminal.WIDTH` columns; the full-run column holds the time
    only, ``verbose`` adds its explanation (``mrfpe study show NAME`` has everything).
    """
    broken: dict[str, str] = {}
    studies = available(broken)
    when = (lambda s: plain(s.full_run)) if verbose else (lambda s: _run_time(s.full_run))
    rows = [(s.name, str(len(tasks(s, resolve_config(s)))), when(s), plain(s.summary))
            for s in studies.values()]
    rows += [(name, "–", "–", f"BROKEN: {err}") for name, err in broken.items()]
    if not rows:
        return "no studies found"
    if verbose:  # the long column is "full run": give it the room, one study per block
        return "\n\n".join(
            "\n".join(textwrap.wrap(f"{n} ({t} trials): {d}", WIDTH, subsequent_indent="  ")
                      + textwrap.wrap(f"full run: {w}", WIDTH, initial_indent="  ",
                                      subsequent_indent="  "))
            for n, t, w, d in rows)
    return table(("name", "trials", "full run", "description"), rows)


def _run_time(full_run: str) -> str:
    """The time of a full run, without its explanation ("about 14 h on two cores")."""
    text = plain(full_run).split(" (", 1)[0].split(",", 1)[0].split(";", 1)[0]
    return shorten(text, 28)


def settings_text(study: Study) -> str:
    """The text of ``mrfpe study show NAME``: every setting with its type, default,
    ``--quick`` value and meaning, one block per setting, at most 100 columns."""
    def wrap(text: str, indent: str = "") -> list[str]:
        return textwrap.wrap(text, WIDTH, initial_indent=indent, subsequent_indent=indent
                             or "  ")

    lines = wrap(f"{study.name}: {plain(study.summary)}") + wrap(
        f"Full run: {plain(study.full_run)}") + [""]
    for s in study.settings:
        allowed = s.valid_choices()
        grid = ", a grid axis" if s.name in study.grid else ""
        quick = (f"; --quick {canonical(study.quick[s.name])}" if s.name in study.quick
                 else "")
        lines += wrap(f"{s.name} ({s.kind}{grid}): default {canonical(s.default)}{quick}")
        lines += wrap(plain(s.help) + (f" [one of: {', '.join(map(str, allowed))}]"
                                       if allowed else ""), "    ")
    lines += ["", "Change one with --set NAME=VALUE (the value as JSON where it parses)."]
    return "\n".join(lines)


def default_out_dir(study: Study, quick: bool) -> Path:
    """``studies/<name>/out`` (``out-quick`` with ``--quick``) under the current directory."""
    return Path("studies") / study.name / ("out-quick" if quick else "out")


def _verify(study: Study, args: Any) -> int:
    """``mrfpe study verify``: a verdict per trial as it is reached, then the count."""
    from mrfpe.study.verification import verify

    out = Path(args.out) if args.out else default_out_dir(study, False)
    print(f"study {study.name} ({study.source}): replaying trials of {out}", flush=True)
    report = verify(study, out, count=args.count, cheapest=args.cheapest, trials=args.trial,
                    log=lambda verdict: print(verdict.text(), flush=True))
    print(report.text())
    return 0 if report.ok else 1


def cli(args: Any) -> int:
    """Entry point of ``mrfpe study ...`` (arguments parsed by :mod:`mrfpe.cli`).

    Input errors raise ``ValueError`` before any trial runs; :func:`mrfpe.cli.main`
    prints them as one line and exits 2.
    """
    if args.study_command == "list":
        print(list_text(verbose=getattr(args, "verbose", False)))
        return 0
    study = get(args.name)
    if args.study_command == "show":
        print(settings_text(study))
        return 0
    if args.study_command == "verify":
        return _verify(study, args)
    config = resolve_config(study, quick=args.quick, overrides=args.set, n_trials=args.trials)
    out = Path(args.out) if args.out else default_out_dir(study, args.quick)
    if args.study_command == "report":
        from mrfpe.study.summary import summarise_existing

        summary = summarise_existing(study, config, out, partial=args.partial)
        print(summary.text())
        print(summary.table)
        print(f"report: {out / 'report.md'}")
        return 0
    print(f"study {study.name} ({study.source}); full run: {_run_time(study.full_run)}")
    try:
        report = run(study, config, out, scheduler=args.scheduler, progress=True,
                     log=lambda msg: print(msg, file=sys.stderr), force=args.force)
    except KeyboardInterrupt:
        done = len(list((out / "trials").glob("*.nc")))
        print(f"interrupted: {done} trial file(s) in {out / 'trials'}; "
              "rerun the same command to resume", file=sys.stderr)
        return 130
    except DiskFullError as exc:
        done = len(list((out / "trials").glob("*.nc")))
        print(f"mrfpe study: error: {exc}; stopped with {done} trial file(s) in "
              f"{out / 'trials'}; rerun the same command to resume", file=sys.stderr)
        return 1
    print(report.text())
    if report.ok:
        print(f"report: {out / 'report.md'}")
    return 0 if report.ok else 1
