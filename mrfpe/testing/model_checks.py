"""Conformance checks for models (plugins of the ``mrfpe.models`` group).

Run them on your own model with data it accepts::

    from mrfpe.testing import check_model
    check_model(my_model, x)                  # x: data for the model's estimators
    check_model(my_model, x, estimators=("pl", "coding"))

What the Model contract (:mod:`mrfpe.models.base`) promises and the checks verify:

* ``name`` a non-empty string; ``estimators`` distinct strings; every estimator's
  options are :class:`mrfpe.targets.options.Option` s;
* an unknown estimator or option raises ``ValueError`` naming the valid ones;
* every estimator builds a target that passes :func:`mrfpe.testing.check_target`
  (batched, ``-inf`` outside the bounds, never NaN ...);
* if ``"pl"`` and ``"coding"`` are offered: the ``n_codings`` codings' log_probs
  sum to the PL's (Besag's codings partition the nodes);
* if ``"block"`` is offered with single-node blocks, it equals the PL;
* ``simulate``, if offered: the data's shape, and the same seed gives the same draws.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from mrfpe.testing._collect import failure, run_all
from mrfpe.testing.target_checks import _close, _inside, check_target

__all__ = ["MODEL_CHECKS", "check_model", "check_model_codings", "check_model_errors",
           "check_model_interface", "check_model_simulate", "check_model_targets"]


def _fail(m: Any, check: str, msg: str) -> AssertionError:
    return failure("model", m, check, msg)


def _chosen(model: Any, estimators: Sequence[str] | None) -> tuple[str, ...]:
    return tuple(model.estimators if estimators is None else estimators)


def check_model_interface(model: Any, data: Any = None, **_: Any) -> None:
    """``name`` a string; ``estimators`` distinct strings; options declared as Options."""
    from mrfpe.targets.options import Option

    if not isinstance(getattr(model, "name", None), str) or not model.name:
        raise _fail(model, "check_model_interface", "name must be a non-empty string")
    est = getattr(model, "estimators", None)
    if not est or isinstance(est, str) or not all(isinstance(e, str) for e in est) \
            or len(set(est)) != len(est):
        raise _fail(model, "check_model_interface", f"estimators must be distinct strings; "
                    f"got {est!r}")
    for e in est:
        opts = model.options(e)
        if not all(isinstance(o, Option) for o in opts):
            raise _fail(model, "check_model_interface", f"options of {e!r} must be Option s")


def check_model_errors(model: Any, data: Any, **_: Any) -> None:
    """Unknown estimator / option: ``ValueError`` naming the valid ones."""
    for bad, kwargs, want in (("no_such_estimator", {}, model.estimators[0]),
                              (model.estimators[0], {"no_such_option": 1}, "valid")):
        try:
            model.target(bad, data, **kwargs)
        except ValueError as exc:
            if want not in str(exc):
                raise _fail(model, "check_model_errors", f"the error for {bad!r} {kwargs} "
                            f"should mention {want!r}; got: {exc}") from None
            continue
        except Exception as exc:
            raise _fail(model, "check_model_errors", f"{bad!r} {kwargs} raised "
                        f"{type(exc).__name__} instead of ValueError: {exc}") from exc
        raise _fail(model, "check_model_errors", f"target({bad!r}, data, **{kwargs}) did not "
                    f"raise ValueError")


def check_model_targets(model: Any, data: Any, *, estimators: Sequence[str] | None = None,
                        rtol: float = 1e-9, options: Mapping[str, Any] | None = None,
                        **_: Any) -> None:
    """Every chosen estimator's target passes :func:`mrfpe.testing.check_target`."""
    opts = dict(options or {})
    for e in _chosen(model, estimators):
        try:
            target = model.target(e, data, **opts)
        except Exception as exc:
            raise _fail(model, "check_model_targets", f"target({e!r}, data) raised "
                        f"{type(exc).__name__}: {exc}") from exc
        try:
            check_target(target, rtol=rtol)
        except AssertionError as exc:
            raise _fail(model, "check_model_targets", f"estimator {e!r}: {exc}") from None


