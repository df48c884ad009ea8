"""Conformance suite for sampler plugins (like scikit-learn's ``check_estimator``).

Third-party authors run it on their own sampler::

    from mrfpe.testing import check_sampler
    check_sampler(MySampler)            # or check_sampler("my_name") once registered

Every check is a public function ``check_<name>(sampler, config=None, **options)``
that raises ``AssertionError`` with a clear message; :func:`check_sampler` runs
them all and reports every failure at once. The analytic targets the checks use
are public too: :class:`CorrelatedGaussian` (3-D, in the unit cube, with a
``partition`` into "observation" subsets that mimics a lattice's sub-lattices,
and ``residuals``), :class:`TwoModes` and :class:`MostlyMinusInf`.

Declaring what does not apply
-----------------------------
A sampler may set the class attribute ``conformance``, a dict whose keys are
check names (see :data:`CHECKS`) and whose values are ``False`` (the check does
not apply: it is skipped and reported as skipped), or a dict of options for
that check (e.g. a looser ``two_modes`` tolerance). The special key
``"quick_config"`` holds the keyword configuration used when ``quick=True`` (a
small budget so the suite runs in seconds); without it the defaults are used.

Two checks cannot be declared away or loosened (:data:`UNDECLARABLE`):
``diagnostics``, and ``gaussian_moments``, whose tolerances come from the
posterior's own ESS (:func:`moment_tolerances`) within fixed absolute bounds. The
one exemption from the moment check is a posterior that says it is not a sample:
a multi-start optimiser builds its posterior with ``kind="optima"``
(:func:`mrfpe.posterior.build`), and the check reports ``"skipped: optima ..."``::

    class MultiStart:
        conformance = {"quick_config": {"n_seeds": 27}}
        def run(self, target, *, seed, progress=False, callback=None):
            ...
            return build(optima, log_target, ..., kind="optima")

A sampler that returns draws but declares ``"gaussian_moments": False`` (or
tolerances) fails that check, saying so. Keep other declarations explicit and
explain them in the sampler's docs: a skipped check is a documented limitation,
not a silent pass.
"""

from __future__ import annotations

import inspect
import json
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from mrfpe import posterior as _post
from mrfpe.testing._collect import run_all
from mrfpe.testing._runs import (
    _cached_run,
    _declared,
    _fail,
    _resolve,
    _run,
    _run_or_refusal,
)
from mrfpe.testing.accuracy import (
    CORR_MAX,
    MEAN_MAX,
    MOMENT_FLOOR,
    MOMENT_Z,
    SD_RATIO_BOUNDS,
    check_diagnostics,
    check_gaussian_moments,
    moment_tolerances,
)
from mrfpe.testing.targets import CorrelatedGaussian, MostlyMinusInf, TwoModes

__all__ = [
    "CHECKS", "CORR_MAX", "MEAN_MAX", "MOMENT_FLOOR", "MOMENT_Z", "SD_RATIO_BOUNDS",
    "UNDECLARABLE", "check_bounds", "check_callback", "check_config", "check_diagnostics",
    "check_gaussian_moments", "check_interface", "check_map_trace", "check_mostly_minus_inf",
    "check_netcdf_roundtrip", "check_reproducible", "check_sampler", "check_schema",
    "check_two_modes", "moment_tolerances", "run_check",
]


# --------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------
def check_interface(sampler: Any, config: dict | None = None) -> None:
    """The registry's interface rules: a class, constructible with no arguments,
    ``run(target, *, seed, progress, callback)``."""
    cls, name = _resolve(sampler)
    from mrfpe.samplers.registry import validate_sampler

    try:
        validate_sampler(cls)
        cls()
    except Exception as exc:
        raise _fail(name, "check_interface", f"{type(exc).__name__}: {exc}") from exc


