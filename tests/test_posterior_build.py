"""mrfpe.posterior.build at the boundary: bad input is refused with a named error,
degenerate weights are never turned into numbers, and the package keeps its public names."""

import warnings

import numpy as np
import pytest

import mrfpe
from mrfpe import posterior as P


def _build(S=200, d=2, **kw):
    rng = np.random.default_rng(0)
    args = {"param_names": [f"p{j}" for j in range(d)], "sampler": "unit"}
    args.update(kw)
    theta = args.pop("theta", rng.random((S, d)))
    return P.build(theta, args.pop("log_target", np.zeros(len(theta))), **args)


def test_public_names_are_re_exported():
    for name in ("build", "load", "save", "summary", "validate", "to_arviz", "resample",
                 "weights", "weighted_mean", "weighted_cov", "weighted_quantiles", "ess",
                 "perplexity", "map_estimate", "normalise_log_weights", "diagnose",
                 "log_evidence", "PosteriorWarning"):
        assert name in P.__all__ and callable(getattr(P, name)), name
    assert mrfpe.PosteriorWarning is P.PosteriorWarning
    assert issubclass(P.PosteriorWarning, UserWarning)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_theta_is_refused(bad):
    theta = np.random.default_rng(1).random((10, 2))
    theta[4, 1] = bad
    with pytest.raises(ValueError, match=r"theta of the posterior of unit.*non-finite.*\[4\]"):
        _build(theta=theta)


@pytest.mark.parametrize("lw", [np.full(5, -np.inf), np.full(5, np.nan),
                                np.array([np.nan, -np.inf, np.nan, -np.inf, np.nan])])
def test_degenerate_weights_are_refused(lw):
    with pytest.raises(ValueError, match="log_weight of the posterior of unit has zero total"):
        _build(S=5, log_weight=lw)


def test_infinite_weight_is_refused():
    with pytest.raises(ValueError, match=r"log_weight.*\+inf"):
        _build(S=5, log_weight=[0.0, np.inf, 1.0, 2.0, 3.0])


def test_zero_weights_and_nan_as_zero_are_kept():
    post = _build(S=4, log_weight=[0.0, -np.inf, np.nan, 0.0])
    assert np.allclose(np.exp(post["log_weight"].values), [0.5, 0, 0, 0.5])


@pytest.mark.parametrize(("kw", "match"), [
    ({"chain": np.zeros(7, int)}, "chain must hold one label per sample"),
    ({"chain": -np.ones(200, int)}, "non-negative integer"),
    ({"chain": np.full(200, 0.5)}, "non-negative integer"),
    ({"chain": (np.arange(200) < 50).astype(int)}, "equal length"),
    ({"kind": "samples"}, "kind must be one of"),
    ({"log_evidence": "x"}, "log_evidence must be a float"),
    ({"log_evidence_se": True}, "log_evidence_se must be a float"),
    ({"log_weight": np.zeros(3)}, "log_weight has 3 values for 200"),
    ({"log_target": np.zeros(3)}, "log_target has 3 values"),
    ({"log_weight": ["a"] * 200}, "log_weight must be numeric"),
])
def test_bad_arguments_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        _build(**kw)


def test_chain_kind_and_evidence_are_stored():
    chain = np.repeat(np.arange(4), 50)  # contiguous chains are fine too
    post = _build(chain=chain.astype(float), log_evidence=-2.0, log_evidence_se=0.1,
                  kind="draws")
    assert post["chain"].dtype == np.int64 and post["chain"].dims == ("sample",)
    assert post.attrs["kind"] == "draws"
    assert post.attrs["log_evidence"] == -2.0 and post.attrs["log_evidence_se"] == 0.1
    assert "log_evidence" not in _build().attrs  # optional: absent when not given
    P.validate(post)


def test_build_stores_diagnostics_and_warns_once_when_unreliable():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        good = _build(S=500)  # 500 independent equal-weight draws: no warning
    assert good.attrs["diag_reliable"] == 1 and good.attrs["diag_messages"] == ""
    assert np.isclose(good.attrs["diag_ess"], 500.0) and np.isnan(good.attrs["diag_pareto_k"])
    assert np.isnan(good.attrs["diag_rhat"]) and np.isnan(good.attrs["diag_ess_chain"])
    with pytest.warns(P.PosteriorWarning) as record:
        bad = _build(S=50)
    assert len(record) == 1
    assert "draw more samples" in str(record[0].message)
    assert bad.attrs["diag_reliable"] == 0
    assert bad.attrs["diag_messages"] == "\n".join(P.diagnose(bad)["messages"])


def test_optima_are_diagnosed_but_not_warned_about():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        post = _build(S=20, kind="optima", log_weight=np.linspace(0, 1, 20))
    d = P.diagnose(post)
    assert d["kind"] == "optima" and not d["reliable"]
    assert "not draws from the posterior" in d["messages"][0]


def test_distances_refuse_zero_weight_sets_by_name():
    from mrfpe.distances.base import SampleSet

    good = _build(S=50, d=2)
    dead = good.assign(log_weight=good["log_weight"] * 0 - np.inf)  # bypassing build
    with pytest.raises(ValueError, match=r"^b\.log_weight has zero total weight"):
        mrfpe.distance("kl", good, dead)
    nan = good.assign(log_weight=good["log_weight"] * np.nan)
    with pytest.raises(ValueError, match=r"^a\.log_weight has zero total weight: every log "
                                         r"weight is NaN"):
        mrfpe.distance("emd", nan, good)
    with pytest.raises(ValueError, match=r"SampleSet.*zero total weight"):
        SampleSet(np.zeros((2, 1)), np.full(2, -np.inf), ("x",), good)
