"""The posterior Dataset every sampler returns (DESIGN.md, "Posterior").

Dims ``sample``, ``param``, ``step``; variables ``theta(sample, param)``,
``log_weight(sample)`` (normalised: logsumexp = 0), ``log_target(sample)``,
``map_theta(step, param)``, ``map_log_target(step)``, ``ess(step)`` and the
optional ``history_theta(step, sample, param)`` /
``history_log_weight(step, sample)``; attributes ``sampler``, ``config``
(JSON), ``seed``, ``target`` (JSON), ``mrfpe_version``, ``n_target_evals``,
``wall_time_s``.

Beyond :func:`build` (which every sampler goes through) this module holds the
statistics of a weighted sample set (:func:`weighted_mean`, :func:`weighted_cov`,
:func:`weighted_quantiles`, :func:`ess`, :func:`perplexity`, :func:`map_estimate`),
:func:`resample` to equal weights, exact netCDF :func:`save` / :func:`load`,
:func:`summary`, :func:`to_arviz` and the schema check :func:`validate`.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import xarray as xr
from scipy.special import logsumexp

from mrfpe.resampling import ess, normalise_log_weights, perplexity
from mrfpe.resampling import resample as _resample

__all__ = [
    "build", "ess", "load", "map_estimate", "normalise_log_weights", "perplexity", "resample",
    "save", "summary", "to_arviz", "validate", "weighted_cov", "weighted_mean",
    "weighted_quantiles", "weights",
]


def weights(post: xr.Dataset) -> np.ndarray:
    """Normalised linear weights (S,) of a posterior (they sum to 1)."""
    return np.exp(normalise_log_weights(post["log_weight"].values))


def weighted_mean(post: xr.Dataset) -> np.ndarray:
    """Importance-weighted mean (d,) of ``theta``."""
    return weights(post) @ post["theta"].values


def weighted_cov(post: xr.Dataset) -> np.ndarray:
    """Importance-weighted covariance (d, d) of ``theta`` (the biased, weight-normalised form)."""
    w = weights(post)
    x = post["theta"].values - w @ post["theta"].values
    return (x * w[:, None]).T @ x


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        return repr(o)
    return json.dumps(obj, default=default, sort_keys=True)


def build(
    theta: Any,
    log_target: Any,
    *,
    param_names: Any,
    log_weight: Any = None,
    map_theta: Any = None,
    map_log_target: Any = None,
    ess: Any = None,
    history_theta: Any = None,
    history_log_weight: Any = None,
    sampler: str,
    config: dict | None = None,
    seed: int | None = None,
    target: Any = None,
    n_target_evals: float = 0.0,
    wall_time_s: float = 0.0,
    extra_vars: dict[str, tuple] | None = None,
    extra_attrs: dict[str, Any] | None = None,
) -> xr.Dataset:
    """Assemble the posterior Dataset.

    Parameters
    ----------
    theta : (S, d) final sample set in the target's sampling space.
    log_target : (S,) target log density of each sample.
    log_weight : (S,) unnormalised log weights; ``None`` for equal weights.
    map_theta, map_log_target : (T, d), (T,) best-so-far trace per step.
        ``None`` gives a one-step trace from the final set.
    ess : (T,) effective sample size per step (NaN where meaningless).
    history_theta, history_log_weight : (T, S, d), (T, S), optional.
    target : the target object (its ``describe()`` is stored) or a dict.
    extra_vars : further ``{name: (dims, values)}`` variables (e.g. ``acceptance``).
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim != 2:
        raise ValueError(f"theta must be (sample, param); got shape {theta.shape}")
    names = [str(p) for p in param_names]
    if len(names) != theta.shape[1]:
        raise ValueError(f"{len(names)} param_names for {theta.shape[1]} parameters")
    lt = np.asarray(log_target, dtype=np.float64).reshape(-1)
    if lt.shape[0] != theta.shape[0]:
        raise ValueError(f"log_target has {lt.shape[0]} values for {theta.shape[0]} samples")
    lw = np.zeros(theta.shape[0]) if log_weight is None else np.asarray(log_weight, float)
    lw = normalise_log_weights(lw)
    if map_theta is None:
        finite = np.where(np.isnan(lt), -np.inf, lt)
        best = int(np.argmax(finite)) if finite.size else 0
        map_theta, map_log_target = theta[best][None], np.array([finite[best]])
    map_theta = np.asarray(map_theta, dtype=np.float64).reshape(-1, theta.shape[1])
    map_log_target = np.asarray(map_log_target, dtype=np.float64).reshape(-1)
    n_steps = map_theta.shape[0]
    ess = np.full(n_steps, np.nan) if ess is None else np.asarray(ess, float).reshape(-1)
    if ess.shape[0] != n_steps or map_log_target.shape[0] != n_steps:
        raise ValueError("map_theta, map_log_target and ess must have one entry per step")
    data = {
        "theta": (("sample", "param"), theta),
        "log_weight": (("sample",), lw),
        "log_target": (("sample",), lt),
        "map_theta": (("step", "param"), map_theta),
        "map_log_target": (("step",), map_log_target),
        "ess": (("step",), ess),
    }
    if history_theta is not None:
        data["history_theta"] = (("step", "sample", "param"), np.asarray(history_theta, float))
    if history_log_weight is not None:
        data["history_log_weight"] = (("step", "sample"), np.asarray(history_log_weight, float))
    for k, v in (extra_vars or {}).items():
        data[k] = v
    target_desc = target.describe() if hasattr(target, "describe") else (target or {})
    from mrfpe import __version__

    attrs = {
        "sampler": sampler,
        "config": _json(config or {}),
        "seed": -1 if seed is None else int(seed),
        "target": _json(target_desc),
        "mrfpe_version": __version__,
        "n_target_evals": float(n_target_evals),
        "wall_time_s": float(wall_time_s),
        **(extra_attrs or {}),
    }
    return xr.Dataset(data, coords={"param": names, "step": np.arange(n_steps)}, attrs=attrs)


