"""A study's effective configuration: overrides applied and checked, resolved, hashed.

Everything here raises ``ValueError`` with a one-line message naming the
setting and what was expected; the command line turns that into exit code 2.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
from collections.abc import Mapping, Sequence
from typing import Any

from mrfpe.study.config import canonical, parse_assignments
from mrfpe.study.spec import Study

__all__ = ["apply_overrides", "config_hash", "resolve_config"]

_SCALARS = (str, int, float, bool)


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
