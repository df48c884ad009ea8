"""Memory budget for target builds and evaluations: fail up front, with the estimate.

A target build (the data tables) or a ``log_prob`` / ``node_terms`` /
``residuals`` call estimates its peak memory *before* allocating anything and
raises :class:`MemoryBudgetError` (a ``MemoryError`` and a ``ValueError``)
with the estimate when it exceeds the budget. Batches are evaluated in chunks
(:func:`chunk_rows`), so a ``log_prob`` call's working memory stays small
whatever the batch size; what cannot be chunked (its input and output, a
per-node output, the tables) is what the budget guards.

The budget, in bytes, is, first found:

1. :func:`set_memory_budget` (``None`` resets);
2. the environment variable ``MRFPE_MEMORY_BUDGET`` -- bytes, or a number with a
   unit ``"512MB"``, ``"2GB"``, ``"1.5GiB"``, or a fraction of RAM written with a
   decimal point, ``"0.25"`` or ``"1.0"`` (a bare ``"1"`` is one byte, not all RAM);
3. half of the machine's physical RAM (:data:`DEFAULT_FRACTION`).
"""

from __future__ import annotations

import itertools
import os
import re
import threading
from typing import Any

__all__ = ["DEFAULT_FRACTION", "WORKING_CHUNK_BYTES", "MemoryBudgetError", "check_memory",
           "chunk_rows", "format_bytes", "memory_budget", "parse_bytes", "set_memory_budget"]

#: Default budget as a fraction of physical RAM.
DEFAULT_FRACTION = 0.5
#: Working memory one evaluation chunk may use (the batch is split to stay below it).
WORKING_CHUNK_BYTES = 64 << 20
_ENV = "MRFPE_MEMORY_BUDGET"
_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12,
          "KIB": 1 << 10, "MIB": 1 << 20, "GIB": 1 << 30, "TIB": 1 << 40}


class _ExplicitBudget:
    """The budget set by :func:`set_memory_budget`: one value for the whole process (like
    numba's thread count), read and swapped under a lock so that threads see whole values."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._value: int | None = None

    def get(self) -> int | None:
        with self._lock:
            return self._value

    def swap(self, value: int | None) -> int | None:
        """Set ``value``; return the previous one."""
        with self._lock:
            old, self._value = self._value, value
            return old


_EXPLICIT = _ExplicitBudget()


class MemoryBudgetError(MemoryError, ValueError):
    """An operation's estimated peak memory exceeds :func:`memory_budget`."""


def format_bytes(n: float) -> str:
    """``1.5 GB``-style rendering of a byte count."""
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1000.0
    return f"{n:.3g} TB"  # pragma: no cover


def _physical_ram() -> int:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - non-POSIX
        return 8 << 30


def parse_bytes(value: Any, name: str = "memory budget") -> int:
    """Bytes from an int, ``"2GB"``-style string or a RAM fraction in (0, 1] written with a
    decimal point (``"0.25"``, ``0.25``); an integer without a unit is a byte count."""
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a byte count, e.g. 2000000000 or '2GB'; got {value!r}")
    fraction_form = False  # a RAM fraction is written as one: 0.25, "0.25" (never 1 or "1")
    if isinstance(value, int | float):
        num, unit = float(value), ""
        fraction_form = isinstance(value, float)
    elif isinstance(value, str):
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([A-Za-z]*)\s*", value)
        if not m or m.group(2).upper() not in _UNITS:
            raise ValueError(f"{name} must be a byte count such as '512MB', '2GB', '1.5GiB' or a "
                             f"RAM fraction such as '0.25'; got {value!r}")
        num, unit = float(m.group(1)), m.group(2).upper()
        fraction_form = "." in m.group(1) and "e" not in m.group(1).lower()
    else:
        raise ValueError(f"{name} must be a byte count, e.g. 2000000000 or '2GB'; got {value!r}")
    if not num > 0 or num != num or num == float("inf"):
        raise ValueError(f"{name} must be positive and finite; got {value!r}")
    if unit == "" and num <= 1.0 and fraction_form:
        return int(num * _physical_ram())
    return max(1, int(num * _UNITS[unit]))


def memory_budget() -> int:
    """The current budget in bytes (see the module docstring for where it comes from)."""
    explicit = _EXPLICIT.get()
    if explicit is not None:
        return explicit
    env = os.environ.get(_ENV)
    if env:
        return parse_bytes(env, _ENV)
    return int(DEFAULT_FRACTION * _physical_ram())


def set_memory_budget(value: Any) -> int | None:
    """Set the budget (bytes, ``"2GB"``, a RAM fraction, or None for the default).

    Returns the previous explicit setting (None if there was none), so that
    ``old = set_memory_budget("1GB"); ...; set_memory_budget(old)`` restores it.
    """
    return _EXPLICIT.swap(None if value is None else parse_bytes(value, "value"))


def check_memory(nbytes: float, what: str, hint: str = "") -> None:
    """Raise :class:`MemoryBudgetError` if ``nbytes`` exceeds the budget, else return."""
    budget = memory_budget()
    if nbytes > budget:
        raise MemoryBudgetError(
            f"{what} needs about {format_bytes(nbytes)}, more than the memory budget of "
            f"{format_bytes(budget)}{'; ' + hint if hint else ''} (raise it with "
            f"mrfpe.budget.set_memory_budget(...) or {_ENV}=...)")


def chunk_rows(n_rows: int, bytes_per_row: float, minimum: int = 16) -> list[slice]:
    """Slices splitting ``n_rows`` into near-equal chunks of at most WORKING_CHUNK_BYTES each.

    Each chunk has at least ``minimum`` rows (unless the batch is smaller), so
    that a chunked evaluation uses the same kernels as an unchunked one.
    """
    per = max(minimum, int(WORKING_CHUNK_BYTES // max(1.0, bytes_per_row)))
    n_chunks = max(1, -(-n_rows // per))
    edges = [round(i * n_rows / n_chunks) for i in range(n_chunks + 1)]
    return [slice(a, b) for a, b in itertools.pairwise(edges)]
