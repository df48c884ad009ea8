"""Tests of mrfpe.posterior: statistics, resampling, netCDF round trip, ArviZ, schema."""

import json

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from mrfpe import posterior as P


def make_post(S=50, d=3, seed=0, weighted=True, history=False, **kw):
    rng = np.random.default_rng(seed)
    theta = rng.random((S, d))
    lt = -np.sum((theta - 0.5) ** 2, axis=1) * 10
    lw = rng.normal(size=S) if weighted else None
    T = 4
    extra = {}
    if history:
        extra = {"history_theta": rng.random((T, S, d)),
                 "history_log_weight": np.log(np.full((T, S), 1.0 / S))}
    return P.build(theta, lt, param_names=[f"p{j}" for j in range(d)], log_weight=lw,
                   map_theta=np.tile(theta[np.argmax(lt)], (T, 1)),
                   map_log_target=np.full(T, lt.max()), ess=np.array([1.0, np.nan, 3.0, 4.0]),
                   sampler="test", config={"a": 1}, seed=seed, target={"class": "X"},
                   n_target_evals=12.5, wall_time_s=0.1, **extra, **kw)


def test_weighted_mean_cov_against_numpy():
    post = make_post()
    w = P.weights(post)
    x = post["theta"].values
    assert np.isclose(w.sum(), 1.0)
    assert np.allclose(P.weighted_mean(post), np.average(x, axis=0, weights=w))
    # biased, weight-normalised covariance = np.cov(aweights, bias=True)
    assert np.allclose(P.weighted_cov(post), np.cov(x.T, aweights=w, bias=True))


def test_ess_and_perplexity_closed_forms():
    assert np.isclose(P.ess(np.zeros(10)), 10)
    assert np.isclose(P.ess([0.0, -np.inf, -np.inf]), 1)
    assert np.isclose(P.ess(np.log([1.0, 1.0, 2.0])), 16 / 6)  # (Σw)²/Σw²
    assert np.isclose(P.perplexity(np.zeros(8)), 1.0)
    assert np.isclose(P.perplexity([0.0, -np.inf, -np.inf, -np.inf]), 0.25)
    w = np.array([0.5, 0.25, 0.25])
    h = -np.sum(w * np.log(w))
    assert np.isclose(P.perplexity(np.log(w)), np.exp(h) / 3)
    assert np.isclose(P.perplexity(np.log(w), normalised=False), np.exp(h))
    post = make_post()
    assert np.isclose(P.ess(post), 1 / np.sum(P.weights(post) ** 2))


def test_weighted_quantiles():
    post = make_post(weighted=False, S=41)
    q = [0.0, 0.1, 0.5, 0.9, 1.0]
    expect = np.quantile(post["theta"].values, q, axis=0, method="hazen")
    assert np.allclose(P.weighted_quantiles(post, q), expect)
    # importance-weighted uniform sample -> normal quantiles (independent route: scipy)
    rng = np.random.default_rng(3)
    x = rng.uniform(-6, 6, (200_000, 1))
    big = P.build(x, np.zeros(len(x)), param_names=["x"], log_weight=stats.norm.logpdf(x[:, 0]),
                  sampler="t")
    got = P.weighted_quantiles(big, [0.05, 0.5, 0.975])[:, 0]
    assert np.allclose(got, stats.norm.ppf([0.05, 0.5, 0.975]), atol=0.03)
    # zero-weight samples are ignored
    z = P.build(np.array([[0.0], [1.0], [100.0]]), np.zeros(3), param_names=["x"],
                log_weight=[0.0, 0.0, -np.inf], sampler="t")
    assert P.weighted_quantiles(z, 1.0)[0, 0] == 1.0
    with pytest.raises(ValueError, match="q must"):
        P.weighted_quantiles(post, [1.5])


def test_map_estimate():
    post = make_post()
    m, lt = P.map_estimate(post)
    assert lt == post["log_target"].max()
    assert np.array_equal(m, post["theta"].values[int(np.argmax(post["log_target"].values))])
    post["map_log_target"][:] = -np.inf  # no trace: fall back to the best sample
    m2, lt2 = P.map_estimate(post)
    assert lt2 == lt and np.array_equal(m2, m)


