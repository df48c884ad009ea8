"""Hand-made weighted sample sets for the distance tests."""

from __future__ import annotations

import numpy as np
import xarray as xr

from mrfpe.posterior import build

NAMES2 = ("u", "v")


def post(theta, log_weight=None, names=None, log_target=None, **kw) -> xr.Dataset:
    """A posterior Dataset from samples, (unnormalised) log weights and optional log target."""
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim == 1:
        theta = theta[:, None]
    names = names or [f"p{i}" for i in range(theta.shape[1])]
    lt = np.zeros(theta.shape[0]) if log_target is None else log_target
    return build(theta, lt, param_names=names, log_weight=log_weight, sampler="test", **kw)


def random_post(rng, S=25, d=2, loc=0.0, scale=1.0, weighted=True) -> xr.Dataset:
    theta = loc + scale * rng.standard_normal((S, d))
    lw = rng.standard_normal(S) if weighted else None
    return post(theta, lw, log_target=rng.standard_normal(S))


def grid_points(n_per_axis=5, d=2) -> np.ndarray:
    axes = [np.linspace(0.0, 1.0, n_per_axis)] * d
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, d)


def grid_post(rng, n_per_axis=5, d=2) -> xr.Dataset:
    g = grid_points(n_per_axis, d)
    return post(g, 1.5 * rng.standard_normal(g.shape[0]), log_target=rng.standard_normal(len(g)))


def with_moments(mu, cov, rng, S=40, weighted=True) -> xr.Dataset:
    """A weighted sample set whose weighted mean and (biased) covariance are exactly mu, cov."""
    mu = np.atleast_1d(np.asarray(mu, float))
    cov = np.atleast_2d(np.asarray(cov, float))
    d = mu.size
    z = rng.standard_normal((S, d))
    lw = rng.standard_normal(S) if weighted else np.zeros(S)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    zc = z - w @ z
    c = (zc * w[:, None]).T @ zc
    x = zc @ np.linalg.inv(np.linalg.cholesky(c)).T @ np.linalg.cholesky(cov).T + mu
    return post(x, lw)


def permuted(ds: xr.Dataset, rng) -> xr.Dataset:
    """The same posterior with its samples in another order."""
    return ds.isel(sample=rng.permutation(ds.sizes["sample"]))


def duplicated_vs_doubled(ds: xr.Dataset, k: int) -> tuple[xr.Dataset, xr.Dataset]:
    """(sample k duplicated, sample k with its weight doubled) -- the same distribution."""
    theta = ds["theta"].values
    lw = ds["log_weight"].values
    lt = ds["log_target"].values
    names = [str(p) for p in ds["param"].values]
    dup = post(np.vstack([theta, theta[k:k + 1]]), np.append(lw, lw[k]), names,
               np.append(lt, lt[k]))
    lw2 = lw.copy()
    lw2[k] += np.log(2.0)
    dbl = post(theta, lw2, names, lt)
    return dup, dbl


def with_var(ds: xr.Dataset, name: str, values) -> xr.Dataset:
    out = ds.copy(deep=True)
    out[name] = (out[name].dims, np.asarray(values, dtype=np.float64))
    return out
