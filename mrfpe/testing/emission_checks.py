"""Conformance checks for emissions (``mrfpe.emissions`` plugins and the built-ins).

::

    from mrfpe.testing import check_emission
    check_emission(models.emissions.gaussian(mean_prior=(0.5, 1.0), sd_prior=(3.0, 0.5)),
                   q=2, params=[0.0, 1.0, 0.5])
    # {'interface': 'passed', 'simulate': 'passed', 'log_lik': 'passed',
    #  'normalised': 'passed', 'moments': 'passed', 'update': 'passed', 'map_update': 'passed',
    #  'start': 'passed', 'errors': 'passed'}

Each check is also a public function ``check_emission_<name>(bound, ...)``:

* ``interface``: a name, distinct parameter names for 2 and 3 states, a data kind;
* ``simulate``: one value per label, of the declared kind, the same for one seed;
* ``log_lik``: batched ``(N, n, q)``, row by row the same, never NaN, 0 at missing nodes;
* ``normalised``: every state's density sums (counts, labels) or integrates (real
  values, on a fine grid) to 1;
* ``moments``: the simulated observations' mean per state agrees with the density's;
* ``update``: Geweke's (2004) test of a conjugate update -- the successive-conditional
  chain ``y ~ p(y | x, φ)``, ``φ ~ update(φ | x, y)`` started from the prior keeps the
  prior as its marginal: the chain's share below each prior quartile (estimated from
  independent prior draws) must agree with the prior's, within batch-means errors (a
  rank test, robust to the heavy tails of inverse-gamma priors). It needs proper priors
  narrow enough for the chain to mix (pass an emission with explicit priors);
* ``map_update``: the conditional mode beats its start and small moves around it;
* ``start``: parameters in the support, labels in ``[0, q)``;
* ``errors``: observations of the wrong kind (negative or fractional counts) refused.

An ``AssertionError`` lists every failure; ``skip=`` leaves checks out by name.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mrfpe.models.emissions.base import BoundEmission, Emission

__all__ = ["EMISSION_CHECKS", "check_emission"]

EMISSION_CHECKS = ("interface", "simulate", "log_lik", "normalised", "moments", "update",
                   "map_update", "start", "errors")


def _bind(emission: Emission, q: int, params: Any, n: int, seed: int,
          ) -> tuple[BoundEmission, np.ndarray, np.ndarray]:
    """``(bound on simulated data, labels, params)``: labels cycle through the states."""
    x = np.arange(n) % q
    rng = np.random.default_rng(seed)
    if params is None:  # the emission's own start on pilot data
        pilot = {"real": rng.normal(size=n) + x, "count": rng.poisson(3 * (1 + x)),
                 "label": x}[emission.data_kind].astype(float)
        params = emission.bind(q, pilot, np.ones(n, bool), {}, {}).start()[0]
    params = np.asarray(params, dtype=np.float64)
    y = emission.simulate(x, params, rng)
    return emission.bind(q, y, np.ones(n, bool), {}, {}), x, params


def check_emission_interface(emission: Emission) -> None:
    assert isinstance(emission.name, str) and emission.name, "name must be a non-empty str"
    assert emission.data_kind in ("real", "count", "label"), f"data_kind {emission.data_kind!r}"
    for q in (2, 3):
        names = emission.param_names(q)
        assert all(isinstance(s, str) for s in names) and len(set(names)) == len(names), \
            f"param_names({q}) must be distinct strings; got {names}"


def check_emission_simulate(emission: Emission, x: np.ndarray, params: np.ndarray) -> None:
    a = emission.simulate(x, params, np.random.default_rng(3))
    b = emission.simulate(x, params, np.random.default_rng(3))
    assert a.shape == x.shape, f"simulate returned {a.shape} for labels {x.shape}"
    assert np.array_equal(a, b), "simulate differs for one seed"
    if emission.data_kind != "real":
        assert np.all((a >= 0) & (a == np.round(a))), "simulated counts/labels not integers >= 0"


def check_emission_log_lik(bound: BoundEmission, params: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    batch = np.stack([params, bound.prior_sample(rng), bound.prior_sample(rng)])
    ll = bound.log_lik(batch)
    assert ll.shape == (3, bound.y.size, bound.q), f"log_lik shape {ll.shape}"
    assert not np.isnan(ll).any(), "log_lik is NaN somewhere"
    assert np.isfinite(ll[0]).all(), "log_lik is not finite at the true parameters"
    for k in range(3):
        np.testing.assert_allclose(bound.log_lik(batch[k])[0], ll[k], rtol=1e-12, atol=1e-12,
                                   err_msg="log_lik differs between batched and single rows")
    missing = bound.emission.bind(bound.q, bound.y, np.arange(bound.y.size) % 2 == 0, {}, {})
    assert np.all(missing.log_lik(params)[0, 1::2] == 0), "log_lik is not 0 at missing nodes"


def _grid(bound: BoundEmission, params: np.ndarray) -> tuple[np.ndarray, float]:
    """A support grid of ``y`` for sums (counts, labels) or integrals (real values)."""
    rng = np.random.default_rng(2)
    sims = bound.emission.simulate(np.repeat(np.arange(bound.q), 2000), params, rng)
    if bound.emission.data_kind == "real":
        lo, hi = sims.min(), sims.max()
        width = hi - lo
        grid = np.linspace(lo - 2 * width, hi + 2 * width, 40001)
        return grid, float(grid[1] - grid[0])
    if bound.emission.data_kind == "label":
        return np.arange(0.0, sims.max() + 1), 1.0
    return np.arange(0.0, 3 * sims.max() + 20), 1.0


def check_emission_normalised(bound: BoundEmission, params: np.ndarray) -> None:
    grid, step = _grid(bound, params)
    g = bound.emission.bind(bound.q, grid, np.ones(grid.size, bool), {}, {})
    dens = np.exp(g.log_lik(params)[0])  # (G, q)
    total = dens.sum(axis=0) * step
    assert np.allclose(total, 1.0, atol=2e-3), f"densities sum/integrate to {total}"


def check_emission_moments(bound: BoundEmission, params: np.ndarray) -> None:
    grid, step = _grid(bound, params)
    g = bound.emission.bind(bound.q, grid, np.ones(grid.size, bool), {}, {})
    dens = np.exp(g.log_lik(params)[0]) * step
    mean = grid @ dens
    var = (grid ** 2) @ dens - mean ** 2
    n = 4000
    sims = bound.emission.simulate(np.repeat(np.arange(bound.q), n), params,
                                   np.random.default_rng(4)).reshape(bound.q, n)
    z = (sims.mean(axis=1) - mean) / np.sqrt(np.maximum(var, 1e-300) / n)
    assert np.all(np.abs(z) < 5), f"simulated means {sims.mean(axis=1)} vs the density's {mean}"


def check_emission_update(bound: BoundEmission, x: np.ndarray, n_iter: int = 6000,
                          seed: int = 5) -> None:
    """Geweke's successive-conditional test of the conjugate update (module docstring)."""
    rng = np.random.default_rng(seed)
    free = np.ones(bound.d, bool)
    phi = bound.prior_sample(rng)
    if bound.update(phi, x, rng, free) is None:
        return
    prior = np.array([bound.prior_sample(rng) for _ in range(n_iter)])
    chain = np.empty((n_iter, bound.d))
    for k in range(n_iter):
        y = bound.emission.simulate(x, phi, rng)
        phi = bound.with_data(y).update(phi, x, rng, free)
        chain[k] = phi
    for j in range(bound.d):
        for level in np.quantile(prior[:, j], [0.25, 0.5, 0.75]):
            a, b = (prior[:, j] <= level).astype(float), (chain[:, j] <= level).astype(float)
            batches = b[: n_iter // 50 * 50].reshape(50, -1).mean(axis=1)
            se = np.sqrt(a.var() / n_iter + batches.var(ddof=1) / 50)
            z = (b.mean() - a.mean()) / max(se, 1e-12)
            assert abs(z) < 4.5, (f"{bound.names[j]}: the update's chain has {b.mean():.3f} below "
                                  f"the prior's quantile {level:.4g}, the prior {a.mean():.3f} "
                                  f"(z = {z:.1f}): the update does not leave the posterior "
                                  f"invariant")


def check_emission_map_update(bound: BoundEmission, x: np.ndarray, params: np.ndarray) -> None:
    rng = np.random.default_rng(6)
    resp = np.clip(bound.one_hot(x) + 0.2 * rng.random((x.size, bound.q)), 0, None)
    resp /= resp.sum(axis=1, keepdims=True)
    free = np.ones(bound.d, bool)

    def objective(p: np.ndarray) -> float:
        ll = bound.log_lik(p)[0]
        return float(np.sum(resp * ll) + bound.log_prior(p)[0])

    mode = bound.map_update(params, resp, free)
    for _ in range(200):  # conditional-mode rounds converge on coupled blocks
        new = bound.map_update(mode, resp, free)
        done = np.allclose(new, mode, rtol=1e-13, atol=0)
        mode = new
        if done:
            break
    best = objective(mode)
    assert best >= objective(params) - 1e-9, "map_update lowered the objective"
    width = bound.bounds[:, 1] - bound.bounds[:, 0]
    for _ in range(20):
        moved = mode + 1e-4 * width * rng.standard_normal(bound.d)
        if bound.in_support(moved)[0] and bound.emission.data_kind != "label":
            assert objective(moved) <= best + 1e-7 * abs(best), \
                "map_update's result is beaten by a small move: not a (local) mode"


def check_emission_start(bound: BoundEmission) -> None:
    params, labels = bound.start()
    assert bound.in_support(params)[0], f"start's parameters {params} lie outside the support"
    assert labels.shape == bound.y.shape and labels.min() >= 0 and labels.max() < bound.q


def check_emission_errors(emission: Emission, q: int, n: int) -> None:
    if emission.data_kind == "real":
        return
    bad = np.full(n, 1.5)
    try:
        emission.check_y(bad, np.ones(n, bool))
    except ValueError:
        return
    raise AssertionError("check_y accepted fractional counts/labels")


def check_emission(emission: Emission, q: int = 2, params: Any = None, n: int = 6,
                   seed: int = 0, skip: Sequence[str] = ()) -> dict[str, str]:
    """Run every emission check; ``{check: "passed" | "skipped"}`` or an AssertionError
    listing every failure (see the module docstring)."""
    if not isinstance(emission, Emission):
        raise AssertionError(f"not an mrfpe.models.emissions.Emission: {type(emission).__name__}")
    bound, x, params = _bind(emission, q, params, n, seed)
    runs = {"interface": lambda: check_emission_interface(emission),
            "simulate": lambda: check_emission_simulate(emission, x, params),
            "log_lik": lambda: check_emission_log_lik(bound, params),
            "normalised": lambda: check_emission_normalised(bound, params),
            "moments": lambda: check_emission_moments(bound, params),
            "update": lambda: check_emission_update(bound, x),
            "map_update": lambda: check_emission_map_update(bound, x, params),
            "start": lambda: check_emission_start(bound),
            "errors": lambda: check_emission_errors(emission, q, n)}
    out, failures = {}, []
    for name in EMISSION_CHECKS:
        if name in skip:
            out[name] = "skipped"
            continue
        try:
            runs[name]()
            out[name] = "passed"
        except Exception as exc:  # every failure is reported, not only the first
            failures.append(f"{name}: {type(exc).__name__}: {exc}")
    if failures:
        raise AssertionError(f"emission {emission.name!r} failed {len(failures)} check(s):\n"
                             + "\n".join(failures))
    return out
