"""`mrfpe demo --quick` end to end: a reliable posterior, a verdict in words, four files."""

import warnings

import numpy as np
import pytest

from mrfpe import cli
from mrfpe import posterior as P
from mrfpe.demo import DEFAULT, QUICK


@pytest.mark.slow
def test_demo_quick(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the demo ends without any warning
        assert cli.main(["demo", "--quick", "--out", str(tmp_path), "--seed", "3"]) == 0
    out = capsys.readouterr().out
    for word in ("true parameters", "MAP", "posterior mean ± sd", "95% interval",
                 "the posterior is reliable", "It is a pseudo-posterior", "Result: the MAP lies",
                 "Next:"):
        assert word in out
    assert max(map(len, out.splitlines())) <= 100
    assert "±0.0000" not in out and "full-PL" not in out  # meaningful precision, no jargon
    assert "thesis Table" not in out  # no thesis figure for the quick settings
    report = (tmp_path / "report.md").read_text()  # the report --help promises
    assert "posterior mean ± sd" in report and "](posterior.png)" in report
    assert "*Left: the posterior" in report  # the figure's caption
    post = P.load(tmp_path / "posterior.nc")
    P.validate(post)
    assert post.attrs["sampler"] == "pmc" and post.attrs["diag_reliable"]
    assert (tmp_path / "scene.nc").stat().st_size > 0
    png = (tmp_path / "posterior.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    from mrfpe.brdf.scene import Scene

    scene = Scene.load(tmp_path / "scene.nc")
    assert scene.true_theta is not None and np.all(np.isfinite(scene.true_theta))


def test_thesis_figure_only_for_its_own_settings():
    """The default quotes Table 7.1 because it runs Table 7.1's labels, N and image size."""
    assert DEFAULT.thesis and "20 labels, 1000 particles, 100x100 pixels" in DEFAULT.thesis
    assert (DEFAULT.n_labels, DEFAULT.n_samples, DEFAULT.shape) == (20, 1000, (100, 100))
    assert QUICK.thesis is None


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
