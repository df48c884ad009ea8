"""The pre-computed surrogate against the exact moments of the sufficient statistic.

For the Potts model ``log Z(β)`` is exact on a narrow lattice by the transfer matrix
(tests/models/hidden/transfer.py); the mean and variance of the number of equal
neighbour pairs are its first two derivatives (central differences): an independent
route to what the surrogate interpolates from simulations.
"""

import numpy as np
import pytest

from mrfpe import models
from mrfpe.models.hidden import Surrogate, build_surrogate
from mrfpe.models.hidden.surrogate import SURROGATE_TOL, is_log_linear
from mrfpe.models.hidden.surrogate_build import statistic_chain
from tests.models.hidden.transfer import log_z_product

H, W, Q = 4, 12, 3
FIXED = {"field_1": 0.0, "field_2": 0.0, "mean_0": 0.0, "mean_1": 1.0, "mean_2": 2.0,
         "sd": 0.5}


def _target(shape=(H, W), method="surrogate", **options):
    hm = models.hidden(models.potts(Q), models.emissions.gaussian())
    _, y = hm.simulate([0.8, 0, 0, 0.0, 1.0, 2.0, 0.5], shape=shape, seed=0)
    return hm.target("hidden", y, fixed=FIXED, method=method,
                     bounds={"coupling": (-0.5, 2.0)}, **options)


def _exact_moments(beta, h=1e-3):
    f = [log_z_product(H, W, Q, b) for b in (beta - h, beta, beta + h)]
    return (f[2] - f[0]) / (2 * h), (f[2] - 2 * f[1] + f[0]) / h ** 2


@pytest.fixture(scope="module")
def surrogate():
    return build_surrogate(_target(), seed=0, n_sweeps=3000)


def test_the_interpolated_moments_match_the_exact_ones_between_design_points(surrogate):
    betas = np.array([-0.3, 0.15, 0.6, 0.95, 1.05, 1.4, 1.85])  # none on the design
    mu, L = surrogate.moments(betas[:, None])
    for b, m, ell in zip(betas, mu[:, 0], L[:, 0, 0], strict=True):
        mean, var = _exact_moments(b)
        # measured: at most 0.14 sd; a design point with ESS >= 250 carries <= 0.065 sd of noise
        assert abs(m - mean) / np.sqrt(var) < 0.2, (b, m, mean, np.sqrt(var))
        assert abs(ell ** 2 / var - 1) < 0.25, (b, ell ** 2, var)
    assert surrogate.validation_error <= SURROGATE_TOL
    assert surrogate.n_design >= 17 and surrogate.ess.min() > 100


def test_the_synthetic_likelihood_is_a_normal_density(surrogate):
    from scipy.stats import norm

    s, beta = 40.0, np.array([[0.7], [1.1]])
    mu, L = surrogate.moments(beta)
    expected = norm.logpdf(s, mu[:, 0], L[:, 0, 0])
    assert np.allclose(surrogate.log_lik(np.array([s]), beta), expected)


def test_the_same_seed_gives_the_same_surrogate_and_another_seed_another():
    a = build_surrogate(_target(), seed=3, n_sweeps=300, n_design=5, max_design=5)
    b = build_surrogate(_target(), seed=3, n_sweeps=300, n_design=5, max_design=5)
    c = build_surrogate(_target(), seed=4, n_sweeps=300, n_design=5, max_design=5)
    assert np.array_equal(a.means, b.means) and not np.array_equal(a.means, c.means)


def test_a_dask_client_gives_the_numbers_of_a_local_run():
    distributed = pytest.importorskip("distributed")
    local = build_surrogate(_target(), seed=5, n_sweeps=300, n_design=5, max_design=5)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster, timeout=30) as client:
        remote = build_surrogate(_target(), seed=5, n_sweeps=300, n_design=5, max_design=5,
                                 client=client)
    assert np.array_equal(local.points, remote.points)
    assert np.array_equal(local.means, remote.means)
    assert np.array_equal(local.covs, remote.covs)


def test_a_client_that_fails_is_an_error_and_no_surrogate():
    class Gone:
        def map(self, *args, **kwargs):
            raise OSError("Timed out trying to connect to tcp://10.0.0.1:8786")

    with pytest.raises(RuntimeError, match=r"dask client.*OSError.*no surrogate was built"):
        build_surrogate(_target(), seed=0, n_sweeps=50, n_design=3, client=Gone())


