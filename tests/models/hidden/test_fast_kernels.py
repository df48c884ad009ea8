"""The fast label kernels against the exact ones they replace, on random states.

* The product-form Gibbs sweep (exponentiated tables and data factors, a log-space path
  where the products fail) against a sweep written from :func:`kernels.conditionals`
  (every ``-inf`` counted apart), colour class by colour class: the same conditional
  probabilities and the same draws, with ``-inf`` data, forbidden states and pairs,
  and data whose products underflow;
* the parallel kernel against the serial one;
* the labels' conditional rows counted by integer keys against
  :meth:`Design.conditional_rows`: the same log pseudolikelihood.
"""

import numpy as np
import pytest

from mrfpe import models
from mrfpe.models.design import softmax_rows_log_prob
from mrfpe.models.hidden import kernels
from mrfpe.models.hidden.field import LabelField


def _field(q, neighbourhood=4, directional=False, shape=(7, 9)):
    design, _, _ = models.potts(q, neighbourhood, directional=directional).compile(shape)
    return design, LabelField(design)


def _reference_sweep(field, x, tables, L, u):
    """A chequerboard sweep from the exact conditionals: per colour class, every node's
    conditional at the current labels, then its draw by inverse CDF at ``u``."""
    x, acc = x.copy(), np.zeros(L.shape)
    for c in range(field.cptr.size - 1):
        nodes = field.order[field.cptr[c]:field.cptr[c + 1]].astype(np.int64)
        P = field.conditionals(x, tables, L)[nodes]
        acc[nodes] = P
        cum = np.cumsum(P, axis=1)
        pick = (u[nodes, None] >= cum).sum(axis=1)
        last = P.shape[1] - 1 - np.argmax(P[:, ::-1] > 0, axis=1)  # u rounded past them all
        x[nodes] = np.where(pick < P.shape[1], pick, last)
    return x, acc


CASES = [  # q, neighbourhood, directional, psi (coupling(s), fields)
    (2, 4, False, [0.9, 0.3]),
    (2, 8, True, [0.4, -0.7, 0.2, 0.5, 0.1]),
    (3, 4, False, [0.7, 0.3, -0.2]),
    (5, 8, False, [1.1, 0.2, -0.4, 0.3, 0.0]),
    (3, 4, False, [-np.inf, 0.0, 0.0]),  # no two neighbours alike: many dead ends
    (4, 4, False, [0.5, 0.1, -np.inf, 0.2]),  # state 2 forbidden everywhere
]


@pytest.mark.parametrize(("q", "nb", "directional", "psi"), CASES)
def test_the_gibbs_sweep_draws_from_the_exact_conditionals(q, nb, directional, psi):
    _, field = _field(q, nb, directional)
    tables = field.tables(np.asarray(psi, float))
    rng = np.random.default_rng(q * nb)
    n = field.n
    for trial in range(6):
        L = rng.normal(scale=2.0, size=(n, q))
        L[rng.random((n, q)) < 0.15] = -np.inf  # impossible observations
        L[rng.random(n) < 0.05] = -np.inf  # every state impossible
        L[rng.random(n) < 0.1] -= 900.0  # outliers: the products underflow
        if trial == 0:
            L[:] = 0.0  # no data at all
        x0 = rng.integers(0, q, n)
        u = rng.random(n)
        want_x, want_acc = _reference_sweep(field, x0, tables, L, u)
        x, acc = x0.copy(), np.zeros((n, q))
        field.gibbs(x, tables, L, u, acc)
        np.testing.assert_allclose(acc, want_acc, rtol=1e-12, atol=1e-14)
        np.testing.assert_array_equal(x, want_x)


@pytest.mark.parametrize("q", [2, 4])
def test_the_parallel_and_serial_kernels_draw_the_same(q):
    _, field = _field(q, 4, shape=(80, 90))  # more nodes than a parallel chunk
    tables = field.tables(np.array([0.8, *np.linspace(-0.3, 0.3, q - 1)]))
    rng = np.random.default_rng(q)
    L = rng.normal(size=(field.n, q))
    x0 = rng.integers(0, q, field.n)
    out = []
    for sweep in (kernels.gibbs_sweep, kernels.gibbs_sweep_serial):
        x, acc = x0.copy(), np.zeros((field.n, q))
        rng = np.random.default_rng(7)
        for _ in range(3):
            sweep(x, field.order, field.cptr, tables.node, tables.pair, tables.enode,
                  tables.epair, field.indptr, field.nbr, field.ntab, L,
                  kernels.data_factors(L), rng.random(field.n), acc, True)
        out.append((x, acc))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


def _hard_core(q):
    """A general potential forbidding equal neighbours once its parameter is positive."""
    def pair(th):
        eq = np.eye(q)[None] > 0
        return np.where(eq & (th[:, :1, None] > 0), -np.inf, th[:, :1, None] * eq)

    return models.MRF(models.lattice(4), q,
                      potential=models.Potential([("c", (-1.0, 1.0))], pair=pair))


@pytest.mark.parametrize("model", [models.potts(2), models.potts(6),
                                   models.potts(3, 8, directional=True),
                                   models.autologistic("z"), _hard_core(3)],
                         ids=["potts2", "potts6", "potts3-directional", "covariates",
                              "forbidding"])
def test_conditional_rows_by_keys_give_the_designs_pseudolikelihood(model):
    rng = np.random.default_rng(0)
    shape = (6, 7)
    cov = {"z": rng.normal(size=shape)} if model.name == "autologistic" else None
    design, names, bounds = model.compile(shape, cov)
    field = LabelField(design)
    for _ in range(5):
        x = rng.integers(0, design.q, shape[0] * shape[1])
        theta = rng.uniform(bounds[:, 0], bounds[:, 1], size=(4, len(names)))
        if model.potential is not None:
            theta[0, 0] = 0.5  # forbidding: -inf wherever two neighbours are alike
        psi = design.psi(theta)
        got = softmax_rows_log_prob([field.conditional_rows(x)], psi)
        want = softmax_rows_log_prob([design.conditional_rows(x[None])], psi)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
