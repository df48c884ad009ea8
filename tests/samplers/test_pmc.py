"""PMC: mixture density, truncated jitter, importance-function cycling, variants, costs."""

import numpy as np
import pytest
from scipy import stats

from mrfpe import posterior as P
from mrfpe.mixture import log_mixture_density
from mrfpe.samplers.kit import grid, jitter, log_kernel_mass
from mrfpe.samplers.pmc import PMC
from mrfpe.samplers.pmc_steps import jitter_scale, soften
from mrfpe.testing import CorrelatedGaussian, TwoModes

QUICK = {"n_samples": 200, "n_iterations": 6, "power": 1.0}


def test_log_mixture_density_matches_scipy_and_chunks():
    rng = np.random.default_rng(0)
    c, x = rng.random((7, 3)), rng.random((50, 3))
    w = rng.dirichlet(np.ones(7))
    ref = np.log(sum(wi * stats.multivariate_normal(ci, 0.05**2 * np.eye(3)).pdf(x)
                     for wi, ci in zip(w, c)))
    got = log_mixture_density(x, c, np.log(w), 0.05)
    assert np.allclose(got, ref)
    assert np.allclose(log_mixture_density(x, c, np.log(w), 0.05, chunk=7), got)  # 1 row a chunk


def test_truncated_mixture_is_a_density_on_the_box():
    # q(x) = Σ w_u N(x; c_u, σ²)/Z_u integrates to 1 over the box (independent route: quadrature)
    b = np.array([[0.0, 1.0], [0.0, 1.0]])
    c = np.array([[0.02, 0.5], [0.97, 0.99], [0.5, 0.5]])
    sigma = 0.07
    lw = np.log([0.5, 0.3, 0.2]) - log_kernel_mass(c, sigma, b)
    m = 400  # midpoint rule on a 400 x 400 grid (the integrand is smooth at this scale)
    h = (np.arange(m) + 0.5) / m
    pts = np.stack(np.meshgrid(h, h, indexing="ij"), -1).reshape(-1, 2)
    total = np.exp(log_mixture_density(pts, c, lw, sigma)).sum() / m**2
    assert np.isclose(total, 1.0, atol=1e-4)


def test_jitter_draws_the_truncated_kernel():
    b = np.array([[0.0, 1.0]])
    x = np.full((20000, 1), 0.02)
    y = jitter(x, 0.05, b, np.random.default_rng(1))
    assert y.min() >= 0 and y.max() <= 1
    tn = stats.truncnorm((0 - 0.02) / 0.05, (1 - 0.02) / 0.05, loc=0.02, scale=0.05)
    assert stats.kstest(y[:, 0], tn.cdf).pvalue > 0.01
    assert np.isclose(log_kernel_mass(np.array([[0.02]]), 0.05, b)[0], np.log(tn.cdf(1) * 0 + (
        stats.norm.cdf(0.98 / 0.05) - stats.norm.cdf(-0.02 / 0.05))))


def test_grid_is_evenly_spaced():
    g = grid(np.array([[0.0, 1.0]] * 3), 1000)
    assert g.shape == (1000, 3)
    assert np.allclose(np.unique(g[:, 0]), (np.arange(10) + 0.5) / 10)
    g2 = grid(np.array([[0.0, 2.0], [1.0, 3.0]]), 7)  # not a perfect square: a spread subset
    assert g2.shape == (7, 2) and len(np.unique(g2, axis=0)) == 7
    assert np.all((g2 >= [0, 1]) & (g2 <= [2, 3]))


def test_grid_from_face_to_face():
    b = np.array([[0.0, 1.0], [-1.0, 1.0], [2.0, 5.0]])
    g = grid(b, 64, faces=True)  # the 4³ grid {0, ⅓, ⅔, 1}³ scaled to the box
    for j, (lo, hi) in enumerate(b):
        assert np.allclose(np.unique(g[:, j]), np.linspace(lo, hi, 4))
    on_face = np.any(np.isclose(g, b[:, 0]) | np.isclose(g, b[:, 1]), axis=1)
    assert on_face.sum() == 64 - 8  # only the 2³ inner points are off the faces
    assert np.allclose(grid(b, 1, faces=True), b.mean(axis=1))  # m = 1: the centre
    g5 = grid(b[:2], 5, faces=True)  # not a perfect square: a spread subset of the 3²
    assert g5.shape == (5, 2) and len(np.unique(g5, axis=0)) == 5


