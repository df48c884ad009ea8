"""docs/samplers.md's worked example (a weighted sampler on the kit) runs and conforms."""

import re
from pathlib import Path

import numpy as np

import mrfpe
from mrfpe.testing import CorrelatedGaussian, check_sampler

DOC = Path(__file__).resolve().parents[2] / "docs" / "samplers.md"


def _example_class():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    code = next(b for b in blocks if "class AdaptiveIS(" in b)
    assert len(code.strip().splitlines()) <= 40, "the worked example should stay ~30 lines"
    namespace: dict = {}
    exec(compile(code, str(DOC), "exec"), namespace)
    return namespace["AdaptiveIS"], code


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
