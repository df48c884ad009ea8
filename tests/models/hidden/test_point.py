"""ICM and mean-field EM: point estimates as kind="optima" posteriors."""

import numpy as np
import pytest

from mrfpe import models
from mrfpe import posterior as P
from mrfpe.models import emissions
from mrfpe.models.hidden import icm, mean_field_em

TRUTH = [0.8, 0.0, 0.0, -1.0, 0.0, 1.0, 0.5]


@pytest.fixture(scope="module")
def image():
    hm = models.hidden(models.potts(3), emissions.gaussian())
    x, y = hm.simulate(TRUTH, shape=(32, 32), seed=2)
    return hm, x, y


@pytest.mark.parametrize(("estimator", "tol", "agree"), [(mean_field_em, 0.06, 0.8),
                                                         (icm, 0.12, 0.8)])
def test_point_estimates_recover_the_truth(image, estimator, tol, agree):
    hm, x, y = image
    post = estimator(hm.target("hidden", y, fixed={"field_1": 0.0, "field_2": 0.0}))
    P.validate(post)
    assert post.attrs["kind"] == "optima" and post.attrs["converged"] == 1
    theta = post["theta"].values[0]
    np.testing.assert_allclose(theta[1:], TRUTH[3:], atol=tol)
    assert abs(theta[0] - TRUTH[0]) < 0.25
    assert (post["label_mode"].values == x).mean() > agree
    prob = post["label_probability"].values
    assert prob.shape == (32, 32, 3)
    np.testing.assert_allclose(prob.sum(axis=-1), 1.0)
    np.testing.assert_array_equal(post["label_mode"].values, prob.argmax(axis=-1))
    np.testing.assert_allclose(post["label_uncertainty"].values, 1 - prob.max(axis=-1))


def test_fixed_parameters_are_kept_and_left_out_of_theta(image):
    hm, _, y = image
    t = hm.target("hidden", y, fixed={"field_1": 0.0, "field_2": 0.0, "sd": 0.5})
    post = mean_field_em(t)
    assert list(post["param"].values) == ["coupling", "mean_0", "mean_1", "mean_2"]
    assert np.all(np.diff(post["theta"].values[0, 1:]) > 0)


def test_poisson_counts_with_em():
    hm = models.hidden(models.potts(2), emissions.poisson())
    x, y = hm.simulate([0.9, 0.0, 2.0, 8.0], shape=(24, 24), seed=1)
    post = mean_field_em(hm.target("hidden", y))
    np.testing.assert_allclose(post["theta"].values[0, 2:], [2.0, 8.0], rtol=0.15)
    assert (post["label_mode"].values == x).mean() > 0.9


def test_a_masked_node_takes_its_neighbours_label():
    hm = models.hidden(models.potts(2), emissions.gaussian())
    y = np.zeros((10, 10))
    y[:, 5:] = 3.0
    y += np.random.default_rng(0).normal(scale=0.3, size=y.shape)
    mask = np.zeros((10, 10), bool)
    mask[4:6, 1:3] = True  # inside the left region
    y[mask] = 3.0  # what a missing value holds does not matter
    post = mean_field_em(hm.target("hidden", y, mask=mask, fixed={"field": 0.0}))
    assert np.all(post["label_mode"].values[mask] == 0)
    assert np.all(post["label_probability"].values[mask][:, 0] > 0.8)


def test_on_a_general_graph():
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    A = sp.random(40, 40, density=0.1, random_state=3)
    A = ((A + A.T) > 0).astype(float)
    A.setdiag(0)
    hm = models.hidden(models.potts(2, graph=models.from_adjacency(A)), emissions.gaussian())
    y = rng.normal(size=40) + (np.arange(40) >= 20) * 3
    post = icm(hm.target("hidden", y))
    assert post["label_probability"].dims == ("node", "state")
    assert (post["label_mode"].values == (np.arange(40) >= 20)).mean() >= 0.85