def check_config(sampler: Any, config: dict | None = None) -> None:
    """Configs are explicit keyword arguments with validated values.

    ``__init__`` takes no ``*args``/``**kwargs``; every parameter has a default;
    a value of the wrong kind (``object()``; ``NaN`` for a float setting; an
    unknown string for a string setting) raises ``ValueError``; an unknown
    keyword raises ``TypeError``; and the posterior's ``config`` attribute
    records every constructor argument.
    """
    cls, name = _resolve(sampler)
    params = list(inspect.signature(cls.__init__).parameters.values())[1:]
    var = [p.name for p in params if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if var:
        raise _fail(name, "check_config", f"__init__ must not take *args/**kwargs ({var})")
    for p in params:
        bad_values: list[Any] = [object()]
        if isinstance(p.default, float):
            bad_values.append(float("nan"))
        if isinstance(p.default, str):
            bad_values.append("\x00not-a-valid-choice")
        for bad in bad_values:
            try:
                cls(**{p.name: bad})
            except ValueError:
                continue
            except Exception as exc:
                raise _fail(name, "check_config", f"{p.name}={bad!r} raised "
                            f"{type(exc).__name__} instead of ValueError: {exc}") from exc
            raise _fail(name, "check_config", f"{p.name}={bad!r} was accepted; "
                        "invalid settings must raise ValueError at construction")
    try:
        cls(**{"no_such_setting_xyz": 1})
    except TypeError:
        pass
    else:
        raise _fail(name, "check_config", "an unknown keyword was accepted")
    post = _cached_run(cls, config, CorrelatedGaussian, 0)
    recorded = json.loads(post.attrs["config"])
    missing = [p.name for p in params if p.name not in recorded]
    if missing:
        raise _fail(name, "check_config", f"posterior attrs['config'] lacks {missing}")


def check_schema(sampler: Any, config: dict | None = None) -> None:
    """The posterior passes :func:`mrfpe.posterior.validate` and describes the target."""
    cls, name = _resolve(sampler)
    post = _cached_run(cls, config, CorrelatedGaussian, 0)
    try:
        _post.validate(post)
    except ValueError as exc:
        raise _fail(name, "check_schema", str(exc)) from exc
    names = [str(p) for p in post["param"].values]
    if names != list(CorrelatedGaussian.param_names):
        raise _fail(name, "check_schema", f"param coordinate {names} != target's param_names")
    if post.attrs["seed"] != 0:
        raise _fail(name, "check_schema", f"attrs['seed'] = {post.attrs['seed']}, ran with 0")
    if not post.attrs["n_target_evals"] > 0:
        raise _fail(name, "check_schema", "n_target_evals must count the evaluations (> 0)")
    if not post.attrs["wall_time_s"] >= 0:
        raise _fail(name, "check_schema", "wall_time_s must be >= 0")


def _numbers(post: xr.Dataset) -> xr.Dataset:
    out = post.copy()
    out.attrs = {k: v for k, v in post.attrs.items() if k != "wall_time_s"}
    return out


def check_reproducible(sampler: Any, config: dict | None = None) -> None:
    """Same seed -> identical numbers; a different seed -> different samples."""
    cls, name = _resolve(sampler)
    a = _cached_run(cls, config, CorrelatedGaussian, 0)
    b = _run(cls, config, CorrelatedGaussian(), 0)
    try:
        xr.testing.assert_identical(_numbers(a), _numbers(b))
    except AssertionError as exc:
        raise _fail(name, "check_reproducible", f"two runs with seed=0 differ:\n{exc}") from exc
    c = _run(cls, config, CorrelatedGaussian(), 1)
    if a["theta"].shape == c["theta"].shape and np.array_equal(a["theta"], c["theta"]):
        raise _fail(name, "check_reproducible", "seeds 0 and 1 gave identical samples")


def check_bounds(sampler: Any, config: dict | None = None) -> None:
    """Samples and the MAP trace lie inside the target's bounds (all three targets)."""
    cls, name = _resolve(sampler)
    for tcls in (CorrelatedGaussian, TwoModes, MostlyMinusInf):
        post = _run_or_refusal(cls, config, tcls, 0) if tcls is MostlyMinusInf else \
            _cached_run(cls, config, tcls, 0)
        if post is None:
            continue
        b = tcls.bounds
        for var in ("theta", "map_theta"):
            x = post[var].values
            bad = ~np.all((x >= b[:, 0]) & (x <= b[:, 1]), axis=-1)
            if bad.any():
                raise _fail(name, "check_bounds", f"{int(bad.sum())} rows of {var} outside the "
                            f"bounds of {tcls.__name__}, e.g. {x[bad][0]}")


def check_two_modes(sampler: Any, config: dict | None = None, *, tol: float = 0.05) -> None:
    """On :class:`TwoModes` the MAP lies within ``tol`` of the higher mode."""
    cls, name = _resolve(sampler)
    post = _cached_run(cls, config, TwoModes, 0)
    m, lt = _post.map_estimate(post)
    d = float(np.linalg.norm(m - TwoModes.high))
    if not d <= tol:
        raise _fail(name, "check_two_modes", f"MAP {m.round(4)} (log target {lt:.3g}) is "
                    f"{d:.3f} from the higher mode {TwoModes.high} (tolerance {tol})")


def check_mostly_minus_inf(sampler: Any, config: dict | None = None) -> None:
    """A target that is ``-inf`` almost everywhere is survived: either a valid posterior
    in which samples with ``log_target = -inf`` carry no weight, or — if no sample found
    the support — the honest ``ValueError`` of :func:`mrfpe.posterior.build` ("zero
    total weight"), never another exception or a made-up uniform weighting."""
    cls, name = _resolve(sampler)
    try:
        post = _run_or_refusal(cls, config, MostlyMinusInf, 0)
    except Exception as exc:
        raise _fail(name, "check_mostly_minus_inf", f"raised {type(exc).__name__}: {exc}") from exc
    if post is None:
        return
    try:
        _post.validate(post)
    except ValueError as exc:
        raise _fail(name, "check_mostly_minus_inf", str(exc)) from exc
    lt, lw = post["log_target"].values, post["log_weight"].values
    if not np.isfinite(lt).any():
        raise _fail(name, "check_mostly_minus_inf", "every sample has log_target = -inf, yet "
                    "the posterior weights them; a set with no sample in the support must be "
                    "refused (build raises for all -inf log weights)")
    carrying = int(np.sum(np.isneginf(lt) & np.isfinite(lw)))
    if carrying:
        raise _fail(name, "check_mostly_minus_inf",
                    f"{carrying} samples with log_target = -inf carry weight")


def check_netcdf_roundtrip(sampler: Any, config: dict | None = None) -> None:
    """:func:`mrfpe.posterior.save` then :func:`~mrfpe.posterior.load` returns the posterior
    unchanged (values, dtypes, attributes)."""
    cls, name = _resolve(sampler)
    for tcls in (CorrelatedGaussian, MostlyMinusInf):
        post = _run_or_refusal(cls, config, tcls, 0) if tcls is MostlyMinusInf else \
            _cached_run(cls, config, tcls, 0)
        if post is None:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "post.nc"
            _post.save(post, path)
            back = _post.load(path)
        try:
            xr.testing.assert_identical(back, post)
        except AssertionError as exc:
            raise _fail(name, "check_netcdf_roundtrip", f"{tcls.__name__}: {exc}") from exc
        for k in post.variables:
            if back[k].dtype != post[k].dtype:
                raise _fail(name, "check_netcdf_roundtrip",
                            f"{k}: dtype {post[k].dtype} came back as {back[k].dtype}")


def check_map_trace(sampler: Any, config: dict | None = None, *, rtol: float = 1e-8) -> None:
    """``map_log_target`` is the target's log density at ``map_theta`` and never decreases
    (a best-so-far trace), and the final MAP is at least as good as every final sample."""
    cls, name = _resolve(sampler)
    for tcls in (CorrelatedGaussian, TwoModes):
        post = _cached_run(cls, config, tcls, 0)
        mt, ml = post["map_theta"].values, post["map_log_target"].values
        fin = np.isfinite(ml)
        lp = tcls().log_prob(mt[fin])
        if not np.allclose(lp, ml[fin], rtol=rtol, atol=1e-9):
            raise _fail(name, "check_map_trace", f"{tcls.__name__}: map_log_target "
                        f"{ml[fin][:4]} != log_prob(map_theta) {lp[:4]}")
        if np.any(np.diff(np.where(fin, ml, -np.inf)) < 0):
            raise _fail(name, "check_map_trace", f"{tcls.__name__}: map_log_target decreases")
        best = np.max(post["log_target"].values)
        if best > ml[-1] + 1e-9 * max(1.0, abs(best)):
            raise _fail(name, "check_map_trace", f"{tcls.__name__}: a final sample "
                        f"(log target {best:.6g}) beats the final MAP ({ml[-1]:.6g})")


def check_callback(sampler: Any, config: dict | None = None) -> None:
    """``callback(step, info)`` is called per step with an int step and a dict, and
    ``progress=True`` runs (the bar goes to stderr)."""
    cls, name = _resolve(sampler)
    calls: list[tuple[Any, Any]] = []
    post = _run(cls, config, CorrelatedGaussian(), 0, progress=True,
                callback=lambda step, info: calls.append((step, info)))
    if not calls:
        raise _fail(name, "check_callback", "callback was never called")
    steps = [s for s, _ in calls]
    if not all(isinstance(s, int | np.integer) for s in steps) or np.any(np.diff(steps) <= 0):
        raise _fail(name, "check_callback", f"steps must be increasing ints; got {steps[:5]}...")
    if not all(isinstance(i, dict) for _, i in calls):
        raise _fail(name, "check_callback", "info must be a dict")
    if len(calls) > post.sizes["step"] * 10_000:  # pragma: no cover - sanity bound
        raise _fail(name, "check_callback", "callback called implausibly often")


CHECKS: dict[str, Callable[..., None]] = {
    "interface": check_interface,
    "config": check_config,
    "schema": check_schema,
    "reproducible": check_reproducible,
    "bounds": check_bounds,
    "gaussian_moments": check_gaussian_moments,
    "diagnostics": check_diagnostics,
    "two_modes": check_two_modes,
    "mostly_minus_inf": check_mostly_minus_inf,
    "netcdf_roundtrip": check_netcdf_roundtrip,
    "map_trace": check_map_trace,
    "callback": check_callback,
}


#: Checks a ``conformance`` declaration may neither skip (``False``) nor tune (options).
#: ``gaussian_moments`` exempts exactly the posteriors of ``kind="optima"`` by itself.
UNDECLARABLE = frozenset({"gaussian_moments", "diagnostics"})


def run_check(sampler: Any, check: str, *, quick: bool = True) -> str:
    """Run one named check with the sampler's declarations.

    Returns ``"passed"``, ``"skipped: declared"`` (the sampler declared the check not
    applicable) or ``"skipped: <reason>"`` (the check found it does not apply, e.g.
    ``gaussian_moments`` on a set of optima); raises ``AssertionError`` on failure,
    including a declaration that tries to skip or loosen a check in
    :data:`UNDECLARABLE` for a posterior the check applies to.
    """
    if check not in CHECKS:
        raise ValueError(f"unknown check {check!r}; checks: {', '.join(CHECKS)}")
    cls, name = _resolve(sampler)
    decl = _declared(cls, check)
    config = getattr(cls, "conformance", {}).get("quick_config") if quick else None
    if check in UNDECLARABLE:
        skipped = CHECKS[check](cls, config)
        if decl is not True and skipped is None:
            raise _fail(name, f"check_{check}", f"{name}.conformance[{check!r}] = {decl!r}, "
                        "but this check cannot be skipped or loosened by a declaration"
                        + ("; only a posterior of kind='optima' (build(..., kind='optima')) "
                           "is exempt" if check == "gaussian_moments" else ""))
        return "passed" if skipped is None else f"skipped: {skipped}"
    if decl is False:
        return "skipped: declared"
    opts = decl if isinstance(decl, dict) else {}
    skipped = CHECKS[check](cls, config, **opts)
    return "passed" if skipped is None else f"skipped: {skipped}"


def check_sampler(sampler: Any, *, quick: bool = True) -> dict[str, str]:
    """Run every conformance check on ``sampler`` (a class or a registered name).

    Returns ``{check: "passed" | "skipped: ..."}``; raises one
    ``AssertionError`` listing every failed check. ``quick=True`` runs with the
    sampler's ``conformance["quick_config"]`` (its defaults otherwise).
    """
    cls, name = _resolve(sampler)
    if not isinstance(getattr(cls, "conformance", {}), dict):
        raise AssertionError(f"{name}.conformance must be a dict")
    unknown = set(getattr(cls, "conformance", {})) - set(CHECKS) - {"quick_config"}
    if unknown:
        raise AssertionError(f"{name}.conformance names unknown checks {sorted(unknown)}; "
                             f"known: {', '.join(CHECKS)}")
    return run_all({check: (lambda c=check: run_check(cls, c, quick=quick)) for check in CHECKS},
                   "conformance")
