"""The multi-spin kernel behind simulate_batch, and a likelihood target's auxiliary draws.

Many Gibbs chains of a binary lattice model run on the multi-spin coded kernel (Jacobs &
Rebbi 1981): equal in distribution to the scalar kernel (checked against exact
expectations on a 3 x 3 lattice through ``MRF.simulate`` with a ``(B, d)`` theta), not
in the draws; ``kernel="scalar"`` keeps every chain identical to its single-chain call.
"""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe import models
from mrfpe.models.simulate import simulate
from mrfpe.models.simulate_batch import MULTISPIN_MIN_ROWS, chain_seeds, simulate_batch
from tests.models.test_simulate_batch import _check_chain, _exact_moments, _model


def _rows(B: int) -> np.ndarray:
    """``B`` parameter vectors (J, h): ferro- and antiferromagnetic, with and without field."""
    return np.column_stack([np.linspace(-0.6, 1.0, B), np.tile([0.0, 0.4, -0.3, 0.1], B)[:B]])


def test_multispin_rows_match_exact_expectations():
    m, theta = _model(2), _rows(MULTISPIN_MIN_ROWS)
    draws = m.simulate(theta, shape=(3, 3), n=3000, seed=5, method="gibbs", n_sweeps=20,
                       thin=1)
    design, _, _ = m.compile((3, 3))
    for b in range(theta.shape[0]):
        _check_chain(design.statistics(draws[b].reshape(3000, 9)),
                     *_exact_moments(2, (3, 3), theta[b]))
    scalar = m.simulate(theta, shape=(3, 3), n=3000, seed=5, method="gibbs", n_sweeps=20,
                        thin=1, kernel="scalar")
    assert not np.array_equal(draws, scalar)  # the multi-spin kernel ran: other draws


def test_scalar_kernel_keeps_single_chain_identity():
    design, _, _ = _model(2).compile((6, 5))
    psi = design.psi(_rows(MULTISPIN_MIN_ROWS + 2))
    out = simulate_batch(design, psi, 3, seed=8, method="gibbs", n_sweeps=2, thin=2,
                         kernel="scalar")
    for b, s in enumerate(chain_seeds(8, psi.shape[0])):
        np.testing.assert_array_equal(out[b], simulate(design, psi[b], 3, seed=int(s),
                                                       method="gibbs", n_sweeps=2, thin=2))


def test_kernel_choice_and_refusals():
    design, _, _ = _model(2).compile((4, 4))
    psi = design.psi(_rows(MULTISPIN_MIN_ROWS))
    # "auto" keeps Swendsen-Wang where it applies: no Gibbs chain, nothing changes
    ferro = design.psi(np.tile([0.4, 0.1], (MULTISPIN_MIN_ROWS, 1)))
    np.testing.assert_array_equal(simulate_batch(design, ferro, 2, seed=1, n_sweeps=3),
                                  simulate_batch(design, ferro, 2, seed=1, n_sweeps=3,
                                                 kernel="scalar"))
    # few rows: scalar unless asked; asked, the draws start where the scalar route does
    few = simulate_batch(design, psi[:2], 2, seed=1, method="gibbs", n_sweeps=0, thin=1)
    forced = simulate_batch(design, psi[:2], 2, seed=1, method="gibbs", n_sweeps=0, thin=1,
                            kernel="multispin")
    np.testing.assert_array_equal(few[:, 0], forced[:, 0])
    assert forced.dtype == np.int64 and set(np.unique(forced)) <= {0, 1}
    with pytest.raises(ValueError, match="kernel must be one of"):
        simulate_batch(design, psi, kernel="fast")
    d3, _, _ = _model(3).compile((4, 4))
    with pytest.raises(ValueError, match="kernel='multispin' cannot run this design: it has 3"):
        simulate_batch(d3, d3.psi(np.array([[0.3, 0.0, 0.0]])), kernel="multispin")


def test_auxiliary_draws_start_at_the_data_one_chain_per_row_and_observation():
    m = models.ising()
    x = m.simulate(np.array([[0.3, 0.0], [0.2, 0.1]]), shape=(5, 6), seed=0, n_sweeps=20)
    t = m.target("likelihood", x[:, 0])  # two observed configurations
    theta = np.array([[0.3, 0.0], [0.5, -0.1], [0.1, 0.2]])
    np.testing.assert_array_equal(t.simulate_aux(theta, seed=1, n_sweeps=0),
                                  np.broadcast_to(t.x, (3, 2, 30)))
    w = t.simulate_aux(theta, seed=1, n_sweeps=4, kernel="scalar")
    assert w.shape == (3, 2, 30)
    psi, seeds = t.design.psi(theta), chain_seeds(1, 6)
    for b in range(3):
        for k in range(2):
            ref = simulate(t.design, psi[b], 1, seed=int(seeds[2 * b + k]), method=t.sampler,
                           n_sweeps=4, init=t.x[k])
            np.testing.assert_array_equal(w[b, k], ref[0])
    pairs = np.stack([theta, theta[::-1]])
    u = t.unnormalised_rows(pairs, w)
    ref = [[t.unnormalised(pairs[j, b], w[b])[0] for b in range(3)] for j in range(2)]
    np.testing.assert_allclose(u, ref, rtol=1e-12)
