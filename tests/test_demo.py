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
    post = P.load(tmp_path / "posterior.nc")
    P.validate(post)
    assert post.attrs["sampler"] == "pmc"
    assert (tmp_path / "scene.nc").stat().st_size > 0
    png = (tmp_path / "particles.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    from mrfpe.scene import Scene

    scene = Scene.load(tmp_path / "scene.nc")
    assert scene.true_theta is not None and np.all(np.isfinite(scene.true_theta))


def test_demo_rejects_bad_seed(tmp_path):
    from mrfpe.demo import main

    with pytest.raises(ValueError, match="seed"):
        main(tmp_path, quick=True, seed=-1)
