"""Run the conformance suite (mrfpe.testing) over every registered sampler.

Samplers join automatically through the entry-point registry: built-ins, and
third-party plugins installed in the environment (e.g. plugins/mrfpe-smc).
Each (sampler, check) pair is its own test; checks a sampler declares as not
applicable (``conformance = {check: False}``), and the moment check on a set of
optima, are reported as skipped.
"""

import pytest

import mrfpe.samplers
from mrfpe.testing import CHECKS, run_check

SAMPLERS = mrfpe.samplers.available()

#: Known failures, in ONE place: (sampler, check) -> the measured reason. The
#: checks are not loosened for them; delete an entry when its sampler is fixed
#: (strict=False, so a fixed sampler passes before its entry is removed).
KNOWN_FAILURES: dict[tuple[str, str], str] = {
    ("dw_q", "gaussian_moments"):
        "quick config (4000 steps), seed 0: mean errors 4.2/0.2/5.0 sd at ESS 1 (Kish ESS "
        "2.4, Pareto k 20); diagnosed unreliable",
    ("dw_r", "gaussian_moments"):
        "quick config (4000 steps), seed 0: mean errors 1.0/0.2/1.3 sd at ESS 1 (Kish ESS "
        "10, Pareto k 8.4); diagnosed unreliable",
}


def test_no_broken_samplers():
    assert mrfpe.samplers.broken() == {}, mrfpe.samplers.table()


def _cases():
    for name in SAMPLERS:
        for check in CHECKS:
            reason = KNOWN_FAILURES.get((name, check))
            marks = [pytest.mark.xfail(strict=False, reason=reason)] if reason else []
            yield pytest.param(name, check, marks=marks, id=f"{name}-{check}")


@pytest.mark.parametrize(("name", "check"), list(_cases()))
def test_conformance(name, check):
    result = run_check(name, check, quick=True)
    if result.startswith("skipped"):
        pytest.skip(f"{name}: {check} {result}")
