"""Shared machinery of the conformance checks: resolving a sampler, cached runs, failures."""

from __future__ import annotations

import inspect
import json
from typing import Any

import xarray as xr

from mrfpe.targets.base import Target

__all__: list[str] = []


def _resolve(sampler: Any) -> tuple[type, str]:
    if isinstance(sampler, str):
        from mrfpe.samplers import get

        return get(sampler), sampler
    if not inspect.isclass(sampler):
        raise ValueError(f"sampler must be a class or a registered name; got {sampler!r}")
    return sampler, sampler.__name__


def _declared(cls: type, check: str) -> Any:
    return getattr(cls, "conformance", {}).get(check, True)


def _run(cls: type, config: dict | None, target: Target, seed: int, **kw: Any) -> xr.Dataset:
    return cls(**(config or {})).run(target, seed=seed, progress=kw.pop("progress", False),
                                     callback=kw.pop("callback", None))


_CACHE: dict[tuple, xr.Dataset] = {}


def _cached_run(cls: type, config: dict | None, target_cls: type, seed: int) -> xr.Dataset:
    """One run per (sampler, config, target, seed) and process; returns a deep copy."""
    key = (cls, json.dumps(config or {}, sort_keys=True, default=repr), target_cls, seed)
    if key not in _CACHE:
        if len(_CACHE) > 32:
            _CACHE.clear()
        _CACHE[key] = _run(cls, config, target_cls(), seed)
    return _CACHE[key].copy(deep=True)


def _refused(exc: Exception) -> bool:
    """A run that honestly refused a degenerate result (no sample found the support)."""
    return isinstance(exc, ValueError) and any(
        m in str(exc) for m in ("zero total weight", "no support"))


def _run_or_refusal(cls: type, config: dict | None, target_cls: type,
                    seed: int) -> xr.Dataset | None:
    """:func:`_cached_run`, or ``None`` if the run refused with zero total weight."""
    try:
        return _cached_run(cls, config, target_cls, seed)
    except ValueError as exc:
        if _refused(exc):
            return None
        raise


def _fail(name: str, check: str, msg: str) -> AssertionError:
    return AssertionError(f"{check} failed for sampler {name}: {msg}")