@pytest.mark.parametrize("method", ["multinomial", "systematic", "stratified", "residual"])
def test_resample_to_equal_weights(method):
    post = make_post(history=True)
    eq = P.resample(post, n=200, method=method, seed=1)
    assert eq.sizes["sample"] == 200
    assert np.allclose(eq["log_weight"], -np.log(200))
    assert "history_theta" not in eq and "map_theta" in eq
    assert eq.attrs["sampler"] == "test" and json.loads(eq.attrs["resampled"])["n"] == 200
    P.validate(eq)
    # every drawn row is an original row with its own target value
    rows = {tuple(r): lt for r, lt in zip(post["theta"].values, post["log_target"].values)}
    for r, lt in zip(eq["theta"].values, eq["log_target"].values):
        assert rows[tuple(r)] == lt
    # the equal-weight mean approximates the weighted mean
    big = P.resample(post, n=20000, method=method, seed=2)
    assert np.allclose(P.weighted_mean(big), P.weighted_mean(post), atol=0.01)
    assert np.array_equal(P.resample(post, method=method, seed=4)["theta"],
                          P.resample(post, method=method, seed=4)["theta"])
    with pytest.raises(ValueError, match="n must"):
        P.resample(post, n=0)


def test_netcdf_round_trip_is_exact(tmp_path):
    post = make_post(history=True)
    post["log_target"][3] = -np.inf
    post["log_weight"][:] = P.normalise_log_weights(np.where(np.arange(50) == 3, -np.inf,
                                                             post["log_weight"].values))
    post["ess"][0] = np.nan
    post["accepted"] = (("step",), np.array([True, False, True, True]))
    post["count"] = (("step",), np.arange(4, dtype=np.int32))
    post.attrs.update(flag=True, nothing=None, nested={"a": [1, 2]}, arr=np.array([1.5, 2.5]),
                      npf=np.float32(0.5))
    post["theta"].attrs["units"] = "unit cube"
    path = tmp_path / "p.nc"
    P.save(post, path)
    back = P.load(path)
    xr.testing.assert_identical(back, post)
    for k in post.variables:
        assert back[k].dtype == post[k].dtype, k
    assert back.attrs["flag"] is True and back.attrs["nothing"] is None
    assert back.attrs["nested"] == {"a": [1, 2]}
    assert np.isneginf(back["log_target"][3]) and np.isnan(back["ess"][0])
    assert back["param"].dtype.kind == "U"
    P.save(back, tmp_path / "again.nc")  # a loaded posterior saves again identically
    xr.testing.assert_identical(P.load(tmp_path / "again.nc"), post)


def test_to_arviz_honours_weights_by_default():
    az = pytest.importorskip("arviz")
    post = make_post(S=400, seed=5)
    idata = P.to_arviz(post)
    assert isinstance(idata, az.InferenceData)
    assert idata.posterior.attrs["mrfpe_weights"] == "resampled"
    assert idata.posterior["theta"].shape == (1, 400, 3)
    assert np.allclose(idata.sample_stats["log_weight"], -np.log(400))
    # the default is the seeded systematic resample, so ArviZ's mean is the resampled mean
    eq = P.resample(post, seed=0)
    assert np.array_equal(idata.posterior["theta"].values[0], eq["theta"].values)
    assert np.array_equal(idata.sample_stats["lp"].values[0], eq["log_target"].values)
    mean = az.summary(idata, kind="stats")["mean"].to_numpy()
    # ArviZ's statistic estimates the weighted mean (resampling noise ~ sd/sqrt(ESS))
    sd = np.sqrt(np.diag(P.weighted_cov(post)))
    assert np.all(np.abs(mean - P.weighted_mean(post)) < 4 * sd / np.sqrt(P.ess(post)))
    assert list(idata.posterior["param"].values) == ["p0", "p1", "p2"]
    assert idata.posterior.attrs["diag_ess"] == post.attrs["diag_ess"]


def test_to_arviz_unweighted_export_and_equal_weights():
    pytest.importorskip("arviz")
    post = make_post()
    raw = P.to_arviz(post, resample_to_equal=False)
    assert raw.posterior.attrs["mrfpe_weights"] == "ignored"
    assert np.array_equal(raw.sample_stats["log_weight"].values[0], post["log_weight"].values)
    assert np.array_equal(raw.posterior["theta"].values[0], post["theta"].values)
    eq = make_post(weighted=False)
    idata = P.to_arviz(eq)  # equal weights are passed through, not resampled
    assert idata.posterior.attrs["mrfpe_weights"] == "equal"
    assert np.array_equal(idata.posterior["theta"].values[0], eq["theta"].values)