# --------------------------------------------------------------------------
# Statistics of a weighted sample set
# --------------------------------------------------------------------------
def weighted_quantiles(post: xr.Dataset, q: Any) -> np.ndarray:
    """Importance-weighted quantiles of each parameter, shape (len(q), d).

    Uses the inverse of the weighted empirical CDF with linear interpolation
    between the midpoints of the sorted samples' weight masses (so equal weights
    give the Hazen quantiles, numpy's ``method="hazen"``); levels outside the
    first/last midpoint clamp to the smallest/largest sample.
    """
    qs = np.atleast_1d(np.asarray(q, dtype=np.float64))
    if qs.ndim != 1 or np.any(~(qs >= 0) | ~(qs <= 1)):
        raise ValueError(f"q must be quantile levels in [0, 1]; got {q!r}")
    w = weights(post)
    theta = post["theta"].values
    out = np.empty((qs.size, theta.shape[1]))
    for j in range(theta.shape[1]):  # d is small; each column is one sort
        order = np.argsort(theta[:, j], kind="stable")
        x, wj = theta[order, j], w[order]
        keep = wj > 0
        x, wj = x[keep], wj[keep]
        mid = np.cumsum(wj) - 0.5 * wj
        out[:, j] = np.interp(qs, mid, x)
    return out


def map_estimate(post: xr.Dataset) -> tuple[np.ndarray, float]:
    """The maximum-a-posteriori point and its target log density.

    The last entry of the best-so-far trace (``map_theta``/``map_log_target``)
    if it is finite, else the final sample with the highest ``log_target``.
    """
    lt_trace = post["map_log_target"].values
    if lt_trace.size and np.isfinite(lt_trace[-1]):
        return post["map_theta"].values[-1].copy(), float(lt_trace[-1])
    lt = np.where(np.isnan(post["log_target"].values), -np.inf, post["log_target"].values)
    best = int(np.argmax(lt))
    return post["theta"].values[best].copy(), float(lt[best])


def resample(post: xr.Dataset, n: int | None = None, method: str = "systematic",
             seed: int | None = None) -> xr.Dataset:
    """An equal-weight posterior drawn from ``post``'s weighted samples.

    Parameters
    ----------
    n : number of draws (default: the sample count of ``post``).
    method : ``"multinomial"``, ``"systematic"``, ``"stratified"`` or ``"residual"``
        (see :mod:`mrfpe.resampling`).
    seed : seed of the resampling draw.

    The trace variables and attributes are kept; the history variables, whose
    ``sample`` axis indexes other sets, are dropped. The attribute
    ``resampled`` records the method, count and seed.
    """

    n = post.sizes["sample"] if n is None else n
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be a positive integer; got {n!r}")
    idx = _resample(post["log_weight"].values, int(n), method, np.random.default_rng(seed))
    out = post.drop_vars([k for k in post.data_vars if k.startswith("history_")]).isel(sample=idx)
    out["log_weight"] = (("sample",), np.full(int(n), -np.log(int(n))))
    out.attrs = dict(post.attrs)
    out.attrs["resampled"] = _json({"method": method, "n": int(n), "seed": seed})
    return out


