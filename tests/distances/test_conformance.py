"""check_distance on every built-in distance (and that the checks catch broken ones)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pytest

import mrfpe.distances as D
from mrfpe.distances.base import Distance
from mrfpe.testing import check_distance


@pytest.mark.parametrize("name", D.available())
def test_builtin_distances_conform(name):
    report = check_distance(name)
    assert set(report.values()) == {"passed"}


class _Mean(Distance):
    """|weighted mean difference| with injectable bugs."""

    name = "mean_test"
    params: ClassVar[dict[str, Any]] = {"bug": "none"}
    bug = "none"

    def compare(self, fa, fb, p):
        ma = fa.weight @ fa.theta
        mb = fb.weight @ fb.theta
        v = float(np.linalg.norm(ma - mb))
        if self.bug == "asymmetric":
            v += 1e-3 * float(ma[0])
        if self.bug == "offset":
            v += 1.0
        if self.bug == "unweighted":
            v = float(np.linalg.norm(fa.theta.mean(0) - fb.theta.mean(0)))
        if self.bug == "negative":
            v = -v
        if self.bug == "nan":
            v = float("nan")
        return v


@pytest.mark.parametrize("bug, check", [("asymmetric", "symmetric"), ("offset", "identity"),
                                        ("unweighted", "weights"), ("negative", "nonnegative"),
                                        ("nan", "finite")])
def test_checks_catch_broken_distances(bug, check):
    cls = type(f"_Mean_{bug}", (_Mean,), {"bug": bug})
    with pytest.raises(AssertionError, match=f"check_distance_{check}"):
        check_distance(cls)


def test_declared_skip_and_unknown():
    cls = type("_Skip", (_Mean,), {"bug": "offset", "conformance": {"identity": False}})
    assert check_distance(cls)["identity"] == "skipped: declared"
    bad = type("_Bad", (_Mean,), {"conformance": {"nope": False}})
    with pytest.raises(AssertionError, match="unknown checks"):
        check_distance(bad)
    with pytest.raises(ValueError, match="distance must be"):
        check_distance(3)


def test_pairwise_arguments_are_checked_before_work():
    from ._helpers import random_post

    a = random_post(np.random.default_rng(0))
    dist = D.get("emd")()
    for kw, word in [({"n_jobs": "x"}, "n_jobs"), ({"n_jobs": 0}, "n_jobs"),
                     ({"progress": "x"}, "progress")]:
        with pytest.raises(ValueError, match=word):
            dist.pairwise([a, a], **kw)
    with pytest.raises(ValueError, match="posteriors must be a sequence"):
        dist.pairwise(a)
