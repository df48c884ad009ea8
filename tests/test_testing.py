"""Tests of mrfpe.testing: the analytic targets and that each check catches what it claims."""

import time

import numpy as np
import pytest
from scipy import stats

from mrfpe import testing as T
from mrfpe.posterior import build, ess
from mrfpe.samplers.base import Sampler, check_positive_int


# -- analytic targets ------------------------------------------------------
def test_gaussian_is_the_stated_gaussian():
    t = T.CorrelatedGaussian()
    rng = np.random.default_rng(0)
    x = t.mean + rng.normal(scale=0.03, size=(20, 3))
    ref = stats.multivariate_normal(t.mean, t.cov).logpdf(x)
    lp = t.log_prob(x)
    assert np.allclose(lp - lp[0], ref - ref[0])  # same density up to a constant
    assert np.all(t.mean - 5 * t.sd > 0) and np.all(t.mean + 5 * t.sd < 1)  # truncation negligible
    assert np.allclose(np.corrcoef(np.linalg.cholesky(t.cov) @ rng.normal(size=(3, 200_000))),
                       t.corr, atol=0.01)
    assert np.isneginf(t.log_prob([[1.2, 0.5, 0.5]]))[0]


@pytest.mark.parametrize("kind", ["strided", "block"])
@pytest.mark.parametrize("k", [1, 3, 7])
def test_gaussian_partition_sums_to_full(kind, k):
    t = T.CorrelatedGaussian()
    parts = t.partition(k, kind)
    assert len(parts) == k and np.isclose(sum(p.cost for p in parts), 1.0)
    x = np.random.default_rng(1).random((15, 3))
    assert np.allclose(sum(p.log_prob(x) for p in parts), t.log_prob(x))
    with pytest.raises(ValueError):
        t.partition(0)
    with pytest.raises(ValueError):
        t.partition(2, "diagonal")


def test_residuals_give_the_log_density():
    x = np.random.default_rng(2).random((10, 3)) * 0.4 + 0.3
    for t in (T.CorrelatedGaussian(), T.CorrelatedGaussian(8)):
        r = t.residuals(x)
        lp = t.log_prob(x)
        assert np.allclose(lp + 0.5 * np.sum(r**2, axis=1), (lp + 0.5 * np.sum(r**2, axis=1))[0])
    tm = T.TwoModes()
    y = x[:, :2]
    r = tm.residuals(y)
    assert np.allclose(tm.log_prob(y), tm.max_log_prob + 1 - 0.5 * np.sum(r**2, axis=1))


def test_two_modes_and_mostly_minus_inf():
    tm = T.TwoModes()
    g = np.stack(np.meshgrid(np.linspace(0, 1, 401), np.linspace(0, 1, 401)), -1).reshape(-1, 2)
    best = g[np.argmax(tm.log_prob(g))]
    assert np.linalg.norm(best - tm.high) < 0.005
    assert tm.log_prob(tm.low)[0] < tm.max_log_prob - 0.99
    mm = T.MostlyMinusInf()
    u = np.random.default_rng(3).random((100_000, 3))
    frac = np.isfinite(mm.log_prob(u)).mean()
    assert 0.002 < frac < 0.005
    assert np.isfinite(mm.log_prob(mm.box.mean(axis=1)))[0]


# -- samplers to test the checks with ----------------------------------------
class GaussIS(Sampler):
    """Importance sampling from a broad Gaussian, redrawn into the bounds (reference)."""

    def __init__(self, n_samples: int = 20000, *, weighted: bool = True,
                 ignore_seed: bool = False, leave_bounds: bool = False):
        self.n_samples = check_positive_int("n_samples", n_samples)
        for k, v in (("weighted", weighted), ("ignore_seed", ignore_seed),
                     ("leave_bounds", leave_bounds)):
            if not isinstance(v, bool):
                raise ValueError(f"{k} must be a bool")
        self.weighted, self.ignore_seed, self.leave_bounds = weighted, ignore_seed, leave_bounds

    def run(self, target, *, seed=None, progress=False, callback=None):
        t0 = time.perf_counter()
        rng = np.random.default_rng(None if self.ignore_seed else seed)
        b = np.asarray(target.bounds)
        c, s = b.mean(1), (b[:, 1] - b[:, 0]) * 0.25
        x = rng.normal(c, s, (self.n_samples, len(c)))
        if not self.leave_bounds:
            out = ~np.all((x >= b[:, 0]) & (x <= b[:, 1]), axis=1)
            x = x[~out]
        lq = -0.5 * np.sum(((x - c) / s) ** 2, 1)
        lt = target.log_prob(x)
        lw = np.where(np.isfinite(lt), lt - lq, -np.inf) if self.weighted else None
        best = int(np.argmax(lt))
        if callback:
            callback(0, {"ess": ess(lw if lw is not None else np.zeros(len(x)))})
        return build(x, lt, param_names=target.param_names, log_weight=lw,
                     map_theta=x[best][None], map_log_target=[lt[best]], sampler="gaussis",
                     config=self.get_config(), seed=seed, target=target,
                     n_target_evals=len(x), wall_time_s=time.perf_counter() - t0)