@pytest.mark.parametrize("initial,faces", [("grid", False), ("grid_faces", True), (None, True)])
def test_thesis_variants_start_from_the_chosen_grid(initial, faces):
    # the default (None) is the grid from face to face, the reading that reproduces Table 7.1
    seen = []

    class Recorder(CorrelatedGaussian):
        def log_prob(self, theta):
            seen.append(np.atleast_2d(theta).copy())
            return super().log_prob(theta)

    t = Recorder()
    PMC(n_samples=27, n_iterations=2, variant="thesis2", k=1, initial=initial).run(t, seed=0)
    assert np.array_equal(seen[0], grid(t.bounds, 27, faces=faces))  # G^0 weighs the start


class Spy(CorrelatedGaussian):
    """Records which sub-target evaluates how many rows."""

    def __init__(self, log=None, tag="full", **kw):
        super().__init__(**kw)
        self.log, self.tag = ([] if log is None else log), tag

    def log_prob(self, theta):
        self.log.append((self.tag, len(np.atleast_2d(theta))))
        return super().log_prob(theta)

    def partition(self, k, kind="strided"):
        parts = super().partition(k, kind)
        out = []
        for n, p in enumerate(parts):
            s = Spy(self.log, f"part{n}", n_obs=self.n_total)
            s.obs, s.cost, s._m, s._k, s._const = p.obs, p.cost, p._m, p._k, p._const
            out.append(s)
        return out


@pytest.mark.parametrize("variant", ["mixture", "thesis2", "thesis1"])
def test_importance_functions_cycle_and_costs_are_counted(variant):
    t = Spy()
    N, T, k = 60, 7, 3
    post = PMC(n_samples=N, n_iterations=T, variant=variant, k=k, power=0.5).run(t, seed=0)
    parts = [tag for tag, n in t.log if tag != "full"]
    full = [n for tag, n in t.log if tag == "full"]
    order = list(dict.fromkeys(parts))
    assert order == ["part0", "part1", "part2"]  # 7.9: G^n = s(PL^{n mod k})
    per_iter = {"mixture": 1, "thesis2": 2, "thesis1": 2}[variant]  # 6.66/6.67: G^n twice
    assert len(parts) == T * per_iter
    # n_target_evals in full-lattice equivalents: each sub-target row costs 1/3
    expect = sum(n for _, n in t.log if _ != "full") / 3 + sum(full)
    assert np.isclose(post.attrs["n_target_evals"], expect)
    if variant == "mixture":  # T sub-evaluations + final N + one MAP candidate per iteration
        assert np.isclose(expect, T * N / 3 + N + (T - 1))


def test_without_partition_uses_softened_full_target():
    post = PMC(**QUICK).run(TwoModes(), seed=1)
    assert np.isclose(post.attrs["n_target_evals"], 6 * 200 + 200 + 5)
    assert np.linalg.norm(P.map_estimate(post)[0] - TwoModes.high) < 0.03


@pytest.mark.parametrize("variant", ["mixture", "thesis2", "thesis1"])
@pytest.mark.parametrize("resampling", ["multinomial", "systematic", "stratified", "residual"])
def test_variants_and_resampling_schemes_run(variant, resampling):
    post = PMC(variant=variant, resampling=resampling, **QUICK).run(CorrelatedGaussian(), seed=2)
    P.validate(post)
    assert post.sizes["step"] == 6 and np.isfinite(post["map_log_target"]).all()
    assert np.all(np.diff(post["map_log_target"].values) >= 0)
    m = P.weighted_mean(post)
    assert np.all(np.abs(m - CorrelatedGaussian.mean) < 0.1)


def test_mixture_moments_on_gaussian_over_seeds():
    # The default variant's weights are exact importance weights: over seeds the mean error
    # averages out and the sd is right (each run 1000 particles, 5 iterations).
    t = CorrelatedGaussian()
    means, sds = [], []
    for seed in range(4):
        post = PMC(n_iterations=5, power=1.0).run(t, seed=seed)
        means.append(P.weighted_mean(post))
        sds.append(np.sqrt(np.diag(P.weighted_cov(post))))
    assert np.all(np.abs(np.mean(means, 0) - t.mean) < 0.3 * t.sd)
    assert np.all(np.abs(np.mean(sds, 0) / t.sd - 1) < 0.2)


def test_history_sigma_schedule_and_callback():
    calls = []
    post = PMC(keep_history=True, sigma0=0.06, **QUICK).run(
        CorrelatedGaussian(), seed=3, callback=lambda s, i: calls.append((s, i)))
    assert post["history_theta"].shape == (6, 200, 3)
    assert post["history_log_weight"].shape == (6, 200)
    assert np.allclose(np.exp(post["history_log_weight"]).sum(axis=1), 1)
    assert np.array_equal(post["history_theta"][-1], post["theta"])
    assert [s for s, _ in calls] == list(range(6))
    assert np.allclose([i["sigma"] for _, i in calls], 0.06 * (1 - np.arange(6) / 6))
    assert np.allclose([i["ess"] for _, i in calls], post["ess"])
    assert calls[-1][1]["n_target_evals"] == post.attrs["n_target_evals"]