# --------------------------------------------------------------------------
# netCDF round trip
# --------------------------------------------------------------------------
_JSON_ATTRS = "_mrfpe_json_attrs"


def _is_nc_attr(v: Any) -> bool:
    if isinstance(v, bool | np.bool_):
        return False
    if isinstance(v, str | int | float | np.integer | np.floating):
        return True
    if isinstance(v, np.ndarray | list | tuple):
        a = np.asarray(v)
        return a.ndim == 1 and a.size > 0 and a.dtype.kind in "iuf"
    return False


def _encode_attrs(attrs: dict) -> dict:
    """netCDF attributes; values netCDF cannot hold (bool, None, dict) go as JSON."""
    out, encoded = {}, []
    for k, v in attrs.items():
        if _is_nc_attr(v):
            out[k] = v
        else:
            out[k] = json.dumps(v.item() if isinstance(v, np.generic) else v)
            encoded.append(k)
    if encoded:
        out[_JSON_ATTRS] = json.dumps(encoded)
    return out


def _decode_attrs(attrs: dict) -> dict:
    attrs = dict(attrs)
    encoded = json.loads(attrs.pop(_JSON_ATTRS, "[]"))
    out = {}
    for k, v in attrs.items():
        if k in encoded:
            out[k] = json.loads(v)
        elif isinstance(v, np.generic):
            out[k] = v.item()  # netCDF returns numpy scalars; build() stores python ones
        else:
            out[k] = v
    return out


def save(post: xr.Dataset, path: Any) -> None:
    """Write a posterior to netCDF4 so that :func:`load` returns it unchanged.

    Float variables keep NaN and ±inf (no fill-value masking on read), string
    coordinates come back as fixed-width unicode, and attributes netCDF cannot
    store (bool, None, dicts, lists of strings) are stored as JSON and decoded.
    """
    ds = post.copy()
    ds.attrs = _encode_attrs(post.attrs)
    for name, var in ds.variables.items():
        var.attrs = _encode_attrs(post[name].attrs)
        var.encoding = {}
        if var.dtype.kind == "f":
            var.encoding["_FillValue"] = None  # NaN is data, not "missing"
    ds.to_netcdf(path, engine="netcdf4", format="NETCDF4")


def load(path: Any) -> xr.Dataset:
    """Read a posterior written by :func:`save` (fully into memory; the file is closed)."""
    with xr.open_dataset(path, engine="netcdf4", mask_and_scale=False, decode_times=False,
                         decode_timedelta=False) as f:
        ds = f.load()
    ds.attrs = _decode_attrs(ds.attrs)
    for name, var in ds.variables.items():
        var.attrs = _decode_attrs(var.attrs)
        var.encoding = {}
        if var.dtype.kind == "O":  # variable-length strings -> fixed-width unicode
            ds[name] = var.astype(str)
    for name in list(ds.coords):
        if ds[name].dtype.kind == "O":
            ds = ds.assign_coords({name: ds[name].values.astype(str)})
    return ds


# --------------------------------------------------------------------------
# Reporting, conversion, validation
# --------------------------------------------------------------------------
def summary(post: xr.Dataset) -> str:
    """A plain-text report: sampler, ESS, perplexity, evaluations, time, and per
    parameter the weighted mean ± sd, the 5/50/95 % quantiles and the MAP."""
    mean, cov = weighted_mean(post), weighted_cov(post)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    q = weighted_quantiles(post, [0.05, 0.5, 0.95])
    m, m_lt = map_estimate(post)
    names = [str(p) for p in post["param"].values]
    w = max(9, *(len(n) for n in names))
    lines = [
        f"sampler {post.attrs.get('sampler', '?')}: {post.sizes['sample']} samples, "
        f"ESS {ess(post):.1f}, perplexity {perplexity(post):.3f}, "
        f"{post.attrs.get('n_target_evals', float('nan')):.4g} target evaluations, "
        f"{post.attrs.get('wall_time_s', float('nan')):.3g} s; MAP log target {m_lt:.6g}",
        f"{'param':<{w}} {'mean':>10} {'sd':>10} {'5%':>10} {'50%':>10} {'95%':>10} {'MAP':>10}",
    ]
    for j, n in enumerate(names):
        lines.append(f"{n:<{w}} {mean[j]:>10.4g} {sd[j]:>10.4g} {q[0, j]:>10.4g} "
                     f"{q[1, j]:>10.4g} {q[2, j]:>10.4g} {m[j]:>10.4g}")
    return "\n".join(lines)