def _variant(**cfg):
    return type("V", (GaussIS,), {"conformance": {"quick_config": cfg}})


def test_reference_sampler_passes_everything():
    report = T.check_sampler(GaussIS)
    assert set(report) == set(T.CHECKS) and set(report.values()) == {"passed"}


@pytest.mark.parametrize(("cfg", "check"), [
    ({"weighted": False}, "gaussian_moments"),
    ({"ignore_seed": True}, "reproducible"),
    ({"leave_bounds": True}, "bounds"),
])
def test_checks_catch_broken_samplers(cfg, check):
    with pytest.raises(AssertionError, match=f"check_{check} failed"):
        T.run_check(_variant(**cfg), check)


def test_config_check_catches_unvalidated_settings():
    class Lax(GaussIS):
        def __init__(self, n_samples: int = 20000, scale: float = 1.0):
            super().__init__(n_samples)
            self.scale = scale  # not validated

    with pytest.raises(AssertionError, match=r"scale=.*accepted"):
        T.check_config(Lax)

    class Star(GaussIS):
        def __init__(self, **kw):
            super().__init__()

    with pytest.raises(AssertionError, match=r"\*\*kwargs"):
        T.check_config(Star)


def test_interface_check_and_map_trace_check():
    class NoRun:
        pass

    with pytest.raises(AssertionError, match="check_interface"):
        T.check_interface(NoRun)

    class BadMap(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            post["map_log_target"][:] = post["map_log_target"] + 1.0
            return post

    with pytest.raises(AssertionError, match="check_map_trace"):
        T.check_map_trace(BadMap)


def test_mostly_minus_inf_check_catches_weight_on_impossible_samples():
    class Careless(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            post["log_weight"][:] = -np.log(post.sizes["sample"])
            return post

    with pytest.raises(AssertionError, match="carry weight"):
        T.check_mostly_minus_inf(Careless)


def test_declarations_skip_and_tune_checks():
    cls = type("D", (GaussIS,), {"conformance": {
        "two_modes": False, "mostly_minus_inf": False, "bounds": {}}})
    report = T.check_sampler(cls)
    assert report["two_modes"] == "skipped: declared"
    assert report["gaussian_moments"] == "passed" and report["diagnostics"] == "passed"
    bad = type("B", (GaussIS,), {"conformance": {"no_such_check": False}})
    with pytest.raises(AssertionError, match="unknown checks"):
        T.check_sampler(bad)
    with pytest.raises(ValueError, match="unknown check"):
        T.run_check(GaussIS, "nope")


@pytest.mark.parametrize("decl", [False, {"z": 100.0}])
@pytest.mark.parametrize("check", ["gaussian_moments", "diagnostics"])
def test_moments_and_diagnostics_cannot_be_declared_away(decl, check):
    cls = type("D", (GaussIS,), {"conformance": {check: decl}})
    with pytest.raises(AssertionError, match="cannot be skipped or loosened"):
        T.run_check(cls, check)


class Exact(Sampler):
    """Independent draws from the true Gaussian, optionally shifted/stretched (in sd)."""

    def __init__(self, n_samples: int = 20000, shift: float = 0.0, stretch: float = 1.0,
                 kind: str = "draws"):
        self.n_samples = check_positive_int("n_samples", n_samples)
        for k, v in (("shift", shift), ("stretch", stretch)):
            if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
                raise ValueError(f"{k} must be a finite float")
        if kind not in ("draws", "optima"):
            raise ValueError("kind must be draws or optima")
        self.shift, self.stretch, self.kind = float(shift), float(stretch), kind

    def run(self, target, *, seed=None, progress=False, callback=None):
        t = T.CorrelatedGaussian()
        rng = np.random.default_rng(seed)
        z = rng.multivariate_normal(np.zeros(3), t.cov, self.n_samples)
        x = t.mean + self.shift * t.sd + self.stretch * z
        lt = t.log_prob(x)
        return build(x, lt, param_names=t.param_names, sampler="exact",
                     config=self.get_config(), seed=seed, target=t, kind=self.kind,
                     n_target_evals=len(x))


def _exact(**cfg):
    return type("E", (Exact,), {"conformance": {"quick_config": cfg}})


@pytest.mark.filterwarnings("ignore::mrfpe.posterior.PosteriorWarning")
@pytest.mark.parametrize(("cfg", "ok"), [
    ({}, True),
    # 0.15 sd off: inside the absolute 0.25 sd, but 12 Monte Carlo SEs at ESS 20000
    ({"shift": 0.15}, False),
    ({"shift": 0.15, "n_samples": 200}, True),  # at ESS 200 it is within 4 SEs
    ({"shift": 0.3, "n_samples": 40}, False),  # the absolute bound holds whatever the ESS
    ({"stretch": 1.08}, False),  # 8 % too wide: far beyond 4 SEs of an sd at ESS 20000
    ({"stretch": 1.08, "n_samples": 300}, True),
    ({"stretch": 1.2, "n_samples": 30}, False),  # outside 0.85-1.15
])
def test_moment_tolerances_follow_the_ess(cfg, ok):
    if ok:
        assert T.run_check(_exact(**cfg), "gaussian_moments") == "passed"
    else:
        with pytest.raises(AssertionError, match="check_gaussian_moments failed"):
            T.run_check(_exact(**cfg), "gaussian_moments")


def test_moment_tolerance_closed_forms():
    corr = np.array([[1.0, 0.6], [0.6, 1.0]])
    m, s, c = T.moment_tolerances(1600, corr)
    assert m == pytest.approx(4 / 40 + 0.05) and s == pytest.approx(4 / np.sqrt(3200) + 0.05)
    assert c[0, 1] == pytest.approx(4 * 0.64 / 40 + 0.05)
    m, s, c = T.moment_tolerances(4, corr)  # tiny ESS: the absolute bounds
    assert (m, s) == (0.25, pytest.approx(0.15)) and c[0, 1] == 0.3
    assert T.moment_tolerances(float("nan"), corr)[0] == 0.25


def test_only_optima_are_exempt_from_the_moment_check():
    opt = _exact(shift=3.0, kind="optima")
    assert T.run_check(opt, "gaussian_moments").startswith("skipped: optima")
    declared = type("O", (opt,), {"conformance": {**opt.conformance, "gaussian_moments": False}})
    assert T.run_check(declared, "gaussian_moments").startswith("skipped: optima")


def test_diagnostics_check_catches_missing_or_forged_diagnostics():
    assert T.run_check(GaussIS, "diagnostics") == "passed"

    class Stripped(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            del post.attrs["diag_pareto_k"]
            return post

    with pytest.raises(AssertionError, match="lacks the attributes"):
        T.check_diagnostics(Stripped)

    class Forged(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            post.attrs["diag_ess"] = 1e6
            return post

    with pytest.raises(AssertionError, match="diag_ess"):
        T.check_diagnostics(Forged)


def test_mostly_minus_inf_accepts_an_honest_refusal_only():
    class Refuses(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            if isinstance(target, T.MostlyMinusInf):  # as if no sample found the support
                build(post["theta"].values, np.full(post.sizes["sample"], -np.inf),
                      param_names=target.param_names, log_weight=np.full(
                          post.sizes["sample"], -np.inf), sampler="refuses")
            return post

    T.check_mostly_minus_inf(Refuses)
    T.check_bounds(Refuses)
    T.check_netcdf_roundtrip(Refuses)

    class MadeUp(GaussIS):
        def run(self, target, **kw):
            post = super().run(target, **kw)
            post["log_target"][:] = -np.inf
            post["log_weight"][:] = -np.log(post.sizes["sample"])
            return post

    # the schema check refuses it first (a log target -inf everywhere has no support)
    with pytest.raises(AssertionError, match="log_target is -inf or NaN at every one"):
        T.check_mostly_minus_inf(MadeUp)


def test_check_sampler_reports_all_failures_at_once():
    with pytest.raises(AssertionError) as info:
        T.check_sampler(_variant(weighted=False, ignore_seed=True))
    msg = str(info.value)
    assert "check_gaussian_moments" in msg and "check_reproducible" in msg
