"""Declaring a hidden MRF: names, simulation, the target and its checks (one line each)."""

import numpy as np
import pytest
import scipy.sparse as sp

from mrfpe import models
from mrfpe.models import emissions
from tests.models.hidden.transfer import forward_backward, gaussian_loglik


def _hm(q=2, **kw):
    return models.hidden(models.potts(q), emissions.gaussian(**kw))


def test_parameter_names_are_the_mrfs_then_the_emissions():
    assert _hm(3).param_names() == ("coupling", "field_1", "field_2", "mean_0", "mean_1",
                                    "mean_2", "sd")
    hm = models.hidden(models.potts(2, directional=True), emissions.poisson())
    assert hm.param_names() == ("coupling_horizontal", "coupling_vertical", "field", "rate_0",
                                "rate_1")
    assert hm.name == "hidden(potts, poisson)"


def test_simulate_returns_labels_and_observations_and_repeats_for_one_seed():
    hm = _hm(3)
    theta = [0.9, 0.0, 0.0, -1.0, 0.0, 1.0, 0.3]
    x, y = hm.simulate(theta, shape=(12, 10), seed=4)
    assert x.shape == y.shape == (12, 10) and x.dtype == np.int64 and y.dtype == np.float64
    x2, y2 = hm.simulate(theta, shape=(12, 10), seed=4)
    np.testing.assert_array_equal(x, x2)
    np.testing.assert_array_equal(y, y2)
    means = np.array([-1.0, 0.0, 1.0])
    assert (y - means[x]).std() == pytest.approx(0.3, rel=0.2)
    with pytest.raises(ValueError, match="theta must be 7 finite numbers"):
        hm.simulate(theta[:-1], shape=(4, 4), seed=0)


def test_a_general_graph_and_an_exposure_covariate():
    A = sp.random(30, 30, density=0.15, random_state=0)
    A = ((A + A.T) > 0).astype(float)
    A.setdiag(0)
    hm = models.hidden(models.potts(2, graph=models.from_adjacency(A)),
                       emissions.poisson(exposure="E"))
    e = np.linspace(0.5, 2.0, 30)
    x, y = hm.simulate([0.5, 0.0, 1.0, 6.0], seed=1, covariates={"E": e})
    assert x.shape == y.shape == (30,)
    t = hm.target("hidden", y, covariates={"E": e})
    assert t.node_shape == (30,) and t.param_names == hm.param_names()


def test_autologistic_with_a_covariate_as_the_hidden_field():
    hm = models.hidden(models.autologistic(covariates=["z"]), emissions.gaussian())
    z = np.linspace(-1, 1, 36).reshape(6, 6)
    names = hm.param_names(covariates={"z": z}, shape=(6, 6))
    assert names == ("coupling", "field", "z", "mean_0", "mean_1", "sd")
    _, y = hm.simulate([0.3, 0.0, 1.0, 0.0, 2.0, 0.5], shape=(6, 6), seed=0,
                       covariates={"z": z})
    t = hm.target("hidden", y, covariates={"z": z})
    assert t.param_names == names


def test_the_target_holds_free_parameters_and_their_bounds():
    hm = _hm(2)
    _, y = hm.simulate([0.8, 0.0, 0.0, 1.0, 0.5], shape=(6, 6), seed=0)
    t = hm.target("hidden", y, fixed={"field": 0.0}, bounds={"coupling": (0.0, 1.5),
                                                             "mean_0": (-1.0, 0.5)})
    assert t.param_names == ("coupling", "mean_0", "mean_1", "sd")
    np.testing.assert_array_equal(t.bounds[:2], [[0.0, 1.5], [-1.0, 0.5]])
    assert t.emission.flat.tolist() == [True, False, False]
    full = t.full([[0.5, 0.1, 0.9, 0.4]])
    np.testing.assert_array_equal(full, [[0.5, 0.0, 0.1, 0.9, 0.4]])
    d = t.describe()
    assert d["fixed"] == {"field": 0.0} and "mean_1" in d["priors"]


def test_the_pseudolikelihood_is_the_mrfs_pl_estimator():
    hm = _hm(3)
    x, y = hm.simulate([0.7, 0.2, -0.1, -1.0, 0.0, 1.0, 0.4], shape=(7, 9), seed=2)
    t = hm.target("hidden", y)
    th = np.array([[0.7, 0.2, -0.1], [0.1, 0.0, 0.3]])
    np.testing.assert_allclose(t.log_pl(x.ravel(), th),
                               models.potts(3).target("pl", x).log_prob(th))


