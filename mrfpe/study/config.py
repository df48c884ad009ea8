"""Study settings from the command line and from Python: parsing, coercion, resolution, hash.

Everything here raises ``ValueError`` with a one-line message naming the
setting and what was expected; the command line turns that into exit code 2.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mrfpe.study.spec import Study

__all__ = ["apply_overrides", "canonical", "coerce_like", "config_hash", "kind_of",
           "parse_assignment", "parse_assignments", "parse_value", "resolve_config"]

_SCALARS = (str, int, float, bool)


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


def _unknown(study: Study, key: str) -> ValueError:
    near = difflib.get_close_matches(key, list(study.config), n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    return ValueError(f"unknown setting {key!r} for study {study.name!r}{hint}; "
                      f"settings: {', '.join(sorted(study.config))}")


def apply_overrides(study: Study, config: Mapping[str, Any],
                    overrides: Mapping[str, Any] | Sequence[str]) -> dict:
    """``config`` with ``overrides`` applied and checked against the study's settings.

    ``overrides`` is a mapping or a list of ``key=value`` strings (values read
    as JSON where possible, as ``--set`` does). A grid key given one scalar
    becomes a one-element list. Unknown keys (with the nearest valid name),
    values of the wrong type and values outside a setting's choices raise
    ``ValueError``.
    """
    if not isinstance(overrides, Mapping):
        overrides = parse_assignments(overrides)
    out = copy.deepcopy(dict(config))
    for key, value in overrides.items():
        if key not in study.config:
            raise _unknown(study, key)
        if key in study.grid and not isinstance(value, list):
            value = [value]
        out[key] = study.setting(key).coerce(value)
    return out


def resolve_config(study: Study, *, quick: bool = False,
                   overrides: Mapping[str, Any] | Sequence[str] = (),
                   n_trials: int | None = None) -> dict:
    """The effective config: defaults, then ``quick``, then ``overrides``, then ``n_trials``.

    Every value is checked here (types, choices, grid lists), so a bad
    setting stops the run before its first trial.
    """
    cfg = copy.deepcopy(dict(study.config))
    if quick:
        cfg = apply_overrides(study, cfg, dict(study.quick))
    cfg = apply_overrides(study, cfg, overrides)
    if n_trials is not None:
        cfg = apply_overrides(study, cfg, {"n_trials": n_trials})
    if isinstance(cfg["n_trials"], bool) or not isinstance(cfg["n_trials"], int) \
            or cfg["n_trials"] < 1:
        raise ValueError(f"n_trials must be an integer >= 1; got {cfg['n_trials']!r}")
    if isinstance(cfg["seed"], bool) or not isinstance(cfg["seed"], int) or cfg["seed"] < 0:
        raise ValueError(f"seed must be an integer >= 0; got {cfg['seed']!r}")
    for key in study.grid:
        vals = cfg[key]
        if not vals:
            raise ValueError(f"grid setting {key!r} must be a non-empty list")
        if not all(isinstance(v, _SCALARS) for v in vals):
            raise ValueError(f"grid setting {key!r} must list scalars; got {vals!r}")
        if len({canonical(v) for v in vals}) != len(vals):
            raise ValueError(f"grid setting {key!r} has duplicate values: {vals!r}")
    if study.check is not None:
        study.check(cfg)
    return cfg


def config_hash(study: Study, trial_config: Mapping[str, Any]) -> str:
    """Hash of what determines a trial's result: study name, version and trial config."""
    blob = canonical({"study": study.name, "version": study.version,
                      "config": dict(trial_config)})
    return hashlib.sha256(blob.encode()).hexdigest()[:16]
