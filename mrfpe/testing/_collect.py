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
