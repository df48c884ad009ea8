"""``log_evidence`` of the importance samplers against closed forms and against dynesty.

Convention (mrfpe.samplers.kit.evidence): ``log(∫_box p / vol(box))``, which is also
dynesty's ``logz`` with the uniform prior on the box.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import stats
from scipy.special import ndtr

import mrfpe
from mrfpe.samplers import kit
from mrfpe.targets.base import Target
from mrfpe.testing import CorrelatedGaussian


class DiagonalGaussian(Target):
    """An unnormalised N(mean, diag(sd²)) · e^offset on a box, cut by the faces."""

    def __init__(self, mean, sd, bounds, offset: float = 0.0):
        self.mean, self.sd = np.asarray(mean, float), np.asarray(sd, float)
        self.bounds = np.asarray(bounds, float)
        self.param_names = tuple(f"p{i}" for i in range(self.mean.size))
        self.offset = offset

    def _log_prob(self, theta: np.ndarray) -> np.ndarray:
        return self.offset + stats.norm.logpdf(theta, self.mean, self.sd).sum(axis=1)

    def log_evidence(self) -> float:
        """Closed form: offset + Σ log(Φ(hi) − Φ(lo)) − log vol(box)."""
        lo = (self.bounds[:, 0] - self.mean) / self.sd
        hi = (self.bounds[:, 1] - self.mean) / self.sd
        return (self.offset + float(np.sum(np.log(ndtr(hi) - ndtr(lo))))
                - kit.log_box_volume(self.bounds))


def correlated_log_evidence(t: CorrelatedGaussian) -> float:
    """exp(log_prob) is c · N(θ; mean, cov) with its mass in the cube 1 to 1e-6."""
    c = t.log_prob(t.mean[None])[0] - stats.multivariate_normal(t.mean, t.cov).logpdf(t.mean)
    return float(c)


#: One cut by two faces of a box that is not the unit cube (the box mass M < 1 and
#: vol ≠ 1 both matter), one well inside.
CUT = DiagonalGaussian([0.05, 0.5, 1.7], [0.06, 0.05, 0.2], [[0, 1], [0, 1], [0, 2]],
                       offset=-3.0)


def _sample(name, target, seed=0, **cfg):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        return mrfpe.sample(name, target, seed=seed, **cfg)


#: A correlated Gaussian well inside the cube (the 3-D one of benchmarks/bench_accuracy.py),
#: scaled by e^-40 so the normaliser is not trivially 0.
class Correlated3D(Target):
    param_names = ("a", "b", "c")
    bounds = np.array([[0.0, 1.0]] * 3)
    sd = np.array([0.05, 0.065, 0.08])
    corr = np.array([[1.0, -0.5, 0.3], [-0.5, 1.0, 0.4], [0.3, 0.4, 1.0]])
    mvn = stats.multivariate_normal([0.42, 0.57, 0.5], corr * np.outer(sd, sd))

    def _log_prob(self, theta):
        return np.atleast_1d(self.mvn.logpdf(theta)) - 40.0


@pytest.mark.parametrize("seed", [0, 1])
def test_pmc_log_evidence_matches_the_closed_form_to_0_05(seed):
    post = _sample("pmc", Correlated3D(), seed)
    assert abs(post.attrs["log_evidence"] - (-40.0)) < 0.05  # mass in the cube: 1 - 1e-9
    assert 0 < post.attrs["log_evidence_se"] < 0.05


def test_pmc_log_evidence_on_the_partitioned_conformance_target():
    # sub-lattice importance functions leave the final weights wider (ESS ~100 of 1000),
    # so the SE is ~0.1 there: the estimate is within a few of them
    t = CorrelatedGaussian()
    post = _sample("pmc", t)
    se = post.attrs["log_evidence_se"]
    assert abs(post.attrs["log_evidence"] - correlated_log_evidence(t)) < 3 * se


@pytest.mark.parametrize("name", ["pmc", "sir", "ppf"])
def test_evidence_of_a_gaussian_cut_by_the_box(name):
    post = _sample(name, CUT)
    assert abs(post.attrs["log_evidence"] - CUT.log_evidence()) < 0.05
    assert post.attrs["log_evidence_se"] < 0.05


def test_pmc_diagonal_kernel_and_single_iteration_evidence():
    t = DiagonalGaussian([0.4, 0.6], [0.08, 0.1], [[0, 1], [0, 1]])
    truth = t.log_evidence()
    exact = _sample("pmc", t, kernel="adaptive", n_iterations=8)  # truncated kernels: M = 1
    assert abs(exact.attrs["log_evidence"] - truth) < 4 * exact.attrs["log_evidence_se"] + 0.02
    start = _sample("pmc", t, n_iterations=1)  # ϱ on the uniform Halton start
    assert abs(start.attrs["log_evidence"] - truth) < 4 * start.attrs["log_evidence_se"] + 0.02


def test_smc_log_evidence_and_its_standard_error():
    t = CorrelatedGaussian()
    post = _sample("smc", t)
    se = post.attrs["log_evidence_se"]
    assert 0 < se < 0.2
    assert abs(post.attrs["log_evidence"] - correlated_log_evidence(t)) < 4 * se


def test_smc_log_evidence_counts_the_support_share_of_the_box():
    class Half(DiagonalGaussian):  # zero density on x > 0.5: the support is half the box
        def _log_prob(self, theta):
            lp = super()._log_prob(theta)
            return np.where(theta[:, 0] > 0.5, -np.inf, lp)

        def log_evidence(self):
            lo, hi = (np.array([0.0, 0.0]) - self.mean) / self.sd, (0.5 - self.mean) / self.sd
            hi = np.array([hi[0], (1.0 - self.mean[1]) / self.sd[1]])
            return float(np.sum(np.log(ndtr(hi) - ndtr(lo))))

    t = Half([0.45, 0.5], [0.1, 0.1], [[0, 1], [0, 1]])
    post = _sample("smc", t)
    assert abs(post.attrs["log_evidence"] - t.log_evidence()) < 4 * post.attrs["log_evidence_se"]


@pytest.mark.parametrize("name, cfg", [("pmc", {"variant": "thesis2", "n_iterations": 3}),
                                       ("pmc", {"variant": "thesis1", "n_iterations": 3}),
                                       ("sir", {"weights": "thesis", "n_iterations": 3}),
                                       ("ppf", {"weights": "thesis", "n_partitions": 3}),
                                       ("mh", {"n_steps": 200, "burn_in": 50})])
def test_no_evidence_where_none_is_defined(name, cfg):
    post = _sample(name, CorrelatedGaussian(), **cfg)
    assert "log_evidence" not in post.attrs and "log_evidence_se" not in post.attrs


def test_mixture_box_mass_estimate():
    rng = np.random.default_rng(0)
    centres = np.array([[0.0, 0.5], [0.5, 0.5]])
    chol = np.diag([0.1, 0.1])
    lm, se = kit.log_mixture_box_mass(centres, np.log([0.5, 0.5]), chol,
                                      np.array([[0.0, 1.0], [0.0, 1.0]]), rng)
    inner = ndtr(5) - ndtr(-5)
    truth = 0.5 * (0.5 * inner) * inner + 0.5 * inner**2  # first centre sits on a face
    assert abs(math.exp(lm) - truth) < 4 * se * truth


def test_pmc_log_evidence_agrees_with_dynesty():
    dynesty = pytest.importorskip("dynesty")
    t = CUT
    lo, hi = t.bounds[:, 0], t.bounds[:, 1]

    def loglike(u):  # dynesty passes one point at a time
        return float(t.log_prob(np.asarray(u)[None])[0])

    ns = dynesty.NestedSampler(loglike, lambda u: lo + (hi - lo) * u, 3, nlive=200,
                               rstate=np.random.default_rng(0))
    ns.run_nested(dlogz=0.05, print_progress=False)
    res = ns.results
    z_dyn, se_dyn = float(res.logz[-1]), float(res.logzerr[-1])
    post = _sample("pmc", t)
    se = math.hypot(se_dyn, post.attrs["log_evidence_se"])
    assert abs(post.attrs["log_evidence"] - z_dyn) < 4 * se + 0.02
    assert abs(z_dyn - t.log_evidence()) < 4 * se_dyn + 0.02  # the two routes share a convention
