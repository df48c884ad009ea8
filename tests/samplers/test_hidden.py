"""The hidden sampler: one call, one posterior of every parameter and of the labels."""

import warnings

import numpy as np
import pytest
import xarray as xr

import mrfpe
from mrfpe import models
from mrfpe import posterior as P
from mrfpe.models import emissions
from mrfpe.samplers.hidden import HiddenSampler
from mrfpe.testing import check_sampler, check_target

QUICK = {"n_steps": 300, "burn_in": 100, "n_chains": 2}


@pytest.fixture(autouse=True)
def registered():
    """The sampler under its name, in this process (pyproject registers it for installs)."""
    mrfpe.samplers.registry.register("hidden", HiddenSampler)
    yield
    mrfpe.samplers.registry.unregister("hidden")


@pytest.fixture(autouse=True)
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        yield


@pytest.fixture(scope="module")
def image():
    hm = models.hidden(models.potts(2), emissions.gaussian())
    x, y = hm.simulate([1.0, 0.0, 0.0, 1.0, 0.4], shape=(12, 12), seed=1)
    return hm, x, y


def test_one_call_gives_every_parameter_and_the_labels(image):
    hm, x, y = image
    post = mrfpe.sample("hidden", hm.target("hidden", y, fixed={"field": 0.0}), seed=0, **QUICK)
    mrfpe.samplers.check_result(post, "hidden")
    assert list(post["param"].values) == ["coupling", "mean_0", "mean_1", "sd"]
    assert post["label_probability"].dims == ("row", "col", "state")
    assert post["label_probability"].shape == (12, 12, 2)
    np.testing.assert_allclose(post["label_probability"].sum("state"), 1.0)
    assert (post["label_mode"].values == x).mean() > 0.9
    np.testing.assert_array_equal(post["label_mode"], post["label_probability"].argmax("state"))
    assert post["param_rhat"].dims == post["param_ess"].dims == ("param",)
    assert np.isfinite(post.attrs["label_mcse_max"])
    assert np.all(np.diff(post["theta"].values[:, 1:3], axis=1) > 0)  # means kept ordered
    assert "mean_0" in post.attrs["priors"] and post.attrs["method"] == "pl"
    assert "pseudo-posterior" in post.attrs["diag_messages"]
    assert post.attrs["diag_reliable"] == 0


def test_same_seed_same_numbers(image):
    hm, _, y = image
    t = hm.target("hidden", y)
    a, b = (mrfpe.sample("hidden", t, seed=3, **QUICK) for _ in range(2))
    np.testing.assert_array_equal(a["theta"], b["theta"])
    np.testing.assert_array_equal(a["label_probability"], b["label_probability"])
    c = mrfpe.sample("hidden", t, seed=4, **QUICK)
    assert not np.array_equal(a["theta"], c["theta"])


def test_netcdf_and_arviz_keep_the_label_posterior(image, tmp_path):
    hm, _, y = image
    post = mrfpe.sample("hidden", hm.target("hidden", y), seed=0, **QUICK)
    P.save(post, tmp_path / "p.nc")
    xr.testing.assert_identical(P.load(tmp_path / "p.nc"), post)
    post.to_netcdf(tmp_path / "plain.nc")
    with xr.open_dataset(tmp_path / "plain.nc") as back:
        np.testing.assert_array_equal(back["label_mode"], post["label_mode"])
    idata = P.to_arviz(post)
    np.testing.assert_array_equal(idata.summary["label_probability"], post["label_probability"])
    assert idata.posterior["theta"].shape[:2] == (2, 200)


def test_known_parameters_make_an_exact_posterior_without_the_pseudolikelihood(image):
    hm, _, y = image
    t = hm.target("hidden", y, fixed={"coupling": 1.0, "field": 0.0})
    post = mrfpe.sample("hidden", t, seed=0, n_steps=600, burn_in=100)
    assert "pseudo-posterior" not in post.attrs["diag_messages"]
    assert np.isnan(post["mrf_acceptance"].values).all()


def test_missing_observations_are_integrated_over(image):
    hm, x, y = image
    mask = np.zeros_like(y, dtype=bool)
    mask[3:6, 3:6] = True
    y = y.copy()
    y[mask] = np.nan
    post = mrfpe.sample("hidden", hm.target("hidden", y, mask=mask, fixed={"field": 0.0}),
                        seed=0, **QUICK)
    assert np.isfinite(post["theta"].values).all()
    inner = post["label_probability"].values[4, 4]
    assert 0.0 < inner.max() < 1.0  # from the neighbours only: not certain
    assert (post["label_mode"].values[~mask] == x[~mask]).mean() > 0.9


