"""Pieces every benchmark shares: machine facts, timing, memory, scenes, RESULTS.md."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import time
import tracemalloc
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from mrfpe.experiments.writeup import markdown_table

__all__ = ["CACHE", "RESULTS", "append_results", "best", "cached_maximiser", "command_line",
           "load_avg", "machine", "markdown_table", "peak_memory", "threading_layer",
           "ward_scene_target"]

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "RESULTS.md"
CACHE = HERE / ".cache"


def machine() -> dict:
    """Date, CPU, cores, threads, versions and load average, for a results header."""
    import numba
    import scipy

    import mrfpe

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "date": _dt.datetime.now().isoformat(timespec="seconds"),
        "cpu": cpu, "cores": os.cpu_count(), "numba_threads": numba.get_num_threads(),
        "threading_layer": threading_layer(), "python": platform.python_version(),
        "numpy": np.__version__, "numba": numba.__version__, "scipy": scipy.__version__,
        "mrfpe": mrfpe.__version__, "platform": platform.platform(),
        "load_avg": load_avg(),
    }


def load_avg() -> str:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return " ".join(f"{x:.2f}" for x in load)


def threading_layer() -> str:
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel region has run yet
        return str(numba.config.THREADING_LAYER)


def best(fn: Callable[[], Any], repeat: int) -> tuple[float, float]:
    """Best wall and CPU seconds of ``repeat`` calls of ``fn``."""
    wall, cpu = np.inf, np.inf
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu


def _vm_hwm_bytes() -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


@contextmanager
def peak_memory():
    """Measure the peak memory of the enclosed block; yields a dict filled on exit.

    ``traced_MiB``: peak of Python/numpy allocations (:mod:`tracemalloc`) above
    the block's start. ``rss_MiB``: the process's peak resident set (VmHWM)
    during the block, where Linux lets it be reset (``/proc/self/clear_refs``);
    it includes the interpreter and every loaded library, and memory allocated
    inside numba kernels, which tracemalloc does not see.
    """
    out: dict[str, float] = {}
    rss_reset = False
    try:
        Path("/proc/self/clear_refs").write_text("5")  # reset VmHWM to the current RSS
        rss_reset = True
    except OSError:
        pass
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    try:
        yield out
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        out["traced_MiB"] = (peak - base) / 2**20
        hwm = _vm_hwm_bytes() if rss_reset else None
        out["rss_MiB"] = hwm / 2**20 if hwm is not None else float("nan")


def ward_scene_target(i: int, shape: tuple[int, int], n_labels: int, **options: Any):
    """Scene ``i``: random true Ward parameters (unit cube, in [0.05, 0.95]^3) and its ``pls``."""
    import mrfpe
    from mrfpe.brdf.synthetic import make_scene

    u = np.random.default_rng(1000 + i).uniform(0.05, 0.95, 3)
    theta = np.asarray(mrfpe.brdf.get("ward").to_natural(u)).reshape(-1)
    scene = make_scene(brdf="ward", theta=theta, shape=shape, n_labels=n_labels, seed=i)
    return u, mrfpe.targets.get("pls", scene, **options)


def cached_maximiser(i: int, target: Any, tag: str,
                     cache: Path = CACHE) -> tuple[np.ndarray, float, float]:
    """(x, log_prob, seconds) of ``target``'s global maximiser, cached on disk by ``tag``, ``i``."""
    import mrfpe

    path = cache / f"max_{tag}_{i}.json"
    if path.exists():
        rec = json.loads(path.read_text())
        return np.array(rec["x"]), float(rec["f"]), float(rec.get("time", np.nan))
    t0 = time.perf_counter()
    x, f = mrfpe.targets.maximise(target)
    rec = {"x": np.asarray(x).tolist(), "f": float(f), "time": time.perf_counter() - t0}
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rec))
    return np.asarray(x), float(f), rec["time"]


def command_line(argv: list[str] | None, module: str) -> str:
    args = sys.argv[1:] if argv is None else argv
    return " ".join(["python -m", module, *args])


def append_results(title: str, command: str, info: dict, body: list[str],
                   path: Path = RESULTS) -> None:
    """Append a dated section (title, command, machine line, body) to RESULTS.md."""
    info = {**info, "load_avg_end": load_avg()}
    section = [f"\n## {title} ({info['date']})\n", f"Command: `{command}`\n",
               "Machine: " + ", ".join(f"{k} {v}" for k, v in info.items() if k != "date")
               + "\n", *body, ""]
    with path.open("a") as f:
        f.write("\n".join(section) + "\n")
    print(f"appended to {path}")
