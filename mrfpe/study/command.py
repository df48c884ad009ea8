"""``mrfpe study list|show|run``: the study side of the command line (parsing is in mrfpe.cli)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from mrfpe.netcdf import DiskFullError
from mrfpe.study.config import canonical
from mrfpe.study.discovery import available, get
from mrfpe.study.runner import run
from mrfpe.study.seeds import tasks
from mrfpe.study.spec import Study

__all__ = ["cli", "default_out_dir", "list_text", "settings_text"]


def _columns(head: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    w = [max(len(r[i]) for r in [*rows, head]) for i in range(len(head) - 1)]
    fmt = "  ".join(f"{{:<{n}}}" for n in w) + "  {}"
    lines = [fmt.format(*head)]
    lines.append("-" * len(lines[0]))
    lines += [fmt.format(*r) for r in rows]
    return "\n".join(lines)


def list_text() -> str:
    """The table of ``mrfpe study list``: name, trials, full-run time, description."""
    from mrfpe.study.config import resolve_config

    broken: dict[str, str] = {}
    studies = available(broken)
    rows = [(s.name, str(len(tasks(s, resolve_config(s)))), s.full_run, s.summary)
            for s in studies.values()]
    rows += [(name, "–", "–", f"BROKEN: {err}") for name, err in broken.items()]
    if not rows:
        return "no studies found"
    return _columns(("name", "trials", "full run", "description"), rows)


def settings_text(study: Study) -> str:
    """The table of ``mrfpe study show NAME``: every setting, its type, default, help."""
    rows = []
    for s in study.settings:
        quick = canonical(study.quick[s.name]) if s.name in study.quick else ""
        allowed = s.valid_choices()
        help_ = s.help + (f" [one of: {', '.join(map(str, allowed))}]" if allowed else "")
        grid = " (grid)" if s.name in study.grid else ""
        rows.append((s.name + grid, s.kind, canonical(s.default), quick, help_))
    return (f"{study.name}: {study.summary}\nFull run: {study.full_run}\n\n"
            + _columns(("setting", "type", "default", "--quick", "meaning"), rows)
            + "\n\nChange one with --set NAME=VALUE (the value as JSON where it parses).")


def default_out_dir(study: Study, quick: bool) -> Path:
    """``studies/<name>/out`` (``out-quick`` with ``--quick``) under the current directory."""
    return Path("studies") / study.name / ("out-quick" if quick else "out")


def cli(args: Any) -> int:
    """Entry point of ``mrfpe study list|show|run`` (arguments parsed by :mod:`mrfpe.cli`).

    Input errors raise ``ValueError`` before any trial runs; :func:`mrfpe.cli.main`
    prints them as one line and exits 2.
    """
    from mrfpe.study.config import resolve_config

    if args.study_command == "list":
        print(list_text())
        return 0
    study = get(args.name)
    if args.study_command == "show":
        print(settings_text(study))
        return 0
    config = resolve_config(study, quick=args.quick, overrides=args.set, n_trials=args.trials)
    out = Path(args.out) if args.out else default_out_dir(study, args.quick)
    if args.study_command == "report":
        from mrfpe.study.summary import summarise_existing

        summary = summarise_existing(study, config, out, partial=args.partial)
        print(summary.text())
        print(summary.table)
        print(f"report: {out / 'report.md'}")
        return 0
    print(f"study {study.name} ({study.source}); full run: {study.full_run}")
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
