"""Every built-in emission passes the conformance checks shipped for emission plugins."""

import numpy as np
import pytest

from mrfpe.models import emissions
from mrfpe.testing import EMISSION_CHECKS, check_emission

CASES = {
    "gaussian": (lambda: emissions.gaussian(mean_prior=(0.5, 1.0), sd_prior=(3.0, 0.5)), 2,
                 [0.0, 1.0, 0.5]),
    "gaussian_default_priors": (emissions.gaussian, 2, None),
    "gaussian_per_state_sd": (lambda: emissions.gaussian(shared_sd=False, mean_prior=(1.0, 1.0),
                                                         sd_prior=(3.0, 0.5)), 3,
                              [0.0, 1.0, 2.0, 0.5, 0.3, 0.4]),
    "poisson": (lambda: emissions.poisson(rate_prior=(2.0, 0.5)), 2, [1.0, 4.0]),
    "poisson_default_priors": (emissions.poisson, 3, None),
    "categorical": (emissions.categorical, 2, [0.8, 0.2, 0.3, 0.7]),
    "categorical_3_categories": (lambda: emissions.categorical(n_categories=3), 2,
                                 [0.7, 0.2, 0.1, 0.2, 0.2, 0.6]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_builtin_emissions_pass_every_check(case):
    make, q, params = CASES[case]
    assert check_emission(make(), q=q, params=params) == dict.fromkeys(EMISSION_CHECKS, "passed")


def _laplace_emission():
    def log_density(y, phi):  # Laplace(loc_a, scale) per state a
        loc, scale = phi[:, None, :2], phi[:, None, 2:3]
        return -np.abs(y[None, :, None] - loc) / scale - np.log(2 * scale)

    def simulate(x, phi, rng):
        return phi[x] + rng.laplace(scale=phi[2], size=x.size)

    return emissions.general(log_density, [("loc_0", (-3, 3)), ("loc_1", (-3, 3)),
                                           ("scale", (0.05, 5))], simulate=simulate)


def test_a_general_emission_passes_every_check():
    assert check_emission(_laplace_emission(), q=2, params=[0.0, 1.0, 0.4])["update"] == "passed"


def test_the_update_check_catches_an_update_that_ignores_the_prior(monkeypatch):
    from mrfpe.models.emissions.poisson import BoundPoisson

    original = BoundPoisson.update

    def wrong(self, params, x, rng, free):  # the prior's rate counted twice
        self.b0 *= 2
        try:
            return original(self, params, x, rng, free)
        finally:
            self.b0 /= 2

    monkeypatch.setattr(BoundPoisson, "update", wrong)
    with pytest.raises(AssertionError, match="update"):
        check_emission(emissions.poisson(rate_prior=(2.0, 0.5)), q=2, params=[1.0, 4.0])


def test_the_checks_refuse_something_that_is_not_an_emission():
    with pytest.raises(AssertionError, match=r"not an mrfpe\.models\.emissions\.Emission"):
        check_emission(object())
