"""Property-based: the netCDF round trip is exact for random posteriors (weights with
zeros and duplicates, random parameter names, chains, optima, evidence attributes)."""

import tempfile
import warnings
from pathlib import Path

import numpy as np
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrfpe import posterior as P

_NAMES = st.lists(st.text(st.characters(blacklist_categories=("Cs", "Cc")), min_size=1,
                          max_size=10), min_size=1, max_size=4, unique=True)


@st.composite
def posteriors(draw):
    names = draw(_NAMES)
    d = len(names)
    n_chains = draw(st.integers(1, 3))
    S = n_chains * draw(st.integers(1, 12))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=(S, d)) * 10.0 ** draw(st.integers(-3, 3))
    # weights: a few distinct values, so duplicates, with zeros (-inf) and NaN sprinkled in
    pool = draw(st.lists(st.floats(-700, 700), min_size=1, max_size=4))
    lw = np.array(pool)[rng.integers(0, len(pool), S)]
    lw[rng.random(S) < draw(st.floats(0, 0.6))] = -np.inf
    lw[rng.random(S) < 0.1] = np.nan
    if not np.isfinite(lw).any():
        lw[rng.integers(S)] = pool[0]
    lt = np.where(rng.random(S) < 0.2, -np.inf, rng.normal(size=S))
    lt[rng.integers(S)] = 0.0  # a target -inf everywhere is refused (no support)
    kw = {}
    if draw(st.booleans()):
        kw["chain"] = np.tile(np.arange(n_chains), S // n_chains)
    if draw(st.booleans()):
        kw["log_evidence"] = draw(st.floats(-1e6, 1e6))
        kw["log_evidence_se"] = draw(st.one_of(st.floats(0, 10), st.just(float("nan"))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", P.PosteriorWarning)
        return P.build(theta, lt, param_names=names, log_weight=lw,
                       kind=draw(st.sampled_from(["draws", "optima"])), sampler="h",
                       config={"n": S, "names": names}, seed=draw(st.one_of(st.none(),
                       st.integers(0, 2**31))), target={"class": "T"}, **kw)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(posteriors())
def test_property_netcdf_round_trip_is_exact(post):
    P.validate(post)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "p.nc"
        P.save(post, path)
        back = P.load(path)
    xr.testing.assert_identical(back, post)
    for k in post.variables:
        assert back[k].dtype == post[k].dtype, k
    for k, v in post.attrs.items():  # exact, including types (bool stays bool, list list)
        assert type(back.attrs[k]) is type(v), k
    assert list(back["param"].values) == list(post["param"].values)
    assert np.array_equal(back["log_weight"].values, post["log_weight"].values)
