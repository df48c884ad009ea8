"""Declarative target options: each target lists its options as :class:`Option` s.

Like :attr:`mrfpe.distances.base.Distance.params`, but with a type, a check
and a help line per option, so that every target

* rejects an unknown option with the list of valid ones and the nearest match
  (``difflib``), before any expensive work;
* checks every value by name (``ValueError`` naming the option and what was
  expected);
* documents itself: :func:`mrfpe.targets.options` (and ``describe_options``)
  list name, type, default and help.

Checks here are value-level (type, range, choice); checks that need the scene
(e.g. a beliefs array's shape) stay in the target's constructor.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrfpe.validation import check_bool, check_choice, check_range

__all__ = ["Option", "bool_check", "choice_check", "describe_options", "number_check",
           "optional", "resolve_options", "unknown_option_error"]


@dataclass(frozen=True)
class Option:
    """One keyword option of a target.

    Attributes
    ----------
    name : str
    type : str
        What is expected, for humans (``"float > 0"``, ``"'pixel' | 'triplet'"``).
    default : Any
    check : callable ``(name, value) -> value``
        Validates (and normalises) a value; raises ValueError naming ``name``.
    help : str
        One line.
    """

    name: str
    type: str
    default: Any
    check: Callable[[str, Any], Any]
    help: str = ""

    def resolve(self, value: Any) -> Any:
        """The checked value (the default if ``value`` is the default object)."""
        return self.check(self.name, value)


def number_check(low: float = -np.inf, high: float = np.inf, *, low_open: bool = False,
                 high_open: bool = False) -> Callable[[str, Any], float]:
    """A check accepting finite real numbers in the interval (bools rejected)."""
    def check(name: str, value: Any) -> float:
        if isinstance(value, bool | np.bool_) or isinstance(value, str):
            raise ValueError(f"{name} must be a number; got {value!r}")
        v = check_range(name, value, low, high, low_open=low_open, high_open=high_open)
        if not np.isfinite(v):
            raise ValueError(f"{name} must be a finite number; got {value!r}")
        return v
    return check


def choice_check(*choices: str) -> Callable[[str, Any], str]:
    """A check accepting one of ``choices``."""
    def check(name: str, value: Any) -> str:
        return check_choice(name, value, tuple(choices))
    return check


def bool_check(name: str, value: Any) -> bool:
    """A check accepting True/False."""
    return check_bool(name, value)


def optional(check: Callable[[str, Any], Any]) -> Callable[[str, Any], Any]:
    """``check`` that also lets ``None`` through."""
    def wrapped(name: str, value: Any) -> Any:
        return None if value is None else check(name, value)
    return wrapped


def unknown_option_error(target: str, unknown: Sequence[str],
                         specs: Sequence[Option]) -> ValueError:
    """ValueError listing the valid options and, per unknown name, the nearest valid one."""
    valid = [o.name for o in specs]
    hints = []
    for u in unknown:
        close = difflib.get_close_matches(str(u), valid, n=1)
        hints.append(f"{u!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return ValueError(f"{target}: unknown option(s) {', '.join(hints)}; valid options: "
                      f"{', '.join(valid) if valid else '(none)'}")


def resolve_options(target: str, specs: Sequence[Option],
                    given: Mapping[str, Any]) -> dict[str, Any]:
    """Every option of ``specs``: the given value or the default, each checked.

    Raises
    ------
    ValueError
        For an unknown option (listing the valid ones, with the nearest match) or
        a bad value (from the option's check).
    """
    names = [o.name for o in specs]
    unknown = [k for k in given if k not in names]
    if unknown:
        raise unknown_option_error(target, unknown, specs)
    return {o.name: o.resolve(given[o.name] if o.name in given else o.default) for o in specs}


def describe_options(specs: Sequence[Option]) -> str:
    """Plain-text table: ``name : type = default -- help`` per option."""
    return "\n".join(f"{o.name} : {o.type} = {o.default!r} -- {o.help}" for o in specs)
