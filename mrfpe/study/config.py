"""Setting values from the command line and from Python: parsing, coercion, canonical JSON.

Values only: nothing here knows what a study is (its settings are checked against a
:class:`~mrfpe.study.Study` in :mod:`mrfpe.study.resolve`). Everything here raises
``ValueError`` with a one-line message naming the setting and what was expected; the
command line turns that into exit code 2.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

__all__ = ["canonical", "coerce_like", "kind_of", "parse_assignment", "parse_assignments",
           "parse_value"]


def canonical(obj: Any) -> str:
    """Compact JSON with sorted keys: equal settings give equal strings (and hashes)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def parse_value(raw: str) -> Any:
    """A ``--set`` value: JSON where it parses (``20``, ``[10, 40]``, ``true``), else the string."""
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def parse_assignment(item: str) -> tuple[str, Any]:
    """``"key=value"`` -> ``(key, parse_value(value))``; ``ValueError`` without ``=`` or key."""
    if not isinstance(item, str) or "=" not in item:
        raise ValueError(f"expected key=value; got {item!r}")
    key, raw = item.split("=", 1)
    key = key.strip()
    if not key:
        raise ValueError(f"expected key=value with a non-empty key; got {item!r}")
    return key, parse_value(raw)


def parse_assignments(items: Sequence[str]) -> dict[str, Any]:
    """Parse ``key=value`` strings (later ones win); values read as JSON where possible."""
    return dict(parse_assignment(item) for item in items)


def kind_of(default: Any) -> str:
    """What a setting with this default accepts, in words (for error messages and listings)."""
    if default is None:
        return "any value"
    if isinstance(default, bool):
        return "true or false"
    if isinstance(default, int):
        return "an integer"
    if isinstance(default, float):
        return "a number"
    if isinstance(default, str):
        return "a string"
    if isinstance(default, list):
        if default and len({type(d) for d in default}) == 1:
            return f"a list of {kind_of(default[0]).split(' ', 1)[-1]}s"
        return "a list"
    if isinstance(default, dict):
        return "a JSON object"
    return type(default).__name__


def coerce_like(key: str, value: Any, default: Any) -> Any:
    """``value`` in the type of ``default`` (int -> float widening allowed), else ``ValueError``.

    ``null`` is accepted only where the default is ``None`` (a setting that
    means "the sampler's own default" when unset); elsewhere it is refused
    here, not left to fail inside a trial.
    """
    if default is None:
        return value
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(default, int) and not isinstance(value, bool):
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif isinstance(default, float) and not isinstance(value, bool):
        if isinstance(value, int | float):
            return float(value)
    elif isinstance(default, str):
        if isinstance(value, str):
            return value
    elif isinstance(default, list):
        if isinstance(value, list):
            if not default or len({type(d) for d in default}) > 1:
                return value  # no single element type to check against
            return [coerce_like(key, v, default[0]) for v in value]
    elif isinstance(default, dict):
        if isinstance(value, dict):
            return value
    raise ValueError(f"setting {key!r} expects {kind_of(default)} (a value like {default!r}); "
                     f"got {value!r}")
