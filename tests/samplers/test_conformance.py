"""Run the conformance suite (mrfpe.testing) over every registered sampler.

Samplers join automatically through the entry-point registry: built-ins, and
third-party plugins installed in the environment (e.g. plugins/mrfpe-smc).
Each (sampler, check) pair is its own test; checks a sampler declares as not
applicable (``conformance = {check: False}``) are reported as skipped.
"""

import pytest

import mrfpe.samplers
from mrfpe.testing import CHECKS, run_check

SAMPLERS = mrfpe.samplers.available()


def test_no_broken_samplers():
    assert mrfpe.samplers.broken() == {}, mrfpe.samplers.table()


@pytest.mark.parametrize("check", list(CHECKS))
@pytest.mark.parametrize("name", SAMPLERS)
def test_conformance(name, check):
    if run_check(name, check, quick=True) == "skipped: declared":
        pytest.skip(f"{name} declares {check!r} not applicable")
