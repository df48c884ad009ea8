"""Build and check the posterior Dataset: :func:`build` and :func:`validate`.

The schema itself is documented in :mod:`mrfpe.posterior` (and docs/samplers.md).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import xarray as xr
from scipy.special import logsumexp

from mrfpe._version import __version__
from mrfpe.posterior.caveats import calibration_flag, caveats
from mrfpe.posterior.diagnostics import ATTRS as _DIAG_ATTRS
from mrfpe.posterior.diagnostics import (
    CHAIN_TYPES,
    KINDS,
    diagnose,
    diagnostics_attrs,
    warn_if_unreliable,
)
from mrfpe.resampling import check_log_weights, normalise_log_weights

__all__ = ["build", "validate"]


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        return repr(o)
    return json.dumps(obj, default=default, sort_keys=True)


def _float_array(name: str, value: Any) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric; got {type(value).__name__}: {exc}") from None


def _chain(chain: Any, S: int) -> np.ndarray:
    c = np.asarray(chain)
    if c.shape != (S,):
        raise ValueError(f"chain must hold one label per sample, shape ({S},); got {c.shape}")
    if c.dtype.kind == "f" and np.all(np.isfinite(c)) and np.all(c == np.round(c)):
        c = c.astype(np.int64)
    if c.dtype.kind not in "iu" or (c.size and c.min() < 0):
        raise ValueError(f"chain must hold non-negative integer chain labels; got {c.dtype} "
                         f"values {c[:5].tolist()}")
    counts = np.unique(c, return_counts=True)[1]
    if np.any(counts != counts[0]):
        raise ValueError(f"chain must label chains of equal length; got lengths {counts.tolist()}")
    return c.astype(np.int64)


def _check_log_target(lt: np.ndarray, name: str) -> None:
    """Refuse ``+inf`` and a log target that is ``-inf``/NaN at every sample (no support:
    the samples would say nothing about the target)."""
    if np.isposinf(lt).any():
        raise ValueError(f"{name} is +inf at {int(np.isposinf(lt).sum())} sample(s); a log "
                         "density must be finite or -inf")
    if lt.size and not np.isfinite(lt).any():
        raise ValueError(f"{name} is -inf or NaN at every one of its {lt.size} samples: the "
                         "target has no support where the sampler looked")


def _optional_float(name: str, value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a float or None; got {value!r}")
    return float(value)


def build(theta: Any, log_target: Any, *, param_names: Any, log_weight: Any = None,
          map_theta: Any = None, map_log_target: Any = None, ess: Any = None,
          history_theta: Any = None, history_log_weight: Any = None, chain: Any = None,
          kind: str = "draws", log_evidence: float | None = None,
          log_evidence_se: float | None = None, bias: str | None = None, sampler: str,
          config: dict | None = None, seed: int | None = None, target: Any = None,
          n_target_evals: float = 0.0, wall_time_s: float = 0.0,
          extra_vars: dict[str, tuple] | None = None,
          extra_attrs: dict[str, Any] | None = None) -> xr.Dataset:
    """Assemble the posterior Dataset, diagnose it and warn if it is unreliable.

    Parameters
    ----------
    theta : (S, d) final sample set in the target's sampling space; finite.
    log_target : (S,) target log density of each sample.
    log_weight : (S,) unnormalised log weights; ``None`` for equal weights. At
        least one must be finite (NaN counts as ``-inf``) and none ``+inf``.
    map_theta, map_log_target : (T, d), (T,) best-so-far trace per step.
        ``None`` gives a one-step trace from the final set.
    ess : (T,) effective sample size per step (NaN where meaningless).
    history_theta, history_log_weight : (T, S, d), (T, S), optional.
    chain : (S,) non-negative int chain label of each sample, for MCMC: the chains
        must have equal lengths and the samples of one chain must be in draw order
        (they may be interleaved with other chains'). Stored as ``chain(sample)``;
        the ESS and R̂ then come from the chains (:func:`mrfpe.posterior.diagnose`).
    kind : ``"draws"`` (a sample of the posterior) or ``"optima"`` (the optima of a
        multi-start optimiser: diagnosed as not a posterior sample, not warned about).
    log_evidence, log_evidence_se : the estimate of the target's log normaliser
        relative to the box, ``log(∫_box p / vol(box))``, and its standard error
        (:func:`mrfpe.samplers.kit.box_log_evidence`), stored as attributes if given.
    bias : a known bias of the estimator as configured (e.g. weights that ignore the
        density the draws came from), in words; stored as the attribute ``bias``, it
        makes the diagnosis unreliable whatever the ESS (:func:`mrfpe.posterior.diagnose`).
    sampler : the sampler's registered name.
    target : the target object (its ``describe()`` is stored) or a dict.
    extra_vars : further ``{name: (dims, values)}`` variables (e.g. ``acceptance``).
    extra_attrs : further attributes.

    Raises
    ------
    ValueError
        Naming the argument: shapes that do not match, non-finite ``theta``, a
        ``log_target`` that is ``+inf`` anywhere or ``-inf``/NaN everywhere,
        degenerate ``log_weight`` (all ``-inf``/NaN, or ``+inf``), a bad ``chain``
        or ``kind``.

    Warns
    -----
    PosteriorWarning
        Once, when a posterior of kind ``"draws"`` is unreliable (too small an ESS,
        a heavy weight tail, unmixed chains), saying what to change.
    """
    theta, names, lt = _samples(theta, param_names, log_target, sampler)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}; got {kind!r}")
    lw = _log_weights(log_weight, theta.shape[0], sampler)
    map_theta, map_log_target, ess = _trace(theta, lt, map_theta, map_log_target, ess)
    data = {
        "theta": (("sample", "param"), theta),
        "log_weight": (("sample",), lw),
        "log_target": (("sample",), lt),
        "map_theta": (("step", "param"), map_theta),
        "map_log_target": (("step",), map_log_target),
        "ess": (("step",), ess),
        **_optional_variables(history_theta, history_log_weight, chain, theta.shape[0]),
        **(extra_vars or {}),
    }
    attrs = _attributes(sampler, config, seed, target, n_target_evals, wall_time_s, kind,
                        log_evidence, log_evidence_se, bias, extra_attrs)
    post = xr.Dataset(data, coords={"param": names, "step": np.arange(map_theta.shape[0])},
                      attrs=attrs)
    diag = diagnose(post)
    post.attrs.update(diagnostics_attrs(diag))
    post.attrs["diag_caveats"] = "\n".join(caveats(post))
    warn_if_unreliable(diag, sampler)
    return post


def _samples(theta: Any, param_names: Any, log_target: Any,
             sampler: str) -> tuple[np.ndarray, list[str], np.ndarray]:
    """``theta`` (S, d) finite, its ``d`` parameter names and ``log_target`` (S,), checked."""
    theta = _float_array("theta", theta)
    if theta.ndim != 2:
        raise ValueError(f"theta must be (sample, param); got shape {theta.shape}")
    bad = ~np.isfinite(theta).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ValueError(f"theta of the posterior of {sampler} has {rows.size} non-finite "
                         f"(NaN/inf) sample(s), e.g. rows {rows[:5].tolist()}")
    names = [str(p) for p in param_names]
    if len(names) != theta.shape[1]:
        raise ValueError(f"{len(names)} param_names for {theta.shape[1]} parameters")
    lt = _float_array("log_target", log_target).reshape(-1)
    if lt.shape[0] != theta.shape[0]:
        raise ValueError(f"log_target has {lt.shape[0]} values for {theta.shape[0]} samples")
    _check_log_target(lt, f"log_target of the posterior of {sampler}")
    return theta, names, lt


def _log_weights(log_weight: Any, n: int, sampler: str) -> np.ndarray:
    """The ``n`` log weights, checked and normalised (equal ones for ``None``)."""
    if log_weight is None:
        lw = np.zeros(n)
    else:
        lw = _float_array("log_weight", log_weight).reshape(-1)
        if lw.shape[0] != n:
            raise ValueError(f"log_weight has {lw.shape[0]} values for {n} samples")
        check_log_weights(lw, f"log_weight of the posterior of {sampler}", allow_posinf=False)
    return normalise_log_weights(lw)


def _optional_variables(history_theta: Any, history_log_weight: Any, chain: Any,
                        n: int) -> dict[str, tuple]:
    """The history and chain variables that were given, checked."""
    data: dict[str, tuple] = {}
    if history_theta is not None:
        data["history_theta"] = (("step", "sample", "param"),
                                 _float_array("history_theta", history_theta))
    if history_log_weight is not None:
        data["history_log_weight"] = (("step", "sample"),
                                      _float_array("history_log_weight", history_log_weight))
    if chain is not None:
        data["chain"] = (("sample",), _chain(chain, n))
    return data


def _trace(theta: np.ndarray, lt: np.ndarray, map_theta: Any, map_log_target: Any,
           ess: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-step trace ``(map_theta, map_log_target, ess)``, one entry per step each;
    without ``map_theta``, one step: the final set's best sample."""
    if map_theta is None:
        finite = np.where(np.isnan(lt), -np.inf, lt)
        best = int(np.argmax(finite)) if finite.size else 0
        map_theta, map_log_target = theta[best][None], np.array([finite[best]])
    map_theta = _float_array("map_theta", map_theta).reshape(-1, theta.shape[1])
    map_log_target = _float_array("map_log_target", map_log_target).reshape(-1)
    n_steps = map_theta.shape[0]
    ess = np.full(n_steps, np.nan) if ess is None else _float_array("ess", ess).reshape(-1)
    if ess.shape[0] != n_steps or map_log_target.shape[0] != n_steps:
        raise ValueError("map_theta, map_log_target and ess must have one entry per step")
    return map_theta, map_log_target, ess


def _attributes(sampler: str, config: dict | None, seed: int | None, target: Any,
                n_target_evals: float, wall_time_s: float, kind: str,
                log_evidence: float | None, log_evidence_se: float | None, bias: str | None,
                extra_attrs: dict[str, Any] | None) -> dict[str, Any]:
    """The posterior's attributes but the diagnostics (see :func:`build`)."""
    target_desc = target.describe() if hasattr(target, "describe") else (target or {})
    attrs = {
        "sampler": sampler,
        "config": _json(config or {}),
        "seed": -1 if seed is None else int(seed),
        "target": _json(target_desc),
        "mrfpe_version": __version__,
        "n_target_evals": float(n_target_evals),
        "wall_time_s": float(wall_time_s),
        "kind": kind,
        "target_calibrated": calibration_flag(target),
    }
    for key, value in (("log_evidence", log_evidence), ("log_evidence_se", log_evidence_se)):
        v = _optional_float(key, value)
        if v is not None:
            attrs[key] = v
    if bias is not None:
        if not isinstance(bias, str) or not bias.strip():
            raise ValueError(f"bias must be a non-empty string (the known bias, in words); "
                             f"got {bias!r}")
        attrs["bias"] = bias
    attrs.update(extra_attrs or {})
    return attrs


_REQUIRED_VARS = {
    "theta": ("sample", "param"), "log_weight": ("sample",), "log_target": ("sample",),
    "map_theta": ("step", "param"), "map_log_target": ("step",), "ess": ("step",),
}
_OPTIONAL_VARS = {"history_theta": ("step", "sample", "param"),
                  "history_log_weight": ("step", "sample")}
_REQUIRED_ATTRS = {"sampler": str, "config": str, "seed": int, "target": str,
                   "mrfpe_version": str, "n_target_evals": float, "wall_time_s": float}
#: Attributes checked when present (build always writes ``kind`` and the ``diag_*``).
_OPTIONAL_ATTRS = {"kind": str, "chain_type": str, "log_evidence": float, "log_evidence_se": float,
                   "target_calibrated": int, "diag_caveats": str, **_DIAG_ATTRS}


def _attr_ok(v: Any, typ: type, key: str = "") -> bool:
    if key == "diag_messages":  # one reason per line; a list in files of mrfpe < 0.2
        return isinstance(v, str) or (isinstance(v, list) and all(isinstance(m, str)
                                                                   for m in v))
    if typ is str:
        return isinstance(v, str)
    if typ is bool:  # 1/0 as netCDF stores it, or a bool
        return isinstance(v, bool | np.bool_) or (isinstance(v, int | np.integer)
                                                  and int(v) in (0, 1))
    if typ is list:
        return isinstance(v, list) and all(isinstance(m, str) for m in v)
    if typ is int:
        return isinstance(v, int | np.integer) and not isinstance(v, bool)
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool)


