"""Emission declarations: names, improper priors refused in one line, the registry."""

import numpy as np
import pytest

from mrfpe.models import emissions


def test_parameter_names_follow_the_states():
    assert emissions.gaussian().param_names(3) == ("mean_0", "mean_1", "mean_2", "sd")
    assert emissions.gaussian(shared_sd=False).param_names(2) == ("mean_0", "mean_1", "sd_0",
                                                                   "sd_1")
    assert emissions.poisson().param_names(2) == ("rate_0", "rate_1")
    assert emissions.categorical(n_categories=3).param_names(2)[:3] == ("prob_0_0", "prob_0_1",
                                                                         "prob_0_2")


@pytest.mark.parametrize(("make", "match"), [
    (lambda: emissions.gaussian(mean_prior=(0.0, 0.0)), "mean_prior must be a proper prior"),
    (lambda: emissions.gaussian(mean_prior=(0.0, np.inf)), "mean_prior must be a proper prior"),
    (lambda: emissions.gaussian(sd_prior=(0.0, 1.0)), "sd_prior must be a proper prior"),
    (lambda: emissions.gaussian(sd_prior=(1.0, -1.0)), "sd_prior must be a proper prior"),
    (lambda: emissions.gaussian(sd_prior="wide"), "sd_prior must be a pair of numbers"),
    (lambda: emissions.poisson(rate_prior=(-1.0, 1.0)), "rate_prior must be a proper prior"),
    (lambda: emissions.categorical(concentration=0.0), "concentration must be a proper"),
    (lambda: emissions.categorical(concentration=[[1, -1], [1, 1]]), "proper Dirichlet"),
    (lambda: emissions.gaussian(shared_sd="yes"), "shared_sd"),
    (lambda: emissions.poisson(exposure=3), "exposure must be None or a covariate name"),
])
def test_improper_or_bad_priors_are_refused_at_once(make, match):
    with pytest.raises(ValueError, match=match) as err:
        make()
    assert "\n" not in str(err.value)


def test_bounds_outside_a_parameters_domain_or_on_categorical_probabilities_are_refused():
    y, obs = np.arange(6.0), np.ones(6, bool)
    with pytest.raises(ValueError, match=r"bounds\['sd'\].*domain"):
        emissions.gaussian().bind(2, y, obs, {}, {"sd": (-1.0, 2.0)})
    with pytest.raises(ValueError, match=r"bounds\['rate_0'\].*domain"):
        emissions.poisson().bind(2, y, obs, {}, {"rate_0": (-1.0, 2.0)})
    with pytest.raises(ValueError, match="Dirichlet"):
        emissions.categorical().bind(2, y % 2, obs, {}, {"prob_0_0": (0.1, 0.9)})


def test_data_of_the_wrong_kind_is_refused():
    obs = np.ones(3, bool)
    with pytest.raises(ValueError, match="non-negative integer counts"):
        emissions.poisson().check_y(np.array([1.0, -2.0, 3.0]), obs)
    with pytest.raises(ValueError, match="non-negative integer labels"):
        emissions.categorical().check_y(np.array([0.0, 0.5, 1.0]), obs)
    with pytest.raises(ValueError, match=r"categories 0 \.\. 1"):
        emissions.categorical().bind(2, np.array([0.0, 1.0, 2.0]), obs, {}, {})


def test_poisson_exposure_must_be_given_and_positive():
    y, obs = np.arange(4.0), np.ones(4, bool)
    em = emissions.poisson(exposure="E")
    with pytest.raises(ValueError, match="must include the exposure 'E'"):
        em.bind(2, y, obs, {}, {})
    with pytest.raises(ValueError, match="finite value > 0 per node"):
        em.bind(2, y, obs, {"E": np.array([1.0, 0.0, 1.0, 1.0])}, {})


def test_general_emission_declarations_and_outputs_are_checked():
    def ld(y, phi):
        return np.zeros((phi.shape[0], y.size, 2))

    with pytest.raises(ValueError, match="finite with low < high"):
        emissions.general(ld, [("a", (1.0, 0.0))])
    with pytest.raises(ValueError, match="each once"):
        emissions.general(ld, [("a", (0, 1)), ("a", (0, 1))])
    with pytest.raises(ValueError, match="must return"):
        emissions.general(ld, [("a", (0, 1))]).bind(3, np.zeros(4), np.ones(4, bool), {}, {})
    nan = emissions.general(lambda y, phi: np.full((phi.shape[0], y.size, 2), np.nan),
                            [("a", (0, 1))])
    with pytest.raises(ValueError, match=r"NaN or \+inf at \(a=0.5\)"):
        nan.bind(2, np.zeros(4), np.ones(4, bool), {}, {})
    with pytest.raises(ValueError, match="has no simulator"):
        emissions.general(ld, [("a", (0, 1))]).simulate(np.zeros(3, int), np.array([0.5]),
                                                        np.random.default_rng(0))


def test_fixed_values_are_checked_against_support_order_and_rows():
    y, obs = np.linspace(0, 1, 6), np.ones(6, bool)
    b = emissions.gaussian().bind(2, y, obs, {}, {})
    with pytest.raises(ValueError, match="break the order"):
        b.check_fixed({"mean_0": 1.0, "mean_1": 0.0})
    with pytest.raises(ValueError, match="outside its support"):
        b.check_fixed({"sd": -1.0})
    c = emissions.categorical().bind(2, (y > 0.5).astype(float), obs, {}, {})
    with pytest.raises(ValueError, match="must sum"):
        c.check_fixed({"prob_0_0": 0.7, "prob_0_1": 0.7})


def test_the_registry_builds_registered_emissions_and_names_broken_ones():
    reg = emissions.registry
    reg.register("test_gaussian", emissions.gaussian)
    try:
        assert "test_gaussian" in emissions.names()
        em = emissions.get("test_gaussian", shared_sd=False)
        assert em.param_names(2)[-1] == "sd_1"
        with pytest.raises(ValueError, match="takes shared_sd, mean_prior, sd_prior"):
            emissions.get("test_gaussian", colour="red")
    finally:
        reg.unregister("test_gaussian")
    with pytest.raises(ValueError, match="unknown emission 'nope'"):
        emissions.get("nope")
    with pytest.raises(TypeError, match="without defaults"):
        reg.register("needs_args", lambda scale: emissions.gaussian())
    with pytest.raises(TypeError, match=r"not an mrfpe\.models\.emissions\.Emission subclass"):
        reg.register("a_class", dict)
