"""map_batched: concurrent tasks whose single-point calls share batched evaluations."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from mrfpe.samplers.kit import map_batched


def _newton_sqrt(a, evaluate):
    """A task that needs a data-dependent number of evaluations: Newton for sqrt(a)."""
    x, calls = np.array([a]), 0
    while True:
        f, df = evaluate(np.array([x[0], a]))
        calls += 1
        step = f / df
        x = x - step
        if abs(step) < 1e-12 * abs(x[0]):
            return x[0], calls


def test_results_in_order_each_row_its_own_and_batches_bounded():
    sizes = []
    lock = threading.Lock()

    def batch(points):
        with lock:
            sizes.append(len(points))
        x, a = points[:, 0], points[:, 1]
        return list(zip(x * x - a, 2 * x))

    items = [float(a) for a in np.linspace(2.0, 50.0, 23)]
    out = list(map_batched(_newton_sqrt, items, batch, n_threads=5))
    alone = [_newton_sqrt(a, lambda p: (p[0] ** 2 - p[1], 2 * p[0])) for a in items]
    assert [r for r, _ in out] == [r for r, _ in alone]  # bit for bit, in item order
    assert [c for _, c in out] == [c for _, c in alone]
    assert max(sizes) <= 5 and sum(sizes) == sum(c for _, c in alone)
    assert max(sizes) > 1  # the calls were in fact gathered


def test_a_task_error_is_raised_in_its_turn_and_stops_new_tasks():
    started = []

    def task(i, evaluate):
        started.append(i)
        evaluate(np.array([float(i)]))
        if i == 2:
            raise ValueError("task 2 failed")
        return i

    gen = map_batched(task, range(40), lambda p: list(p[:, 0]), n_threads=3)
    assert [next(gen), next(gen)] == [0, 1]
    with pytest.raises(ValueError, match="task 2 failed"):
        next(gen)
    # No task starts once task 2 failed: the other two clients wait in the gather
    # for it until it has recorded the failure, so at most one more each starts.
    assert sorted(started)[:3] == [0, 1, 2] and len(started) <= 5


def test_a_failing_batch_reaches_every_waiting_task():
    def batch(points):
        raise FloatingPointError("kernel failed")

    with pytest.raises(RuntimeError, match="batched evaluation failed") as info:
        list(map_batched(lambda i, ev: ev(np.zeros(1)), range(6), batch, n_threads=3))
    assert isinstance(info.value.__cause__, FloatingPointError)
