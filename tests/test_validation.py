"""Shared argument checks (mrfpe.validation)."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.validation import check_beliefs, check_n_jobs


@pytest.mark.parametrize("value", [1, 2, -1, -2, np.int64(3)])
def test_check_n_jobs_accepts_joblib_counts(value):
    assert check_n_jobs("n_jobs", value) == int(value)
    assert type(check_n_jobs("n_jobs", value)) is int


@pytest.mark.parametrize("value", [0, True, 1.0, "2", None])
def test_check_n_jobs_names_the_argument(value):
    with pytest.raises(ValueError, match=r"workers must be a non-zero integer \(-1 = all cores\)"):
        check_n_jobs("workers", value)


def test_check_beliefs_returns_a_float64_copy():
    b = np.full((3, 4, 2), 0.5, dtype=np.float32)
    out = check_beliefs(b, (3, 4, 2))
    assert out.dtype == np.float64 and out is not b
    np.testing.assert_array_equal(out, 0.5)


@pytest.mark.parametrize(("beliefs", "message"), [
    ("abc", "my_beliefs must be a numeric array"),
    (np.full((3, 4), 0.5), r"my_beliefs must have shape \(3, 4, 2\); got \(3, 4\)"),
    (np.full((3, 4, 2), np.nan), "my_beliefs must be finite and >= 0"),
    (np.stack([np.full((3, 4), 1.5), np.full((3, 4), -0.5)], axis=2),
     "my_beliefs must be finite and >= 0"),
    (np.full((3, 4, 2), 0.6), r"my_beliefs must be normalised per node \(sum over labels = 1\)"),
])
def test_check_beliefs_names_the_argument(beliefs, message):
    with pytest.raises(ValueError, match=message):
        check_beliefs(beliefs, (3, 4, 2), "my_beliefs")


def test_scene_and_pl3_share_the_beliefs_check():
    """One validator: the scene's beliefs and pl3's beliefs option give the same errors."""
    import dataclasses

    from mrfpe.brdf.synthetic import make_scene
    from mrfpe.targets import get

    scene = make_scene(theta=[0.5, 0.3, 0.1], shape=(4, 4), n_labels=3, seed=0)
    bad = np.full((5, 5, 3), 0.5)
    with pytest.raises(ValueError, match="beliefs must be normalised per node") as from_scene:
        dataclasses.replace(scene, beliefs=bad)
    with pytest.raises(ValueError, match="beliefs must be normalised per node") as from_pl3:
        get("pl3", scene, beliefs=bad)
    assert str(from_scene.value) == str(from_pl3.value)
