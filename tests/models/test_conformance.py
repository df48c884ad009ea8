"""Every registered model passes the shipped conformance check; plugins cannot break others."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from mrfpe import models
from mrfpe.models.registry import validate_model
from mrfpe.testing import check_model


def test_no_broken_builtin_models():
    assert models.registry.errors() == {}
    assert {"potts", "ising", "autologistic", "autonormal", "brdf"} <= set(models.names())


@pytest.mark.parametrize("make,theta", [
    (lambda: models.potts(3, 8), [0.4, 0.1, -0.2]),
    (lambda: models.ising(directional=True), [0.2, 0.3, 0.0]),
    (lambda: models.potts(2, graph=nx.cycle_graph(9)), [0.4, 0.0]),
])
def test_discrete_models_conform(make, theta):
    m = make()
    shape = None if not isinstance(m.graph_spec, models.LatticeSpec) else (16, 16)
    x = m.simulate(theta, shape=shape, n=2, seed=0, n_sweeps=100)
    est = tuple(e for e in m.estimators if e not in ("exact", "pl_adjusted"))
    report = check_model(m, x, theta=theta, estimators=est)
    assert set(report.values()) <= {"passed"}, report


def test_covariate_model_and_exact_and_adjusted_conform():
    m = models.autologistic(["z"])
    z = np.random.default_rng(0).normal(size=(10, 10))
    x = m.simulate([0.3, -0.1, 0.8], shape=(10, 10), seed=1, covariates={"z": z})
    report = check_model(m, x, theta=[0.3, -0.1, 0.8], options={"covariates": {"z": z}})
    assert set(report.values()) <= {"passed"}, report


def test_check_model_catches_a_broken_model():
    class Broken(models.MRF):
        def _build(self, estimator, data, options):
            t = super()._build(estimator, data, options)
            if estimator == "coding":
                t.rows = t.rows[:0]  # drops every conditional: codings no longer sum to the PL
            return t

    m = Broken(4, 2, [models.Coupling(), models.Field()])
    x = models.potts().simulate([0.3, 0.0], shape=(6, 6), seed=0)
    with pytest.raises(AssertionError, match="codings sum to"):
        check_model(m, x, estimators=("pl", "coding"))


def test_model_plugins_are_validated():
    with pytest.raises(TypeError, match="no arguments"):
        validate_model(lambda shape: None)
    with pytest.raises(TypeError, match=r"not an mrfpe\.models\.Model"):
        validate_model(int)
    models.registry.register("not_a_model", lambda: 3)
    try:
        with pytest.raises(TypeError, match="returned int"):
            models.get("not_a_model")
        assert models.get("potts").name == "potts"  # the others are unaffected
    finally:
        models.registry.unregister("not_a_model")
