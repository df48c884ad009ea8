"""The hidden sampler against exact answers computed by the transfer matrix (tests/...transfer).

* Label marginals: with the coupling and the sd known and the two means free (normal
  priors, ordered), ``p(x_i | y) = ∫ p(x_i | y, μ) p(μ | y) dμ`` by a grid over the means,
  each point exact by the transfer matrix; the sampler's Rao-Blackwellised label
  probabilities must match within their own Monte Carlo error, and its means' moments
  the grid's.
* The coupling: the exact posterior of β under its flat prior, ``p(β | y) ∝ p(y | β)``,
  on a grid; the ``pl`` pseudo-posterior's mean error (in exact sds) and sd ratio are
  measured and reported (printed with ``-s``), not required to vanish.
"""

import warnings

import numpy as np
import pytest
from scipy.special import logsumexp

import mrfpe
from mrfpe import models
from mrfpe.samplers.hidden import HiddenSampler
from tests.models.hidden.transfer import forward_backward, forward_backward_batch, gaussian_loglik

H, W = 3, 6


def _exact_over_means(y, beta, sd, m0, s0, grid):
    """Posterior label marginals and the means' posterior moments, means on ``grid``²."""
    a, b = np.meshgrid(grid, grid, indexing="ij")
    keep = a < b
    a, b = a[keep], b[keep]
    ya = gaussian_loglik(y.ravel(), grid, sd)  # (n, G)
    idx_a = np.searchsorted(grid, a)
    idx_b = np.searchsorted(grid, b)
    L = np.stack([ya[:, idx_a].T, ya[:, idx_b].T], axis=2)  # (K, n, 2)
    lz, marg = forward_backward_batch(H, W, 2, beta, None, L)
    lz0, _ = forward_backward(H, W, 2, beta, None, None)
    logp = lz - lz0 - 0.5 * ((a - m0) / s0) ** 2 - 0.5 * ((b - m0) / s0) ** 2
    w = np.exp(logp - logsumexp(logp))
    mean = np.array([w @ a, w @ b])
    sd_ = np.sqrt(np.array([w @ a ** 2, w @ b ** 2]) - mean ** 2)
    return np.einsum("k,kiq->iq", w, marg), mean, sd_


def test_label_probabilities_equal_the_exact_marginals_with_the_means_integrated_out():
    beta, sd, m0, s0 = 0.6, 0.5, 0.5, 1.0
    hm = models.hidden(models.potts(2), models.emissions.gaussian(mean_prior=(m0, s0)))
    _, y = hm.simulate([beta, 0.0, 0.0, 1.0, sd], shape=(H, W), seed=3)
    target = hm.target("hidden", y, fixed={"coupling": beta, "field": 0.0, "sd": sd})
    exact, mean, sd_exact = _exact_over_means(y, beta, sd, m0, s0, np.linspace(-3.5, 4.5, 241))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = mrfpe.sample(HiddenSampler, target, seed=0, n_steps=2000, burn_in=300,
                            n_chains=3)
    p = post["label_probability"].values.reshape(-1, 2)
    se = post["label_probability_mcse"].values.reshape(-1, 2)
    z = np.abs(p - exact) / se
    assert z.max() < 4.5, (z.max(), np.abs(p - exact).max())
    assert np.mean(z ** 2) < 2.0  # about 1 if the standard errors are right
    theta = post["theta"].values  # mean_0, mean_1
    ess = post["param_ess"].values
    assert np.all(np.abs(theta.mean(axis=0) - mean) < 4 * sd_exact / np.sqrt(ess) + 0.01)
    assert np.all(np.abs(theta.std(axis=0) / sd_exact - 1) < 4 / np.sqrt(2 * ess) + 0.02)
    assert post.attrs["diag_reliable"] == 1  # nothing drawn from a pseudolikelihood here


CASES = [(0.3, 1), (0.7, 2), (1.1, 3)]


@pytest.mark.slow
@pytest.mark.parametrize(("beta", "seed"), CASES)
def test_coupling_pseudo_posterior_against_the_exact_posterior(beta, seed):
    Hb, Wb, sd = 3, 10, 0.5
    hm = models.hidden(models.potts(2), models.emissions.gaussian())
    _, y = hm.simulate([beta, 0.0, 0.0, 1.0, sd], shape=(Hb, Wb), seed=seed)
    target = hm.target("hidden", y, fixed={"field": 0.0, "mean_0": 0.0, "mean_1": 1.0,
                                           "sd": sd})
    L = gaussian_loglik(y.ravel(), [0.0, 1.0], sd)
    grid = np.linspace(-2.0, 2.0, 801)  # the coupling's flat prior: the MRF's bounds
    lp = np.array([forward_backward(Hb, Wb, 2, b, None, L)[0]
                   - forward_backward(Hb, Wb, 2, b, None, None)[0] for b in grid])
    w = np.exp(lp - logsumexp(lp))
    m = w @ grid
    s = np.sqrt(w @ (grid - m) ** 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = mrfpe.sample(HiddenSampler, target, seed=0, n_steps=3000, burn_in=500)
    draws = post["theta"].values[:, 0]
    err, ratio = (draws.mean() - m) / s, draws.std() / s
    print(f"\nbeta={beta}: exact mean {m:.3f} sd {s:.3f}; pl mean {draws.mean():.3f} sd "
          f"{draws.std():.3f}; error {err:+.2f} exact sd, sd ratio {ratio:.2f}, "
          f"ESS {post['param_ess'].values[0]:.0f}")
    assert "pseudo-posterior" in post.attrs["diag_messages"]
    assert abs(err) < 1.5 and 0.5 < ratio < 2.0  # measured: |error| 0.6-0.9, ratio 1.3-1.4
