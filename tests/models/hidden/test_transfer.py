"""The exact reference of the hidden-field tests against brute-force enumeration."""

import numpy as np
import pytest

from tests.models.hidden.transfer import brute_force, forward_backward, log_marginal_likelihood


@pytest.mark.parametrize(("H", "W", "q", "diagonal"), [(2, 3, 2, False), (3, 3, 2, True),
                                                        (2, 3, 3, False), (1, 5, 3, False)])
def test_transfer_matrix_equals_enumeration(H, W, q, diagonal):
    rng = np.random.default_rng(H * 10 + W + q)
    L = rng.normal(size=(H * W, q))
    field = np.concatenate([[0.0], rng.normal(size=q - 1)])
    lz, marg = forward_backward(H, W, q, 0.7, field, L, diagonal)
    lz_b, marg_b = brute_force(H, W, q, 0.7, field, L, diagonal)
    assert lz == pytest.approx(lz_b, abs=1e-10)
    np.testing.assert_allclose(marg, marg_b, atol=1e-12)
    np.testing.assert_allclose(marg.sum(axis=1), 1.0)


def test_marginal_likelihood_is_a_density_of_y_for_discrete_emissions():
    # binary observations y_i in {0, 1}: summing p(y | theta) over all 2^n y gives 1
    H, W, q = 2, 2, 2
    total = []
    flip = np.log(np.array([[0.8, 0.2], [0.3, 0.7]]))  # p(y = c | x = a)
    for ys in np.ndindex(*(2,) * (H * W)):
        L = flip[:, list(ys)].T  # (n, q): log p(y_i | a)
        total.append(log_marginal_likelihood(H, W, q, 0.5, [0.0, 0.2], L))
    assert np.exp(total).sum() == pytest.approx(1.0)


def test_the_batched_recursion_equals_the_single_one():
    from tests.models.hidden.transfer import forward_backward_batch

    rng = np.random.default_rng(7)
    L = rng.normal(size=(3, 6, 3))
    lz, marg = forward_backward_batch(2, 3, 3, 0.4, [0.0, 0.1, -0.3], L, diagonal=True)
    for k in range(3):
        one = forward_backward(2, 3, 3, 0.4, [0.0, 0.1, -0.3], L[k], diagonal=True)
        assert lz[k] == pytest.approx(one[0])
        np.testing.assert_allclose(marg[k], one[1], atol=1e-12)