def to_arviz(post: xr.Dataset, *, resample_to_equal: bool = False, seed: int | None = None):
    """Convert to ``arviz.InferenceData`` (one chain, draws = samples).

    ArviZ has no place for importance weights and treats every draw as equally
    weighted. The weights are therefore kept as the ``sample_stats`` variable
    ``log_weight`` (normalised, logsumexp = 0) next to ``lp`` (the target log
    density), and are NOT applied by ArviZ's statistics or plots. For weighted
    samplers pass ``resample_to_equal=True`` (systematic resampling with
    ``seed``) to get equal-weight draws that ArviZ summarises correctly.
    The ``posterior`` group holds ``theta(chain, draw, param)``; the MAP trace
    and ESS per step go to a ``trace`` group; attributes are copied.
    """
    import arviz as az

    src = resample(post, seed=seed) if resample_to_equal else post
    theta = src["theta"].values[None]
    coords = {"param": [str(p) for p in src["param"].values]}
    posterior = xr.Dataset({"theta": (("chain", "draw", "param"), theta)},
                           coords={**coords, "chain": [0], "draw": np.arange(theta.shape[1])},
                           attrs=dict(src.attrs))
    stats = xr.Dataset({"log_weight": (("chain", "draw"), src["log_weight"].values[None]),
                        "lp": (("chain", "draw"), src["log_target"].values[None])},
                       coords={"chain": [0], "draw": np.arange(theta.shape[1])})
    trace = src[["map_theta", "map_log_target", "ess"]]
    import warnings

    with warnings.catch_warnings():  # arviz warns about the non-standard "trace" group
        warnings.simplefilter("ignore", UserWarning)
        return az.InferenceData(posterior=posterior, sample_stats=stats, trace=trace)


_REQUIRED_VARS = {
    "theta": ("sample", "param"), "log_weight": ("sample",), "log_target": ("sample",),
    "map_theta": ("step", "param"), "map_log_target": ("step",), "ess": ("step",),
}
_OPTIONAL_VARS = {"history_theta": ("step", "sample", "param"),
                  "history_log_weight": ("step", "sample")}
_REQUIRED_ATTRS = {"sampler": str, "config": str, "seed": int, "target": str,
                   "mrfpe_version": str, "n_target_evals": float, "wall_time_s": float}


def validate(post: Any) -> None:
    """Check that ``post`` follows the posterior schema of DESIGN.md.

    Raises
    ------
    ValueError
        Naming the first problem found: missing or mis-dimensioned variable,
        non-float data, NaN samples, log weights that are not normalised, an
        ESS outside [0, S], a ``param`` coordinate that does not match, or a
        missing / mistyped / non-JSON attribute.
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
    if np.isnan(post["theta"].values).any():
        raise ValueError("theta contains NaN")
    lw = post["log_weight"].values
    if np.isnan(lw).any() or np.isposinf(lw).any():
        raise ValueError("log_weight contains NaN or +inf")
    total = logsumexp(lw)
    if not abs(total) < 1e-6:
        raise ValueError(f"log_weight must be normalised (logsumexp = 0); got {total:.3g}")
    if np.isnan(post["log_target"].values).any():
        raise ValueError("log_target contains NaN (use -inf for impossible samples)")
    e = post["ess"].values
    if np.any((e < 0) | (e > S * (1 + 1e-9)) & ~np.isnan(e)):
        raise ValueError(f"ess must lie in [0, {S}] or be NaN; got {e}")
    if "step" not in post.coords:
        raise ValueError("posterior lacks the step coordinate")
    for key, typ in _REQUIRED_ATTRS.items():
        if key not in post.attrs:
            raise ValueError(f"posterior lacks the attribute {key!r}")
        v = post.attrs[key]
        ok = (isinstance(v, str) if typ is str else
              isinstance(v, int | np.integer) and not isinstance(v, bool) if typ is int else
              isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool))
        if not ok:
            raise ValueError(f"attribute {key!r} must be {typ.__name__}; got {v!r}")
    for key in ("config", "target"):
        try:
            json.loads(post.attrs[key])
        except json.JSONDecodeError as exc:
            raise ValueError(f"attribute {key!r} must be JSON: {exc}") from None
    if not post.attrs["n_target_evals"] >= 0:
        raise ValueError(f"n_target_evals must be >= 0; got {post.attrs['n_target_evals']}")
