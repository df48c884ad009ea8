"""Memory budget, chunked log_prob and progress bars."""

from __future__ import annotations

import numpy as np
import pytest

import mrfpe.targets as T
from mrfpe import budget
from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import MemoryBudgetError, get, set_memory_budget


@pytest.fixture
def restore_budget():
    old = set_memory_budget(None)
    yield
    set_memory_budget(old)


@pytest.fixture(scope="module")
def scene():
    return make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(3, 3), n_labels=4, seed=2)


def test_parse_bytes():
    assert budget.parse_bytes("2GB") == 2 * 10**9
    assert budget.parse_bytes("1.5GiB") == int(1.5 * (1 << 30))
    assert budget.parse_bytes(1234) == 1234
    assert 0 < budget.parse_bytes("0.25") < budget.parse_bytes("0.5")
    for bad in ("lots", "-1GB", 0, True, None, "2XB"):
        with pytest.raises(ValueError, match="memory budget"):
            budget.parse_bytes(bad)


def test_env_var_and_setter(monkeypatch, restore_budget):
    monkeypatch.setenv("MRFPE_MEMORY_BUDGET", "123MB")
    assert T.memory_budget() == 123 * 10**6
    set_memory_budget(5000)
    assert T.memory_budget() == 5000
    assert set_memory_budget(None) == 5000
    assert T.memory_budget() == 123 * 10**6
    monkeypatch.setenv("MRFPE_MEMORY_BUDGET", "nonsense")
    with pytest.raises(ValueError, match="MRFPE_MEMORY_BUDGET"):
        T.memory_budget()


def test_build_fails_up_front_with_the_estimate(restore_budget):
    big = make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(4, 4), n_labels=3, seed=7)
    set_memory_budget("10MB")
    with pytest.raises(MemoryBudgetError, match=r"needs about .*MB, more than the memory budget"):
        get("pl", big)
    assert issubclass(MemoryBudgetError, ValueError) and issubclass(MemoryBudgetError,
                                                                    MemoryError)


def test_log_prob_fails_up_front(scene, restore_budget):
    t = get("pl", scene)
    set_memory_budget(100_000)
    with pytest.raises(MemoryBudgetError, match="log_prob on 20000 parameter vectors"):
        t.log_prob(np.full((20000, 3), 0.5))
    with pytest.raises(MemoryBudgetError, match="residuals"):
        t.residuals(np.full((2000, 3), 0.5))
    assert np.isfinite(t.log_prob(np.full((3, 3), 0.5))).all()


def test_chunked_log_prob_equals_unchunked(scene, monkeypatch):
    t = get("pl", scene)
    x = np.random.default_rng(0).uniform(-0.05, 1.05, (300, 3))
    whole = t.log_prob(x)
    monkeypatch.setattr(budget, "WORKING_CHUNK_BYTES", 64 * t._row_bytes())
    assert len(budget.chunk_rows(300, t._row_bytes())) > 3
    np.testing.assert_allclose(t.log_prob(x, progress=True), whole, rtol=1e-12)
    assert np.array_equal(np.isinf(t.log_prob(x)), np.isinf(whole))


def test_chunk_rows_cover_in_order():
    for n in (0, 1, 17, 1000):
        sl = budget.chunk_rows(n, 1e6)
        got = np.concatenate([np.arange(n)[s] for s in sl]) if sl else np.zeros(0)
        assert np.array_equal(got, np.arange(n))
        assert all(s.stop - s.start >= min(16, n) for s in sl)


def test_build_progress(scene, capsys):
    fresh = make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(3, 3), n_labels=4, seed=9)
    t = get("pls", fresh, progress=True)
    assert np.isfinite(t.log_prob([0.5, 0.5, 0.5])).all()
    assert "progress" not in t.describe()["options"]


def test_a_bare_one_is_one_byte_not_all_ram():
    from mrfpe.budget import _physical_ram, parse_bytes

    assert parse_bytes("1") == 1 and parse_bytes(1) == 1
    assert parse_bytes("1.0") == parse_bytes(1.0) == _physical_ram()
    assert parse_bytes("0.25") == int(0.25 * _physical_ram())
