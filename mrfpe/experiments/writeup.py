"""Helpers for study summaries: numbers for tables, markdown tables, figures, report files.

Public, for your own studies (``docs/studies.md``). Figures are made without
pyplot (:func:`blank_figure`), so summaries hold no global state and run in
any thread.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["blank_figure", "fmt", "markdown_table", "mean_sd", "new_figure", "save_figure",
           "write_report"]


def fmt(value: Any, spec: str = ".4g") -> str:
    """Format a number for a table ('–' for None/NaN); other values with ``str``."""
    if value is None:
        return "–"
    if isinstance(value, float | int) and not isinstance(value, bool):
        if isinstance(value, float) and math.isnan(value):
            return "–"
        return format(value, spec) if isinstance(value, float) else str(value)
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    return "–" if math.isnan(v) else format(v, spec)


def mean_sd(mean: float, sd: float, digits: int = 2) -> str:
    """``mean ± sd`` with the mean rounded where the sd's ``digits`` significant digits end.

    ``mean_sd(0.609612, 0.0123) == "0.610 ± 0.012"``; ``mean_sd(0.6096123, 3.2e-6)
    == "0.6096123 ± 0.0000032"``. An sd of zero (all weight on one point) or NaN
    gives the mean to 4 significant digits and says so.
    """
    mean, sd = float(mean), float(sd)
    if not math.isfinite(mean):
        return str(mean)
    if not math.isfinite(sd) or sd <= 0:
        return f"{mean:.4g} ± {'0' if sd == 0 else sd} (no spread)"
    decimals = max(0, digits - 1 - math.floor(math.log10(sd)))
    if decimals == 0:  # sd >= 10**(digits-1): integers, still `digits` significant in the sd
        scale = 10 ** (math.floor(math.log10(sd)) - digits + 1)
        return f"{round(mean / scale) * scale:.0f} ± {round(sd / scale) * scale:.0f}"
    return f"{mean:.{decimals}f} ± {sd:.{decimals}f}"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]],
                   spec: str = ".4g") -> str:
    """A GitHub-flavoured markdown table; numbers formatted with ``spec``."""
    lines = ["| " + " | ".join(map(str, header)) + " |",
             "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(fmt(v, spec) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def blank_figure(size: tuple[float, float] = (6.4, 4.8)):
    """An empty matplotlib Figure, without pyplot (no global state, any thread)."""
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained")


def new_figure(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (6.4, 4.8),
               **kw: Any):
    """A Figure (:func:`blank_figure`) and its (nrows, ncols) array of axes."""
    fig = blank_figure(size)
    return fig, fig.subplots(nrows, ncols, squeeze=False, **kw)


def save_figure(fig: Any, path: Path, dpi: int = 110) -> str:
    """Save ``fig`` as PNG; return its file name (for a markdown link).

    Panels with nothing drawn in them (a grid cell with no results yet, or the spare
    cell of a 2 × 2 grid over three label counts) are hidden, not shown as empty frames.
    """
    for ax in fig.axes:
        if not ax.has_data():
            ax.set_visible(False)
    fig.savefig(path, dpi=dpi)
    return Path(path).name


def write_report(out_dir: Path, title: str, sections: Sequence[str],
                 name: str = "report.md") -> Path:
    """Write ``out_dir/name`` from a title and markdown sections."""
    path = Path(out_dir) / name
    path.write_text(f"# {title}\n\n" + "\n\n".join(s.strip() for s in sections) + "\n")
    return path
