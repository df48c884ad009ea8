"""docs/samplers.md's worked examples (a weighted sampler on the kit, a random walk as a step
and a driver) run and conform."""

import re
from pathlib import Path

import numpy as np

import mrfpe
from mrfpe.testing import CorrelatedGaussian, check_sampler

DOC = Path(__file__).resolve().parents[2] / "docs" / "samplers.md"


def _example_class(name="AdaptiveIS", max_lines=40):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    code = next(b for b in blocks if f"class {name}(" in b)
    assert len(code.strip().splitlines()) <= max_lines, "the worked example should stay short"
    namespace: dict = {}
    exec(compile(code, str(DOC), "exec"), namespace)
    return namespace[name], code


def test_worked_example_passes_the_conformance_suite():
    cls, code = _example_class()
    assert "mrfpe.samplers import kit" in code and "._" not in code  # public kit only
    report = check_sampler(cls)
    assert all(v == "passed" for v in report.values()), report


def test_worked_example_runs_through_the_front_door():
    cls, _ = _example_class()
    post = mrfpe.sample(cls, CorrelatedGaussian(), seed=0, n_samples=500)
    assert post.attrs["sampler"] == "adaptive_is" and post.sizes["sample"] == 500
    assert np.isclose(np.exp(post["log_weight"].values).sum(), 1.0)


def test_step_and_driver_example_passes_the_conformance_suite():
    cls, code = _example_class("RandomWalk", max_lines=50)
    assert "mrfpe.samplers import kit" in code and "._" not in code  # public kit only
    report = check_sampler(cls)
    assert all(v == "passed" for v in report.values()), report


def test_step_and_driver_example_step_is_pure():
    cls, _ = _example_class("RandomWalk", max_lines=50)
    namespace = cls.run.__globals__
    state_cls, step = namespace["WalkState"], namespace["walk_step"]
    target = CorrelatedGaussian()
    state = state_cls(np.full((4, 3), 0.5), target.log_prob(np.full((4, 3), 0.5)))
    before = [a.copy() for a in state]

    def log_density(y, inside):
        return np.where(inside, target.log_prob(y), -np.inf)

    out = [step(0.05, state, np.random.default_rng(9), log_density, target.bounds)
           for _ in range(2)]
    assert all(np.array_equal(a, b) for a, b in zip(state, before))
    assert all(np.array_equal(a, b) for a, b in zip(out[0][0], out[1][0]))
