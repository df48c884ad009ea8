"""check_target on every built-in target (and that the checks catch broken targets)."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.synthetic import make_scene
from mrfpe.models.short_forms import gibbs_sample
from mrfpe.targets import Target, get, names, softened
from mrfpe.testing import CorrelatedGaussian, MostlyMinusInf, TwoModes, check_target

THETA = {"lambertian": [0.6], "ward": [0.6, 0.5, 0.2], "ward_aniso": [0.6, 0.3, 0.2, 0.1],
         "phong": [0.5, 0.4, 10.0], "phong_aniso": [0.5, 0.4, 10.0, 5.0]}


@pytest.fixture(scope="module", params=sorted(THETA))
def scene(request):
    return make_scene(brdf=request.param, theta=THETA[request.param], shape=(3, 4),
                      n_labels=3, noise=0.01, seed=3)


def _opts(name, scene):
    if name != "pl3":
        return {}
    b = np.random.default_rng(0).random((*scene.lattice.node_shape, scene.n_labels))
    return {"beliefs": b / b.sum(axis=2, keepdims=True)}


BRDF_TARGETS = [n for n in names() if not n.startswith("potts")]


@pytest.mark.parametrize("name", BRDF_TARGETS)
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_brdf_targets_conform(scene, name, dtype):
    t = get(name, scene, dtype=dtype, **_opts(name, scene))
    report = check_target(t, rtol=1e-9 if dtype == "float64" else 1e-5)
    assert set(report.values()) == {"passed"}


@pytest.mark.parametrize("name", BRDF_TARGETS)
def test_triplet_and_softened_conform(name):
    sc = make_scene(brdf="ward", theta=THETA["ward"], shape=(2, 3), n_labels=4, seed=1)
    t = get(name, sc, data_term="triplet", **_opts(name, sc))
    check_target(t)
    check_target(softened(t, 0.3))


def test_potts_targets_conform():
    x = gibbs_sample([0.5, 0.1], (6, 6), seed=1)
    check_target(get("potts", x))
    check_target(lambda: get("potts", x[0], n_states=3))
    check_target(get("potts_exact", x[:, :3, :3]))
    check_target(softened(get("potts", x), 0.5))


@pytest.mark.parametrize("cls", [CorrelatedGaussian, TwoModes, MostlyMinusInf])
def test_analytic_targets_conform(cls):
    check_target(cls)


# -- the checks catch broken targets --------------------------------------------------------
class _Broken(Target):
    param_names = ("a", "b")
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])

    def __init__(self, bug):
        self.bug = bug

    def _log_prob(self, theta):
        return -np.sum(theta**2, axis=1)

    def log_prob(self, theta, **kw):
        out = super().log_prob(theta)
        if self.bug == "nan":
            out[:] = np.nan
        if self.bug == "outside":
            out[~np.isfinite(out)] = 0.0
        if self.bug == "shape":
            return out[:, None]
        return out

    def partition(self, k, kind="strided"):
        return [_Broken("ok") for _ in range(k)]  # every part is the whole: no sum identity


@pytest.mark.parametrize("bug, check", [("nan", "bounds"), ("outside", "bounds"),
                                        ("shape", "batch"), ("ok", "partition")])
def test_checks_catch_broken_targets(bug, check):
    with pytest.raises(AssertionError, match=f"check_target_{check}"):
        check_target(_Broken(bug))


def test_check_target_bad_arguments():
    with pytest.raises(ValueError, match="target_or_factory"):
        check_target(3)
    with pytest.raises(ValueError, match="unknown checks"):
        check_target(TwoModes(), skip=("nope",))
    assert check_target(TwoModes(), skip=("partition",))["partition"] == "skipped"


class _DuckTarget:
    """Not a Target subclass: the contract is structural."""

    param_names = ("x",)
    bounds = np.array([[-1.0, 2.0]])
    cost = 1.0

    def log_prob(self, theta):
        theta = np.asarray(theta, dtype=float)
        if theta.ndim == 1:
            theta = theta[None]
        if theta.ndim != 2 or theta.shape[1] != 1 or np.isnan(theta).any():
            raise ValueError("theta must be (N, 1) without NaN")
        inside = (theta[:, 0] >= -1) & (theta[:, 0] <= 2)
        return np.where(inside, -0.5 * theta[:, 0] ** 2, -np.inf)


def test_duck_typed_target_conforms():
    report = check_target(_DuckTarget())
    assert report["partition"] == "passed" and report["describe"] == "passed"  # absent: vacuous
