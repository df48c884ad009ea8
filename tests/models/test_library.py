"""Ready-made models: today's Potts target, the Ising spin convention, the autologistic CRF."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import models
from mrfpe.targets import get

RNG = np.random.default_rng(7)


def _potts_pl_by_rows(x, q, theta):
    """The 4-neighbour Potts PL written from its definition with numpy (an independent route)."""
    x = x[None] if x.ndim == 2 else x
    onehot = (x[..., None] == np.arange(q)).astype(float)
    n = np.zeros_like(onehot)
    n[:, 1:] += onehot[:, :-1]
    n[:, :-1] += onehot[:, 1:]
    n[:, :, 1:] += onehot[:, :, :-1]
    n[:, :, :-1] += onehot[:, :, 1:]
    out = []
    for th in theta:
        e = th[0] * n + np.r_[0.0, th[1:]]
        own = np.take_along_axis(e, x[..., None], axis=-1)[..., 0]
        out.append((own - np.log(np.exp(e).sum(-1))).sum())
    return np.array(out)


@pytest.mark.parametrize("q", [2, 3, 5])
def test_potts_pl_equals_the_definition_and_the_short_form(q):
    x = RNG.integers(0, q, (2, 17, 23))
    theta = RNG.uniform(-1, 1, (11, q))
    want = _potts_pl_by_rows(x, q, theta)
    got = models.potts(q, 4).target("pl", x).log_prob(theta)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    np.testing.assert_array_equal(get("potts", x, n_states=q).log_prob(theta), got)


def test_ising_is_potts_with_halved_parameters():
    x = RNG.integers(0, 2, (12, 12))
    th = RNG.uniform(-0.8, 0.8, (6, 2))
    # J/2 sum s s + h/2 sum s = J sum [x=x'] + h sum [x=1] + const, so conditionals agree
    ising = models.ising().target("pl", x).log_prob(th / 2)
    potts = models.potts(2).target("pl", x).log_prob(th)
    np.testing.assert_allclose(ising, potts, rtol=1e-12)


def test_autologistic_conditional_is_logistic():
    z = RNG.normal(size=(6, 7))
    x = RNG.integers(0, 2, (6, 7))
    m = models.autologistic(["z"])
    assert m.param_names() == ("coupling", "field", "z")
    th = np.array([0.4, -0.3, 0.9])
    nb = np.zeros((6, 7))
    nb[1:] += x[:-1]
    nb[:-1] += x[1:]
    nb[:, 1:] += x[:, :-1]
    nb[:, :-1] += x[:, 1:]
    eta = th[1] + th[2] * z + th[0] * nb
    want = (x * eta - np.log1p(np.exp(eta))).sum()
    got = m.target("pl", x, covariates={"z": z}).log_prob(th)[0]
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_directional_names_and_registry():
    assert models.potts(3, 8, directional=True).param_names() == (
        "coupling_horizontal", "coupling_vertical", "coupling_diagonal", "coupling_antidiagonal",
        "field_1", "field_2")
    assert {"potts", "ising", "autologistic", "brdf"} <= set(models.names())
    assert models.get("potts", n_states=3).n_states == 3
    with pytest.raises(ValueError, match="unknown model"):
        models.get("pots")
    with pytest.raises(ValueError, match="takes"):
        models.get("potts", colours=3)
