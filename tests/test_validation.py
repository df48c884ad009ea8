"""Shared argument checks (mrfpe.validation)."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.validation import check_n_jobs


@pytest.mark.parametrize("value", [1, 2, -1, -2, np.int64(3)])
def test_check_n_jobs_accepts_joblib_counts(value):
    assert check_n_jobs("n_jobs", value) == int(value)
    assert type(check_n_jobs("n_jobs", value)) is int


@pytest.mark.parametrize("value", [0, True, 1.0, "2", None])
def test_check_n_jobs_names_the_argument(value):
    with pytest.raises(ValueError, match=r"workers must be a non-zero integer \(-1 = all cores\)"):
        check_n_jobs("workers", value)
