"""The label kernels with the data term against exact answers (transfer matrix, closed forms)."""

import numpy as np
import pytest

from mrfpe import models
from mrfpe.models.hidden.field import LabelField
from tests.models.hidden.transfer import forward_backward, gaussian_loglik

H, W = 3, 6


def _setup(q, neighbourhood, theta, seed=0):
    m = models.potts(q, neighbourhood)
    design, _, _ = m.compile((H, W))
    field = LabelField(design)
    rng = np.random.default_rng(seed)
    y = rng.normal(size=H * W)
    L = gaussian_loglik(y, np.linspace(-1, 1, q), 0.8)
    L[4] = 0.0  # a missing observation: no data term
    tables = field.tables(design.psi(np.asarray(theta, float)[None])[0], swendsen_wang=True)
    _, marg = forward_backward(H, W, q, theta[0], [0.0, *theta[1:]], L,
                                diagonal=neighbourhood == 8)
    return field, tables, L, marg, rng


@pytest.mark.parametrize(("q", "nb", "theta"), [(2, 4, [0.9, 0.2]), (3, 8, [0.7, 0.3, -0.2])])
def test_gibbs_probabilities_equal_the_exact_marginals(q, nb, theta):
    field, tables, L, marg, rng = _setup(q, nb, theta)
    x = np.zeros(H * W, np.int64)
    acc = np.zeros((H * W, q))
    n = 6000
    for _ in range(200):
        field.gibbs(x, tables, L, rng.random(H * W))
    for _ in range(n):
        field.gibbs(x, tables, L, rng.random(H * W), acc)
    # Rao-Blackwellised estimates: errors ~ 0.5 / sqrt(n / tau); 0.01 is > 4 of them here
    assert np.abs(acc / n - marg).max() < 0.01


def test_swendsen_wang_with_an_external_field_samples_the_exact_marginals():
    field, tables, L, marg, rng = _setup(3, 8, [0.7, 0.3, -0.2], seed=1)
    x = np.zeros(H * W, np.int64)
    counts = np.zeros((H * W, 3))
    n = 8000
    for _ in range(100):
        field.swendsen_wang(x, tables, L, rng)
    for _ in range(n):
        field.swendsen_wang(x, tables, L, rng)  # alone: no Gibbs sweep in between
        counts[np.arange(H * W), x] += 1
    assert np.abs(counts / n - marg).max() < 0.025


def test_swendsen_wang_refuses_tables_of_another_form():
    m = models.potts(2)
    design, _, _ = m.compile((H, W))
    field = LabelField(design)
    tables = field.tables(design.psi(np.array([[-0.5, 0.0]]))[0], swendsen_wang=True)
    assert tables.sw_field is None
    with pytest.raises(ValueError, match="antiferromagnetic"):
        field.swendsen_wang(np.zeros(H * W, np.int64), tables, np.zeros((H * W, 2)),
                            np.random.default_rng(0))


def test_gibbs_draws_depend_only_on_the_uniforms():
    field, tables, L, _, _ = _setup(3, 8, [0.7, 0.3, -0.2])
    u = np.random.default_rng(5).random((20, H * W))
    runs = []
    for _ in range(2):
        x = np.zeros(H * W, np.int64)
        for s in range(20):
            field.gibbs(x, tables, L, u[s])
        runs.append(x.copy())
    np.testing.assert_array_equal(*runs)


def test_icm_ends_at_a_labelling_where_every_label_is_its_conditional_mode():
    field, tables, L, _, _ = _setup(3, 4, [1.2, 0.0, 0.0])
    x = np.zeros(H * W, np.int64)
    for _ in range(50):
        if field.icm(x, tables, L) == 0:
            break
    cond = field.conditionals(x, tables, L)
    assert np.all(cond[np.arange(H * W), x] >= cond.max(axis=1) - 1e-12)


def test_mean_field_without_coupling_is_each_node_posterior():
    q = 3
    field, _, L, _, _ = _setup(q, 4, [0.0, 0.0, 0.0])
    m = models.potts(q)
    design, _, _ = m.compile((H, W))
    tables = field.tables(design.psi(np.array([[0.0, 0.4, -0.1]]))[0])
    P = np.full((H * W, q), 1 / q)
    field.mean_field(P, tables, L)
    w = L + np.array([0.0, 0.4, -0.1])
    expected = np.exp(w - w.max(axis=1, keepdims=True))
    np.testing.assert_allclose(P, expected / expected.sum(axis=1, keepdims=True), atol=1e-12)


def test_a_forbidden_state_is_never_drawn():
    field, tables, L, _, rng = _setup(3, 4, [0.5, 0.0, 0.0])
    L = L.copy()
    L[:, 2] = -np.inf  # no observation can come from state 2
    x = np.zeros(H * W, np.int64)
    acc = np.zeros((H * W, 3))
    for _ in range(50):
        field.gibbs(x, tables, L, rng.random(H * W), acc)
    assert not np.any(x == 2) and np.all(acc[:, 2] == 0)
