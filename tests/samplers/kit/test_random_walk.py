"""The kit's random-walk pieces: proposals in the box, evaluation inside it only, the rule."""

import numpy as np
import pytest

from mrfpe.samplers.kit import (
    AdaptiveRandomWalk,
    Run,
    evaluate_inside,
    in_box,
    metropolis_accept,
    random_walk_proposal,
)
from mrfpe.testing import CorrelatedGaussian

BOUNDS = np.array([[0.0, 1.0], [-1.0, 2.0]])


class Counting(CorrelatedGaussian):
    """The conformance Gaussian that records every row it is asked for."""

    param_names = ("a", "b")
    bounds = BOUNDS

    def __init__(self):
        self.seen = []

    def log_prob(self, theta):
        theta = np.atleast_2d(theta)
        self.seen.append(theta.copy())
        return -0.5 * np.sum((theta - 0.5) ** 2, axis=1)


def test_in_box_includes_the_faces():
    y = np.array([[0.0, -1.0], [1.0, 2.0], [0.5, 0.5], [1.0 + 1e-12, 0.0], [0.5, -1.5]])
    assert in_box(y, BOUNDS).tolist() == [True, True, True, False, False]


def test_proposal_is_theta_plus_scaled_cholesky_noise():
    x = np.full((500, 2), 0.5)
    chol = np.array([[0.1, 0.0], [0.05, 0.2]])
    y, inside = random_walk_proposal(x, chol, BOUNDS, np.random.default_rng(3), scale=0.5)
    z = np.random.default_rng(3).standard_normal(x.shape)
    np.testing.assert_array_equal(y, x + 0.5 * z @ chol.T)
    np.testing.assert_array_equal(inside, in_box(y, BOUNDS))


def test_per_parameter_sds_are_a_diagonal_factor():
    x = np.random.default_rng(0).random((200, 2))
    sd = np.array([0.3, 0.7])
    y1, in1 = random_walk_proposal(x, sd, BOUNDS, np.random.default_rng(5))
    y2, in2 = random_walk_proposal(x, np.diag(sd), BOUNDS, np.random.default_rng(5))
    np.testing.assert_allclose(y1, y2, rtol=0, atol=1e-15)
    assert in1.tolist() == in2.tolist() and 0 < in1.sum() < in1.size  # some outside


def test_proposals_outside_the_box_are_rejected_without_evaluation():
    target = Counting()
    run = Run(target, 1)
    x = np.full((400, 2), 0.95)  # near the face a = 1: about half the proposals leave
    y, inside = random_walk_proposal(x, np.array([0.1, 0.1]), BOUNDS, np.random.default_rng(1))
    assert 0 < inside.sum() < inside.size
    lp = evaluate_inside(run, target, y, inside)
    assert np.all(np.isneginf(lp[~inside]))
    np.testing.assert_array_equal(lp[inside], target.log_prob(y[inside]))
    assert len(target.seen) == 2 and target.seen[0].shape[0] == inside.sum()
    assert in_box(target.seen[0], BOUNDS).all()
    assert run.n_evals == inside.sum()  # counted: only the rows evaluated


def test_nothing_inside_evaluates_nothing():
    target = Counting()
    run = Run(target, 1)
    y = np.array([[2.0, 0.0], [-1.0, 0.0]])
    lp = evaluate_inside(run, target, y, in_box(y, BOUNDS))
    assert np.all(np.isneginf(lp)) and target.seen == [] and run.n_evals == 0


def test_adaptive_walk_proposes_through_the_primitive():
    walk = AdaptiveRandomWalk(BOUNDS, 4, 0.05, burn_in=10)
    x = np.full((4, 2), 0.5)
    y, inside = walk.propose(x, np.random.default_rng(2))
    y2, inside2 = random_walk_proposal(x, walk.chol, BOUNDS, np.random.default_rng(2),
                                       walk.scale)
    np.testing.assert_array_equal(y, y2)
    assert inside.tolist() == inside2.tolist()


@pytest.mark.parametrize(("lp", "lpy", "log_u", "expected"), [
    (0.0, -1.0, np.log(0.3), True),      # ratio e^-1 = 0.37 > 0.3
    (0.0, -1.0, np.log(0.4), False),
    (-np.inf, -5.0, 0.0, True),          # a stuck chain accepts anything
    (0.0, -np.inf, -50.0, False),        # zero density is never accepted from the support
])
def test_metropolis_rule(lp, lpy, log_u, expected):
    assert metropolis_accept(np.array([log_u]), np.array([lp]), np.array([lpy]))[0] == expected