def test_to_arviz_chain_layout():
    pytest.importorskip("arviz")
    S, c = 60, 3
    chain = np.tile(np.arange(c), S // c)  # interleaved, as MCMC samplers store them
    post = make_post(S=S, weighted=False, chain=chain)
    idata = P.to_arviz(post)
    th = idata.posterior["theta"].values
    assert th.shape == (3, 20, 3)
    for k in range(c):
        assert np.array_equal(th[k], post["theta"].values[chain == k])  # draw order kept
    assert list(idata.posterior["chain"].values) == [0, 1, 2]
    assert "chain" not in P.resample(post, seed=0)  # resampled draws are no longer chains


def test_to_arviz_rejects_bad_input():
    pytest.importorskip("arviz")
    with pytest.raises(ValueError, match="post must be a posterior"):
        P.to_arviz({})
    post = make_post()
    post["log_weight"][:] = -np.inf
    with pytest.raises(ValueError, match=r"posterior of test.*zero total weight"):
        P.to_arviz(post)


def test_summary_mentions_everything():
    text = P.summary(make_post())
    for word in ("sampler test", "ESS", "perplexity", "p0", "p2", "MAP", "95%", "Pareto k̂",
                 "R̂ n/a", "UNRELIABLE", "ESS 25.2 < 100"):
        assert word in text
    good = P.build(np.random.default_rng(0).random((500, 2)), np.zeros(500),
                   param_names=["a", "b"], sampler="s", log_evidence=-1.5, log_evidence_se=0.01)
    text = P.summary(good)
    assert ": reliable" in text and "log evidence" in text and "-1.5 ± 0.01" in text


def _corruptions():
    def drop(v):
        return lambda p: p.drop_vars(v)
    yield "theta", drop("theta")
    yield "log_weight", lambda p: p.assign(log_weight=p["log_weight"] + 1.0)
    yield "NaN", lambda p: p.assign(theta=p["theta"].where(p["theta"] > 0.1))
    yield "float64", lambda p: p.assign(log_target=p["log_target"].astype(np.float32))
    yield "dims", lambda p: p.assign(ess=(("foo",), p["ess"].values))
    yield "ess", lambda p: p.assign(ess=p["ess"] * 0 + 1e6)
    yield "sampler", lambda p: p.assign_attrs(sampler=None)
    yield "attribute 'seed'", lambda p: p.drop_attrs() if hasattr(p, "drop_attrs") else \
        p.assign_attrs(seed="x")
    yield "JSON", lambda p: p.assign_attrs(config="{not json")
    yield "n_target_evals", lambda p: p.assign_attrs(n_target_evals=-1.0)
    yield "inf theta", lambda p: p.assign(theta=p["theta"].where(p["theta"] > 0.1, np.inf))
    yield "all -inf weights", lambda p: p.assign(log_weight=p["log_weight"] * 0 - np.inf)
    yield "kind", lambda p: p.assign_attrs(kind="guesses")
    yield "diag_reliable", lambda p: p.assign_attrs(diag_reliable="yes")
    yield "diag_messages", lambda p: p.assign_attrs(diag_messages=[1, 2])
    yield "log_evidence", lambda p: p.assign_attrs(log_evidence="big")
    yield "chain dtype", lambda p: p.assign(chain=(("sample",), np.zeros(p.sizes["sample"])))
    yield "chain lengths", lambda p: p.assign(
        chain=(("sample",), (np.arange(p.sizes["sample"]) < 3).astype(np.int64)))


@pytest.mark.parametrize(("what", "corrupt"), list(_corruptions()))
def test_validate_rejects_corrupt_posteriors(what, corrupt):
    post = make_post(history=True)
    P.validate(post)
    with pytest.raises(ValueError):
        P.validate(corrupt(post))


def test_validate_rejects_non_dataset():
    with pytest.raises(ValueError, match=r"xarray\.Dataset"):
        P.validate({"theta": 1})


def test_normalise_log_weights_degenerate():
    assert np.allclose(np.exp(P.normalise_log_weights([-np.inf, -np.inf])), 0.5)
    assert np.allclose(np.exp(P.normalise_log_weights([0.0, np.inf, np.inf])), [0, 0.5, 0.5])
    assert np.allclose(np.exp(P.normalise_log_weights([np.nan, 1.0])), [0, 1])
    out = P.normalise_log_weights([1e308, -1e308])
    assert out[0] == 0 and np.isneginf(out[1])