def check_model_codings(model: Any, data: Any, *, estimators: Sequence[str] | None = None,
                        rtol: float = 1e-9, shape: Any = None,
                        options: Mapping[str, Any] | None = None, **_: Any) -> str:
    """The codings' log_probs sum to the PL's; single-node blocks equal the PL."""
    opts = dict(options or {})
    est = _chosen(model, estimators)
    if "pl" not in est:
        return "skipped"
    pl = model.target("pl", data, **opts)
    theta = _inside(pl, 7, 3)
    want = pl.log_prob(theta)
    done = False
    if "coding" in est:
        shape = np.shape(data)[-2:] if shape is None else shape
        k = model.n_codings(shape)
        total = sum(model.target("coding", data, coding=c, **opts).log_prob(theta)
                    for c in range(k))
        if not np.all(_close(total, want, rtol)):
            raise _fail(model, "check_model_codings", f"the {k} codings sum to "
                        f"{np.asarray(total)[:3].tolist()}, the PL is {want[:3].tolist()}")
        done = True
    if "block" in est:
        one = [o for o in model.options("block") if o.name == "block"]
        single = (1, 1) if np.ndim(data) >= 2 and getattr(model, "graph_spec", None) is not \
            None and hasattr(model.graph_spec, "offsets") else 1
        if one:
            got = model.target("block", data, block=single, **opts).log_prob(theta)
            if not np.all(_close(got, want, rtol)):
                raise _fail(model, "check_model_codings", f"block pseudolikelihood with "
                            f"single-node blocks gives {got[:3].tolist()}, the PL "
                            f"{want[:3].tolist()}")
            done = True
    return "passed" if done else "skipped"


def check_model_simulate(model: Any, data: Any, *, theta: Any = None,
                         options: Mapping[str, Any] | None = None, **_: Any) -> str:
    """``simulate`` returns the data's shape and is reproducible from ``seed``."""
    sim = getattr(model, "simulate", None)
    if sim is None or theta is None:
        return "skipped"
    shape = np.shape(data)[-2:] if getattr(model, "graph_spec", None) is not None and \
        hasattr(model.graph_spec, "offsets") else None
    cov = {"covariates": options["covariates"]} if options and options.get("covariates") \
        is not None else {}
    a = model.simulate(theta, shape=shape, n=2, seed=11, **cov)
    b = model.simulate(theta, shape=shape, n=2, seed=11, **cov)
    one = np.shape(data)[-(len(np.shape(a)) - 1):]
    if np.shape(a)[1:] != one or np.shape(a)[0] != 2:
        raise _fail(model, "check_model_simulate", f"simulate(n=2) must return (2, "
                    f"{', '.join(map(str, one))}); got {np.shape(a)}")
    if not np.array_equal(a, b):
        raise _fail(model, "check_model_simulate", "the same seed gave different draws")
    return "passed"


#: The checks :func:`check_model` runs, by name.
MODEL_CHECKS: dict[str, Callable[..., Any]] = {
    "interface": check_model_interface,
    "errors": check_model_errors,
    "targets": check_model_targets,
    "codings": check_model_codings,
    "simulate": check_model_simulate,
}


def check_model(model: Any, data: Any, *, estimators: Sequence[str] | None = None,
                theta: Any = None, rtol: float = 1e-9, options: Mapping[str, Any] | None = None,
                skip: tuple[str, ...] = ()) -> dict[str, str]:
    """Run every model check on ``data``; return ``{check: "passed" | "skipped"}``.

    Parameters
    ----------
    model : a :class:`mrfpe.models.Model` (or a zero-argument factory returning one).
    data : what the model's estimators take (small: every estimator is built).
    estimators : the estimators to check (default all; leave out e.g. ``"exact"``
        where the data are too large for it).
    theta : parameters for the simulator check (skipped without).
    rtol : tolerance of the sum identities.
    options : further options passed to every ``target`` call (e.g. ``covariates``).
    skip : names of :data:`MODEL_CHECKS` not to run.

    Raises
    ------
    AssertionError
        Listing every failed check.
    """
    from mrfpe.models.base import Model

    if not isinstance(model, Model) and callable(model):
        model = model()
    if not isinstance(model, Model):
        raise ValueError(f"model must be an mrfpe.models.Model or a factory returning one; "
                         f"got {type(model).__name__}")
    unknown = sorted(set(skip) - set(MODEL_CHECKS))
    if unknown:
        raise ValueError(f"skip names unknown checks {unknown}; checks: "
                         f"{', '.join(MODEL_CHECKS)}")

    def call(name: str, fn: Callable) -> Callable[[], str]:
        def check() -> str:
            if name in skip:
                return "skipped"
            out = fn(model, data, estimators=estimators, rtol=rtol, theta=theta,
                     options=options)
            return out or "passed"
        return check

    return run_all({name: call(name, fn) for name, fn in MODEL_CHECKS.items()}, "model")