def test_ess_threshold_controls_resampling():
    never = []
    PMC(ess_threshold=0.0, **QUICK).run(CorrelatedGaussian(), seed=4,
                                        callback=lambda s, i: never.append(i["resampled"]))
    always = []
    PMC(ess_threshold=1.0, **QUICK).run(CorrelatedGaussian(), seed=4,
                                        callback=lambda s, i: always.append(i["resampled"]))
    assert not any(never[1:]) and all(always[1:])


@pytest.mark.parametrize(("kw", "match"), [
    ({"n_samples": 1}, "n_samples"), ({"variant": "thesis3"}, "variant"),
    ({"power": 0}, "power"), ({"power": float("nan")}, "power"), ({"sigma0": -1}, "sigma0"),
    ({"resampling": "bogus"}, "resampling"), ({"k": 0}, "k"), ({"partition": "x"}, "partition"),
    ({"ess_threshold": 1.5}, "ess_threshold"),
    ({"ess_threshold": 0.5, "variant": "thesis2"}, "ess_threshold"),
    ({"keep_history": "yes"}, "keep_history"),
    ({"power": "auto", "variant": "thesis1"}, "power"), ({"power": "manual"}, "power"),
    ({"kernel": "adaptive", "variant": "thesis2"}, "kernel"), ({"kernel": "box"}, "kernel"),
    ({"auto_ess": 0.0}, "auto_ess"), ({"initial": "faces"}, "initial"),
])
def test_bad_config(kw, match):
    with pytest.raises(ValueError, match=match):
        PMC(**kw)


def test_bad_target_and_seed():
    with pytest.raises(ValueError, match="Target contract"):
        PMC(**QUICK).run(object(), seed=0)
    with pytest.raises(ValueError, match="seed"):
        PMC(**QUICK).run(CorrelatedGaussian(), seed=-1)


def test_variant_defaults():
    m, t2, lit = PMC(), PMC(variant="thesis2"), PMC(variant="thesis2_literal")
    assert (m.power, m.kernel, m.initial) == ("auto", "covariance", "halton")  # issue 12
    assert (t2.power, t2.kernel, t2.initial) == (1e-4, "isotropic", "grid_faces")  # issue 13
    assert (lit.power, lit.kernel, lit.initial) == (0.01, "isotropic", "grid_faces")
    assert PMC(**m.get_config()).get_config() == m.get_config()  # config round-trips


class Narrow(CorrelatedGaussian):
    """A Gaussian 50x sharper in x than in y and z (like the Ward PL's rho_d)."""

    sd = np.array([0.001, 0.05, 0.05])
    corr = np.eye(3)


def test_auto_power_anneals_and_resolves_a_sharp_direction():
    t = Narrow()
    info = []
    post = PMC(n_samples=500, n_iterations=12).run(t, seed=0, callback=lambda s, i: info.append(i))
    powers = [i["power"] for i in info]
    assert np.all(np.diff(powers) >= 0) and 0 < powers[0] < 1  # annealing, from a soft start
    m = P.weighted_mean(post)
    assert abs(m[0] - t.mean[0]) < 3 * t.sd[0]  # the sharp direction is resolved


def test_adaptive_kernel_scales():
    rng = np.random.default_rng(1)
    x = rng.normal([0.5, 0.5, 0.5], [0.001, 0.05, 0.2], size=(1000, 3))
    params = PMC(sigma0=0.07, n_iterations=10, kernel="adaptive").params()
    h = (4 / (5 * 1000)) ** (1 / 7)  # Silverman's factor, d = 3
    k = jitter_scale(params, 2, x, np.zeros(1000))
    sd = x.std(axis=0)
    assert np.allclose(k, [h * sd[0], h * sd[1], 0.07 * 0.8])  # capped by σ_2 = 0.056
    thesis = PMC(variant="thesis2", n_iterations=10).params()
    assert jitter_scale(thesis, 2, x, np.zeros(1000)) == 0.07 * 0.8


def test_auto_power_weights_keep_the_ess_fraction():
    rng = np.random.default_rng(0)
    raw, lq = rng.normal(scale=50, size=400), rng.normal(size=400)
    l, lw = soften(raw, lq, 0.0, "auto", 0.5)
    assert np.isclose(P.ess(lw), 0.5 * P.ess(-lq), rtol=1e-3)
    assert np.allclose(lw, l * raw - lq)
    l2, _ = soften(raw, lq, l, "auto", 0.5)
    assert l2 >= l