def test_swendsen_wang_labels_agree_with_gibbs(image):
    hm, _, y = image
    t = hm.target("hidden", y, fixed={"coupling": 1.0, "field": 0.0, "sd": 0.4})
    g = mrfpe.sample("hidden", t, seed=0, n_steps=800, burn_in=100)
    s = mrfpe.sample("hidden", t, seed=0, n_steps=800, burn_in=100, labels="swendsen_wang")
    se = np.hypot(g["label_probability_mcse"], s["label_probability_mcse"]).values
    diff = np.abs(g["label_probability"] - s["label_probability"]).values
    assert np.all(diff < 5 * se + 0.01)


def test_swendsen_wang_is_refused_for_tables_it_cannot_cluster():
    hm = models.hidden(models.potts(2), emissions.gaussian())
    _, y = hm.simulate([-0.5, 0.0, 0.0, 1.0, 0.4], shape=(6, 6), seed=0)
    t = hm.target("hidden", y, fixed={"coupling": -0.5})
    with pytest.raises(ValueError, match="labels='swendsen_wang' needs ferromagnetic"):
        mrfpe.sample("hidden", t, seed=0, labels="swendsen_wang", **QUICK)


@pytest.mark.parametrize(("emission", "theta", "fixed"), [
    (emissions.poisson(), [0.9, 0.0, 2.0, 8.0], {}),
    (emissions.categorical(), [0.9, 0.0, 0.9, 0.1, 0.1, 0.9], {"field": 0.0}),
    (emissions.gaussian(shared_sd=False), [0.9, 0.0, 0.0, 2.0, 0.3, 0.6], {}),
])
def test_every_emission_samples_end_to_end(emission, theta, fixed):
    hm = models.hidden(models.potts(2), emission)
    x, y = hm.simulate(theta, shape=(10, 10), seed=2)
    post = mrfpe.sample("hidden", hm.target("hidden", y, fixed=fixed), seed=0, **QUICK)
    P.validate(post)
    assert (post["label_mode"].values == x).mean() > 0.8
    assert np.all(np.isfinite(post["theta"].values))


def test_a_general_emission_is_sampled_by_a_random_walk():
    def log_density(y, phi):
        loc, scale = phi[:, None, :2], phi[:, None, 2:3]
        return -np.abs(y[None, :, None] - loc) / scale - np.log(2 * scale)

    em = emissions.general(log_density, [("loc_0", (-3, 3)), ("loc_1", (-3, 3)),
                                         ("scale", (0.05, 5))])
    hm = models.hidden(models.potts(2), em)
    truth = np.where(np.arange(100).reshape(10, 10) % 10 < 5, -1.0, 1.0)
    y = truth + np.random.default_rng(0).laplace(scale=0.3, size=(10, 10))
    post = mrfpe.sample("hidden", hm.target("hidden", y, fixed={"field": 0.0}), seed=0,
                        n_steps=600, burn_in=200, n_chains=2)
    acc = post["emission_acceptance"].values
    assert 0.05 < np.nanmean(acc[200:]) < 0.9
    means = post["theta"].values[:, 1:3].mean(axis=0)
    assert sorted(np.round(means)) == [-1.0, 1.0]


def test_states_the_data_cannot_support_are_flagged():
    hm = models.hidden(models.potts(3), emissions.gaussian())
    rng = np.random.default_rng(0)
    y = np.where(np.arange(64).reshape(8, 8) % 8 < 4, 0.0, 10.0) + 0.01 * rng.normal(size=(8, 8))
    post = mrfpe.sample("hidden", hm.target("hidden", y, fixed={"coupling": 1.0}), seed=0,
                        **QUICK)
    assert post["state_empty_fraction"].values.max() > 0.5
    assert "the data support fewer than n_states=3 states" in post.attrs["diag_messages"]


def test_init_choices_and_bad_settings():
    hm = models.hidden(models.potts(2), emissions.gaussian())
    _, y = hm.simulate([0.8, 0.0, 0.0, 1.0, 0.4], shape=(6, 6), seed=0)
    t = hm.target("hidden", y)
    for init in ("icm", "classify"):
        P.validate(mrfpe.sample("hidden", t, seed=0, init=init, **QUICK))
    for bad in ({"labels": "metropolis"}, {"init": "kmeans"}, {"n_batches": 1},
                {"theta_steps": 0}, {"burn_in": 400, "n_steps": 300}):
        with pytest.raises(ValueError):
            mrfpe.sample("hidden", t, seed=0, **{**QUICK, **bad})


def test_the_hidden_target_is_a_target_and_the_sampler_a_sampler(image):
    hm, _, y = image
    assert set(check_target(hm.target("hidden", y)).values()) == {"passed"}
    # on a target without labels the sampler is random-walk Metropolis: every check
    assert set(check_sampler(HiddenSampler).values()) == {"passed"}
