"""The Examples sections of the models' docstrings run as written."""

from __future__ import annotations

import doctest

import pytest

import mrfpe.models.gaussian.model


@pytest.mark.parametrize("module", [mrfpe.models.gaussian.model], ids=lambda m: m.__name__)
def test_docstring_examples_run(module):
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