def _validate_chain(post: xr.Dataset) -> None:
    c = post["chain"]
    if c.dims != ("sample",) or c.dtype.kind not in "iu":
        raise ValueError(f"chain must be an integer variable over (sample,); got {c.dims} "
                         f"{c.dtype}")
    if c.size and int(c.min()) < 0:
        raise ValueError("chain labels must be non-negative")
    counts = np.unique(c.values, return_counts=True)[1]
    if np.any(counts != counts[0]):
        raise ValueError(f"chain must label chains of equal length; got {counts.tolist()}")


def validate(post: Any) -> None:
    """Check that ``post`` follows the posterior schema (:mod:`mrfpe.posterior`).

    Raises
    ------
    ValueError
        Naming the first problem found: missing or mis-dimensioned variable,
        non-float data, non-finite samples, log weights that are not normalised
        or all ``-inf``, a log target that is ``+inf`` somewhere or ``-inf``
        everywhere, an ESS outside [0, S], a ``param`` coordinate that does not
        match, a bad ``chain``, or a missing / mistyped / non-JSON attribute
        (``kind``, ``diag_*`` and ``log_evidence*`` are checked when present).
    """
    if not isinstance(post, xr.Dataset):
        raise ValueError(f"a posterior must be an xarray.Dataset; got {type(post).__name__}")
    for name, dims in {**_REQUIRED_VARS, **_OPTIONAL_VARS}.items():
        if name not in post:
            if name in _REQUIRED_VARS:
                raise ValueError(f"posterior lacks the variable {name!r}")
            continue
        if post[name].dims != dims:
            raise ValueError(f"{name} must have dims {dims}; got {post[name].dims}")
        if post[name].dtype != np.float64:
            raise ValueError(f"{name} must be float64; got {post[name].dtype}")
    S, d = post.sizes["sample"], post.sizes["param"]
    if S < 1 or d < 1:
        raise ValueError(f"posterior must have samples and parameters; got S={S}, d={d}")
    if "param" not in post.coords or len(set(map(str, post["param"].values))) != d:
        raise ValueError("the param coordinate must hold d distinct parameter names")
    if not np.isfinite(post["theta"].values).all():
        raise ValueError("theta contains NaN or ±inf")
    lw = post["log_weight"].values
    if np.isnan(lw).any() or np.isposinf(lw).any():
        raise ValueError("log_weight contains NaN or +inf")
    if not np.isfinite(lw).any():
        raise ValueError("log_weight is -inf everywhere (zero total weight)")
    total = logsumexp(lw)
    if not abs(total) < 1e-6:
        raise ValueError(f"log_weight must be normalised (logsumexp = 0); got {total:.3g}")
    if np.isnan(post["log_target"].values).any():
        raise ValueError("log_target contains NaN (use -inf for impossible samples)")
    _check_log_target(post["log_target"].values, "log_target")
    e = post["ess"].values
    if np.any((e < 0) | (e > S * (1 + 1e-9)) & ~np.isnan(e)):
        raise ValueError(f"ess must lie in [0, {S}] or be NaN; got {e}")
    if "step" not in post.coords:
        raise ValueError("posterior lacks the step coordinate")
    for key, typ in {**_REQUIRED_ATTRS, **_OPTIONAL_ATTRS}.items():
        if key not in post.attrs:
            if key in _REQUIRED_ATTRS:
                raise ValueError(f"posterior lacks the attribute {key!r}")
            continue
        v = post.attrs[key]
        if not _attr_ok(v, typ, key):
            raise ValueError(f"attribute {key!r} must be {typ.__name__}; got {v!r}")
    if post.attrs.get("chain_type", "independent") not in CHAIN_TYPES:
        raise ValueError(f"attribute 'chain_type' must be one of {CHAIN_TYPES}; got "
                         f"{post.attrs['chain_type']!r}")
    if post.attrs.get("kind", "draws") not in KINDS:
        raise ValueError(f"attribute 'kind' must be one of {KINDS}; got {post.attrs['kind']!r}")
    if "chain" in post:
        _validate_chain(post)
    for key in ("config", "target"):
        try:
            json.loads(post.attrs[key])
        except json.JSONDecodeError as exc:
            raise ValueError(f"attribute {key!r} must be JSON: {exc}") from None
    if not post.attrs["n_target_evals"] >= 0:
        raise ValueError(f"n_target_evals must be >= 0; got {post.attrs['n_target_evals']}")
