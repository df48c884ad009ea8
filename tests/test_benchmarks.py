"""``python -m benchmarks --quick`` runs every suite end to end (numbers not asserted)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from . import _processes as procs

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_benchmark_runner_quick():
    before = (ROOT / "benchmarks" / "RESULTS.md").read_bytes()
    proc = procs.run([sys.executable, "-m", "benchmarks", "--quick", "--no-write"], cwd=ROOT,
                     timeout=600)
    out = proc.stdout
    for heading in ("== models ==", "== targets ==", "== samplers ==", "== stereo ==",
                    "| quarter | mrfpe", "| autologistic + covariate |"):
        assert heading in out
    assert "| ward | float64 | 10 |" in out  # a targets row with every column filled
    row = next(line for line in out.splitlines() if line.startswith("| ward | float64 | 10 |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert len(cells) >= 20 and "-" not in cells
    for sampler in ("pmc", "emcee", "dw_r", "lm_multiseed"):
        assert f"| {sampler} |" in out
    assert (ROOT / "benchmarks" / "RESULTS.md").read_bytes() == before  # --no-write