def test_a_surrogate_is_checked_against_the_target_it_serves(surrogate):
    assert isinstance(surrogate, Surrogate)
    _target(surrogate=surrogate)  # the one it was built for
    with pytest.raises(ValueError, match="node shape"):
        _target(shape=(H, W + 1), surrogate=surrogate)
    with pytest.raises(ValueError, match="does not cover the prior of coupling"):
        hm = models.hidden(models.potts(Q), models.emissions.gaussian())
        _, y = hm.simulate([0.8, 0, 0, 0.0, 1.0, 2.0, 0.5], shape=(H, W), seed=0)
        hm.target("hidden", y, fixed=FIXED, method="surrogate", surrogate=surrogate)
    with pytest.raises(ValueError, match="method='surrogate' only"):
        _target(method="exchange", surrogate=surrogate)
    with pytest.raises(ValueError, match="surrogate must be"):
        _target(surrogate={"means": [1, 2]})


def test_statistics_chains_and_the_log_linear_check():
    t = _target()
    assert is_log_linear(t.design, t.n_mrf)
    s, last = statistic_chain(t.design, np.array([0.5, 0.0, 0.0]), np.array([0]), 30, seed=0)
    assert last.shape == (t.n_nodes,) and s.shape == (30, 1)
    assert np.all(s >= 0) and np.all(s <= t.design.graph.n_edges)

    def pair(th):  # a coupling through its square: not log-linear
        return (th[:, 0] ** 2)[:, None, None] * np.eye(2)[None]

    general = models.MRF(models.lattice(4), 2,
                         potential=models.Potential([("c", (-1.0, 1.0))], pair=pair))
    assert not is_log_linear(general.compile((3, 3))[0], 1)
    hm = models.hidden(general, models.emissions.gaussian())
    _, y = hm.simulate([0.5, 0.0, 1.0, 0.5], shape=(3, 3), seed=0)
    with pytest.raises(ValueError, match=r"log-linear.*use method='exchange'"):
        build_surrogate(hm.target("hidden", y, method="surrogate"), seed=0)


def test_no_free_mrf_parameter_or_a_feature_map_is_refused_before_any_work():
    t = _target()
    fixed_all = _target().model.target("hidden", t.y.reshape(H, W), method="surrogate",
                                        fixed={**{k: v for k, v in FIXED.items() if k != "sd"},
                                               "coupling": 0.5})
    with pytest.raises(ValueError, match="needs a free MRF parameter"):
        build_surrogate(fixed_all, seed=0)
    with pytest.raises(ValueError, match="n_design"):
        build_surrogate(t, seed=0, n_design=1)


def test_a_design_point_is_simulated_until_it_holds_enough_effective_draws():
    from mrfpe.models.hidden.surrogate_build import moments_at

    t = _target()
    full, free = np.array([1.0, 0.0, 0.0]), np.array([0])
    short = moments_at(t.design, full, free, 50, 0, seed=0, min_ess=1.0)
    capped = moments_at(t.design, full, free, 50, 0, seed=0, min_ess=1e9, max_sweeps=400)
    enough = moments_at(t.design, full, free, 50, 0, seed=0, min_ess=100.0)
    assert short.n_sweeps == 50 and capped.n_sweeps == 400
    assert enough.ess >= 100.0 and 50 < enough.n_sweeps <= 1600


def test_the_error_that_counts_is_the_one_in_the_posterior_range(surrogate):
    import dataclasses

    s = dataclasses.replace(surrogate, checks=np.array([[0.0, 1.0, 0.05], [1.0, 2.0, 0.5]]))
    assert s.validation_error == 0.5
    assert s.error_within([0.2], [0.8]) == 0.05
    assert s.error_within([0.5], [1.5]) == 0.5
    assert s.error_within([2.5], [2.6]) == 0.5  # no check there: every check's


def test_a_surrogate_saves_loads_and_pickles_to_the_same_numbers(surrogate, tmp_path):
    import pickle

    path = tmp_path / "potts3_4x12.npz"
    surrogate.save(path)
    back = Surrogate.load(path)
    beta = np.linspace(-0.4, 1.9, 7)[:, None]
    for other in (back, pickle.loads(pickle.dumps(surrogate))):
        assert other.names == surrogate.names and other.node_shape == surrogate.node_shape
        assert np.array_equal(other.log_lik(np.array([30.0]), beta),
                              surrogate.log_lik(np.array([30.0]), beta))
    _target(surrogate=back)  # still checked against the target it serves
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"junk\.npz: not a surrogate"):
        Surrogate.load(tmp_path / "junk.npz")
