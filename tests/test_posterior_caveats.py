"""What a posterior says it cannot say: a pseudo-posterior, a parameter cut by the box."""

import warnings

import numpy as np
import pytest

import mrfpe
from mrfpe import models
from mrfpe.posterior import caveats
from mrfpe.testing import CorrelatedGaussian


def _sample(sampler, target, **config):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        return mrfpe.sample(sampler, target, seed=0, **config)


@pytest.fixture(scope="module")
def ising():
    m = models.ising()
    return m, m.simulate([0.3, 0.0], shape=(6, 6), seed=0)


def test_a_pseudolikelihood_posterior_says_it_is_a_pseudo_posterior(ising):
    m, x = ising
    post = _sample("pmc", m.target("pl", x))
    assert post.attrs["target_calibrated"] == 0
    assert post.attrs["diag_caveats"].startswith("pseudo-posterior")
    assert "caveat: pseudo-posterior" in mrfpe.posterior.summary(post)
    exact = _sample("pmc", m.target("exact", x))
    assert exact.attrs["target_calibrated"] == 1 and exact.attrs["diag_caveats"] == ""


def test_data_in_one_state_give_a_posterior_cut_by_the_box(ising):
    m, _ = ising
    ones = np.ones((6, 6), dtype=np.int64)  # the coupling's MLE is at infinity
    for post in (_sample("pmc", m.target("exact", ones)),
                 _sample("exchange", m.target("likelihood", ones), n_steps=1500,
                         burn_in=300)):
        lines = caveats(post)
        assert any(c.startswith("cut by the box: coupling's posterior density at its upper "
                                "bound") for c in lines), lines
        assert post.attrs["diag_caveats"] == "\n".join(lines)


def test_a_posterior_inside_its_box_and_an_undeclared_target_have_no_caveat(ising):
    m, x = ising
    post = _sample("pmc", m.target("exact", x))
    assert caveats(post) == []
    gauss = _sample("pmc", CorrelatedGaussian())
    assert gauss.attrs["target_calibrated"] == -1 and caveats(gauss) == []


def test_a_file_written_before_caveats_reads_back_without_them(ising, tmp_path):
    m, x = ising
    post = _sample("pmc", m.target("pl", x))
    for key in ("target_calibrated", "diag_caveats"):
        del post.attrs[key]
    mrfpe.posterior.save(post, tmp_path / "old.nc")
    back = mrfpe.posterior.load(tmp_path / "old.nc")
    assert caveats(back) == []  # undeclared: nothing claimed
    assert "caveat" not in mrfpe.posterior.summary(back)
