"""The checks a hidden model's data and options pass before any work, each a one-line error.

Observations ``y`` must have the shape of the graph (``(H, W)`` on a lattice, one
value per node on a fixed graph) and be finite wherever the boolean ``mask`` does not
mark them missing (a non-finite value is refused naming how many there are and where
the first is); ``fixed`` and ``bounds`` must name parameters the model has; and the
observed data must be able to support ``q`` states (at least ``q`` distinct values
for a real or count emission).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["check_fixed", "check_names", "check_observations", "check_support",
           "split_covariates"]


def check_observations(y: Any, node_shape: tuple[int, ...], mask: Any, model: str,
                       ) -> tuple[np.ndarray, np.ndarray]:
    """``(y (n,) float64 with 0 at missing nodes, observed (n,) bool)`` from the data.

    Raises
    ------
    ValueError
        For non-numeric data, a shape other than the graph's, a mask of the wrong shape
        or kind, a mask that leaves nothing observed, or NaN/inf outside the mask
        (naming how many and the first).
    """
    try:
        arr = np.asarray(y, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"y must be an array of numbers; got {type(y).__name__}") from None
    where = "image (H, W)" if len(node_shape) == 2 else f"array of one value per node " \
                                                      f"({node_shape[0]},)"
    if arr.shape != tuple(node_shape):
        raise ValueError(f"y must be an {where} for the hidden model {model!r}; got shape "
                         f"{np.shape(y)}")
    if mask is None:
        missing = np.zeros(arr.shape, dtype=bool)
    else:
        missing = np.asarray(mask)
        if missing.dtype != bool or missing.shape != arr.shape:
            raise ValueError(f"mask must be a boolean array of y's shape {arr.shape} (True: "
                             f"missing); got {missing.dtype} of shape {missing.shape}")
    if missing.all():
        raise ValueError("mask marks every observation missing: nothing is observed")
    bad = ~np.isfinite(arr) & ~missing
    if bad.any():
        first = tuple(int(v) for v in np.argwhere(bad)[0])
        at = first if len(first) > 1 else first[0]
        raise ValueError(f"y holds {int(bad.sum())} non-finite value(s) (NaN or inf) outside the "
                         f"mask, the first at {at} ({arr[first]}): mark missing observations "
                         f"with mask= (True: missing)")
    observed = ~missing.reshape(-1)
    return np.where(observed, arr.reshape(-1), 0.0), observed


def check_support(y: np.ndarray, observed: np.ndarray, q: int, data_kind: str) -> None:
    """Refuse ``q`` states the observed data cannot support: a real or count emission
    needs at least ``q`` distinct observed values (else some state is empty for every
    labelling that separates them)."""
    if data_kind == "label":
        return
    distinct = np.unique(y[observed]).size
    if distinct < q:
        raise ValueError(f"n_states={q} is more than the data can support: the observed y "
                         f"takes only {distinct} distinct value(s), so at least "
                         f"{q - distinct} state(s) would be empty; use fewer states")


def check_names(option: str, given: Mapping[str, Any] | None,
                names: Sequence[str]) -> dict[str, Any]:
    """``given`` as a dict after checking that every key is one of ``names``."""
    if given is None:
        return {}
    if not isinstance(given, Mapping):
        raise ValueError(f"{option} must be a mapping parameter name -> value; got "
                         f"{type(given).__name__}")
    for key in given:
        if key not in names:
            near = difflib.get_close_matches(str(key), list(names), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ValueError(f"{option} names {key!r}, which the model does not have{hint}; "
                             f"parameters: {', '.join(names)}")
    return dict(given)


def check_fixed(fixed: Mapping[str, Any] | None, names: Sequence[str]) -> dict[str, float]:
    """Known parameters: names the model has, each a finite number."""
    out = {}
    for key, value in check_names("fixed", fixed, names).items():
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"fixed[{key!r}] must be a number; got {value!r}") from None
        if isinstance(value, bool) or not np.isfinite(v):
            raise ValueError(f"fixed[{key!r}] must be a finite number; got {value!r}")
        out[key] = v
    if len(out) == len(names):
        raise ValueError(f"fixed holds every parameter ({', '.join(names)}): there is nothing "
                         f"to estimate; leave at least one free")
    return out


def split_covariates(covariates: Mapping[str, Any] | None, emission_names: Sequence[str],
                     ) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(the MRF's covariates, the emission's)`` from one mapping."""
    if covariates is None:
        return {}, {}
    if not isinstance(covariates, Mapping):
        raise ValueError(f"covariates must be a mapping name -> array; got "
                         f"{type(covariates).__name__}")
    em = {k: v for k, v in covariates.items() if k in emission_names}
    return {k: v for k, v in covariates.items() if k not in emission_names}, em
