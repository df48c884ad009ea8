"""`mrfpe demo --quick` end to end: prints the report and writes its three files."""

import numpy as np
import pytest

from mrfpe import cli
from mrfpe import posterior as P


@pytest.mark.slow
def test_demo_quick(tmp_path, capsys):
    assert cli.main(["demo", "--quick", "--out", str(tmp_path), "--seed", "3"]) == 0
    out = capsys.readouterr().out
    for word in ("true parameters", "MAP", "|MAP - truth|", "posterior mean", "ESS"):
        assert word in out
    assert "±0.0000" not in out and "full-PL" not in out  # meaningful precision, no jargon
    report = (tmp_path / "report.md").read_text()  # the report --help promises
    assert "posterior mean ± sd" in report and "](particles.png)" in report
    post = P.load(tmp_path / "posterior.nc")
    P.validate(post)
    assert post.attrs["sampler"] == "pmc"
    assert (tmp_path / "scene.nc").stat().st_size > 0
    png = (tmp_path / "particles.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    from mrfpe.scene import Scene

    scene = Scene.load(tmp_path / "scene.nc")
    assert scene.true_theta is not None and np.all(np.isfinite(scene.true_theta))


def test_demo_rejects_unwritable_out_before_work(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert cli.main(["demo", "--quick", "--out", str(blocker / "out")]) == 2


def test_demo_rejects_bad_seed(tmp_path):
    from mrfpe.demo import main

    with pytest.raises(ValueError, match="seed"):
        main(tmp_path, quick=True, seed=-1)


def test_demo_over_the_memory_budget_writes_nothing(tmp_path, monkeypatch, capsys):
    from mrfpe import cli

    monkeypatch.setenv("MRFPE_MEMORY_BUDGET", "1KB")
    assert cli.main(["demo", "--quick", "--out", str(tmp_path / "d")]) == 2
    assert "memory budget" in capsys.readouterr().err
    assert list((tmp_path / "d").iterdir()) == []
