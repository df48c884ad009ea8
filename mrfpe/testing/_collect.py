"""One report for every conformance suite: run the checks, raise all failures together."""

from __future__ import annotations

from typing import Any

__all__: list[str] = []


def run_all(checks: dict[str, Any], what: str) -> dict[str, str]:
    """Run every ``check()`` (each returns its status, e.g. ``"passed"``), collect the
    ``AssertionError``\\ s and raise them together: the report of ``check_sampler``,
    ``check_target`` and ``check_distance``.

    Returns ``{name: status}``; raises ``AssertionError`` listing every failure.
    """
    report, failures = {}, []
    for name, check in checks.items():
        try:
            report[name] = check()
        except AssertionError as exc:
            report[name] = "failed"
            failures.append(str(exc))
    if failures:
        raise AssertionError(f"{len(failures)} {what} check(s) failed:\n- "
                             + "\n- ".join(failures))
    return report


def display_name(obj: Any) -> str:
    """A checked object's ``name`` attribute, else its class name (for failure messages)."""
    return getattr(obj, "name", "") or type(obj).__name__


def failure(kind: str, obj: Any, check: str, msg: str) -> AssertionError:
    """The ``AssertionError`` a check raises: ``"<check> failed for <kind> <name>: <msg>"``."""
    return AssertionError(f"{check} failed for {kind} {display_name(obj)}: {msg}")
