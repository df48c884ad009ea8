"""Parametric-bootstrap intervals for a model's point estimate (the MPLE by default).

Fit the data, simulate data sets of the same size at the estimate with the
model's simulator (:func:`mrfpe.models.draws.simulate_draws`), refit each:
the refits' spread is the estimator's sampling distribution at the estimate, as
R's ngspatial reports for the MPLE of an autologistic model.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.models.draws import simulate_draws
from mrfpe.targets.maximise import grid_size, maximise
from mrfpe.validation import check_positive_int

__all__ = ["parametric_bootstrap"]


def parametric_bootstrap(model: Any, data: Any, *, n_boot: int = 200, estimator: str = "pl",
                         seed: int = 0, **options: Any) -> Any:
    """Parametric-bootstrap distribution of the maximiser of ``estimator`` (default the MPLE).

    Fits the data, simulates ``n_boot`` data sets of the same size at the
    estimate with the model's simulator, refits each; returns a posterior-schema
    Dataset of ``kind="optima"`` (the refits; their quantiles are the bootstrap
    intervals) with the original estimate as ``map_theta``. Refits on the box's face
    (a simulated data set without information on a parameter, e.g. a uniform lattice
    near the critical coupling) are marked in the variable ``on_face`` and named in
    the posterior's ``bias`` attribute and diagnostics.

    The refits need data sets the model can simulate: a model whose data are a scene
    (the BRDF MRF draws the labels of a fixed image, not images) is refused, as is an
    ``n_boot`` that is not a positive integer, before any fit.
    """
    from mrfpe.posterior import build

    n_boot = check_positive_int("n_boot", n_boot)
    rng = np.random.default_rng(seed)
    target = model.target(estimator, data, **options)
    if getattr(target, "data_kind", "data") == "scene":
        raise ValueError(f"parametric_bootstrap refits {estimator!r} on data sets simulated at "
                         f"the estimate, and model {getattr(model, 'name', model)!r} simulates "
                         f"the labels of a fixed scene, not scenes: bootstrap its label-field "
                         f"estimators elsewhere, or use 'pl_adjusted' or the exchange sampler "
                         f"for a calibrated posterior")
    grid = max(3, grid_size(4096, target.ndim))  # at most 4096 points
    theta_hat, value = maximise(target, grid=grid, seed=int(rng.integers(2**31)))
    lik = model.target("likelihood", data, **{k: v for k, v in options.items()
                                               if k in ("covariates", "bounds")})
    draws = simulate_draws(lik, theta_hat, n_boot * lik.n_observations,
                           seed=int(rng.integers(2**63)))
    from mrfpe.models.graph import LatticeSpec

    lattice = isinstance(getattr(model, "graph_spec", None), LatticeSpec)
    shape = tuple(np.shape(data)[-2:]) if lattice else (lik.x.shape[1],)
    fits, values, boxes = [], [], []
    for k in range(n_boot):
        yk = draws.y[k * lik.n_observations:(k + 1) * lik.n_observations]
        tk = model.target(estimator, yk.reshape(-1, *shape), **options)
        t, v = maximise(tk, grid=grid, seed=int(rng.integers(2**31)))
        fits.append(t)
        values.append(v)
        boxes.append(np.asarray(tk.bounds, dtype=np.float64))
    fits, b = np.array(fits), np.array(boxes)  # (n_boot, d), (n_boot, d, 2)
    tol = 1e-6 * (b[:, :, 1] - b[:, :, 0])
    on_face, bias = (fits - b[:, :, 0] <= tol) | (b[:, :, 1] - fits <= tol), None
    if on_face.any():  # degenerate simulated data (e.g. uniform lattices): the bound is no fit
        faces = [target.param_names[j] for j in np.flatnonzero(on_face.any(axis=0))]
        bias = (f"{int(on_face.any(axis=1).sum())} of {n_boot} refits lie on the box's face "
                f"({', '.join(faces)}): their data sets carry no information there, so "
                f"intervals reaching that bound are truncated by the box, not estimated")
    return build(fits, np.array(values), param_names=target.param_names,
                 map_theta=theta_hat[None], map_log_target=np.array([value]),
                 sampler="parametric_bootstrap", kind="optima", target=target,
                 config={"n_boot": n_boot, "estimator": estimator}, seed=seed, bias=bias,
                 extra_vars={"on_face": (("sample",), on_face.any(axis=1))},
                 extra_attrs={"simulation_sweeps": draws.n_sweeps, "tau": draws.tau})