def test_log_prob_is_exact_without_coupling():
    # the mean-field-like approximation is exact when the labels are independent
    hm = _hm(2)
    _, y = hm.simulate([0.0, 0.4, 0.0, 1.0, 0.5], shape=(3, 5), seed=3)
    t = hm.target("hidden", y, fixed={"coupling": 0.0})
    th = np.array([0.4, 0.1, 1.1, 0.6])
    L = gaussian_loglik(y.ravel(), th[1:3], th[3])
    exact = forward_backward(3, 5, 2, 0.0, [0.0, 0.4], L)[0] - \
        forward_backward(3, 5, 2, 0.0, [0.0, 0.4], None)[0]
    assert t.log_prob(th)[0] == pytest.approx(exact + t.emission.log_prior(th[1:])[0])


@pytest.mark.parametrize(("call", "match"), [
    (lambda hm, y: hm.target("hidden", y[:, :3].ravel()), r"y must be an image \(H, W\)"),
    (lambda hm, y: hm.target("hidden", np.where(np.arange(36).reshape(6, 6) % 7 == 3, np.nan, y)),
     r"y holds 5 non-finite value\(s\) \(NaN or inf\) outside the mask, the first at \(0, 3\)"),
    (lambda hm, y: hm.target("hidden", y, fixed={"couplin": 0.5}),
     r"fixed names 'couplin', which the model does not have \(did you mean 'coupling'\?\)"),
    (lambda hm, y: hm.target("hidden", y, bounds={"beta": (0, 1)}), "bounds names 'beta'"),
    (lambda hm, y: hm.target("hidden", y, fixed={"coupling": 5.0}), "outside its bounds"),
    (lambda hm, y: hm.target("hidden", y, fixed={"mean_0": 1.0, "mean_1": 0.0}),
     "break the order"),
    (lambda hm, y: hm.target("hidden", y, mask=np.ones((6, 6), bool)),
     "mask marks every observation missing"),
    (lambda hm, y: hm.target("hidden", y, mask=np.zeros((5, 6), bool)),
     "mask must be a boolean array of y's shape"),
    (lambda hm, y: hm.target("hidden", y, method="exact"), "method must be one of 'pl'"),
    (lambda hm, y: hm.target("hidden", y, fixed=dict.fromkeys(hm.param_names(), 0.5)),
     "fixed holds every parameter"),
    (lambda hm, y: hm.target("hidden", np.round(y * 0)), "more than the data can support"),
    (lambda hm, y: hm.target("hidden", y, fixed={"sd": np.nan}), "finite number"),
    (lambda hm, y: hm.target("hidden", y, covariates={"z": y}), "not used by any term"),
])
def test_bad_input_is_one_line_before_any_work(call, match):
    hm = _hm(2)
    _, y = hm.simulate([0.8, 0.0, 0.0, 1.0, 0.5], shape=(6, 6), seed=0)
    with pytest.raises(ValueError, match=match) as err:
        call(hm, y)
    assert "\n" not in str(err.value)


def test_missing_observations_may_hold_anything():
    hm = _hm(2)
    _, y = hm.simulate([0.8, 0.0, 0.0, 1.0, 0.5], shape=(6, 6), seed=0)
    y[2, 3], y[4, 4] = np.nan, np.inf
    mask = np.zeros((6, 6), bool)
    mask[2, 3] = mask[4, 4] = True
    t = hm.target("hidden", y, mask=mask)
    assert t.observed.sum() == 34 and np.isfinite(t.y).all()
    assert np.all(t.emission.log_lik(t.emission.start()[0])[0, [15, 28]] == 0)


def test_too_many_states_for_counts_and_wrong_declarations():
    hm = models.hidden(models.potts(3), emissions.poisson())
    with pytest.raises(ValueError, match="takes only 2 distinct value"):
        hm.target("hidden", np.tile([0.0, 4.0], 18).reshape(6, 6))
    with pytest.raises(ValueError, match="non-negative integer counts"):
        hm.target("hidden", np.full((6, 6), -1.0))
    with pytest.raises(ValueError, match="mrf must be a declared discrete MRF"):
        models.hidden(models.autonormal(), emissions.gaussian())
    with pytest.raises(ValueError, match=r"emission must be an mrfpe\.models\.emissions"):
        models.hidden(models.potts(2), "gaussian")
