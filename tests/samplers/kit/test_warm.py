"""Kernels compile before a progress bar starts, and a slow first call says so once."""

import numpy as np

from mrfpe.samplers.kit import runlog, warm


class _Slow:
    """A target whose first evaluation is slow, like a numba kernel compiling."""

    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    param_names = ("a", "b")

    def __init__(self, seconds: float):
        self.seconds, self.calls = seconds, 0

    def log_prob(self, theta):
        import time

        self.calls += 1
        if self.calls == 1:
            time.sleep(self.seconds)
        return np.zeros(np.atleast_2d(theta).shape[0])


def test_warm_target_reports_a_slow_first_call(monkeypatch):
    monkeypatch.setattr(warm, "REPORT_AFTER_S", 0.05)
    monkeypatch.setattr(warm, "kernels_cached", lambda *kernels: True)
    said: list[str] = []
    target = _Slow(0.1)
    assert warm.warm_target(target, said.append) >= 0.1
    assert target.calls == 2 and len(said) == 1 and "kernels ready in" in said[0]


def test_warm_target_announces_a_cold_cache(monkeypatch):
    monkeypatch.setattr(warm, "kernels_cached", lambda *kernels: False)
    said: list[str] = []
    warm.warm_target(_Slow(0.0), said.append)
    assert said and said[0].startswith("compiling numerical kernels (first run only")


def test_fast_warm_target_is_silent(monkeypatch):
    monkeypatch.setattr(warm, "kernels_cached", lambda *kernels: True)
    said: list[str] = []
    warm.warm_target(_Slow(0.0), said.append)
    assert said == []


def test_progress_bar_starts_after_the_warm_up(monkeypatch):
    """The sampler's run log evaluates the target before its bar: the ETA excludes it."""
    from mrfpe.samplers.kit import Run

    calls: list[str] = []
    monkeypatch.setattr(runlog, "warm_target", lambda t: calls.append("warm") or 0.0)
    Run(_Slow(0.0), 3, progress=True)._bar.close()
    Run(_Slow(0.0), 3, progress=False)
    assert calls == ["warm"]
