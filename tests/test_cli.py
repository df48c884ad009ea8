"""The command line: sampler listing, estimate -> compare round trip on a tiny scene."""

import numpy as np
import pytest

import mrfpe.samplers
from mrfpe import cli
from mrfpe import posterior as P

BUILTINS = ["dw_q", "dw_r", "emcee", "exchange", "lm_multiseed", "mh", "nlopt_multiseed", "pmc",
            "ppf", "sir"]


def test_samplers_lists_every_registered_sampler(capsys):
    assert cli.main(["samplers"]) == 0
    out = capsys.readouterr().out
    rows = [line.split()[0] for line in out.splitlines()[2:] if line.strip()]
    for name in BUILTINS:
        assert name in rows
    assert set(mrfpe.samplers.available()) <= set(rows)
    third_party = [i for i in mrfpe.samplers.registry.available().values()
                   if i.package != "mrfpe"]
    if not third_party:
        pytest.skip("no third-party sampler plugin installed (README installs plugins/*)")
    assert len(rows) >= 10


def test_models_lists_every_registered_model(capsys):
    from mrfpe import models

    assert cli.main(["models"]) == 0
    rows = [line.split()[0] for line in capsys.readouterr().out.splitlines()[2:] if line.strip()]
    assert set(models.names()) <= set(rows)
    assert {"potts", "ising", "autologistic", "autonormal", "brdf"} <= set(rows)


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    from mrfpe.brdf import get
    from mrfpe.brdf.synthetic import make_scene

    theta = np.asarray(get("ward").to_natural(np.array([0.5, 0.4, 0.5]))).reshape(-1)
    scene = make_scene(brdf="ward", theta=theta, shape=(10, 10), n_labels=5, seed=0)
    path = tmp_path_factory.mktemp("scene") / "scene.nc"
    scene.save(path)
    return path


def test_estimate_then_compare(tiny_scene, tmp_path, capsys):
    outs = []
    for seed in (0, 1):
        out = tmp_path / f"post{seed}.nc"
        rc = cli.main(["estimate", str(tiny_scene), "--sampler", "pmc", "--out", str(out),
                       "--seed", str(seed), "--set", "n_samples=64", "--set", "n_iterations=3",
                       "--quiet"])
        assert rc == 0
        post = P.load(out)
        P.validate(post)
        assert post.attrs["sampler"] == "pmc" and post.attrs["seed"] == seed
        assert post.sizes["sample"] == 64 and post.sizes["step"] == 3
        outs.append(out)
    assert "MAP" in capsys.readouterr().out
    assert cli.main(["compare", str(outs[0]), str(outs[1]), "--distance", "bhattacharyya"]) == 0
    d = _compared(capsys.readouterr().out, "bhattacharyya distance")
    assert np.isfinite(d) and d >= 0
    assert cli.main(["compare", str(outs[0]), str(outs[0]), "--distance", "bhattacharyya"]) == 0
    assert _compared(capsys.readouterr().out, "bhattacharyya distance") <= d + 1e-12


def _compared(out: str, name: str) -> float:
    """The number of ``mrfpe compare``'s one line, which names the distance first."""
    assert out.startswith(name + " between ")
    return float(out.rsplit(": ", 1)[1].split()[0])


@pytest.mark.parametrize("argv", [["samplers"], ["distances"], ["study", "list"], ["--help"],
                                  ["demo", "--help"], ["study", "run", "--help"]])
def test_output_fits_a_terminal(argv, capsys):
    """Listings and help fit 100 columns and carry no reStructuredText markup."""
    try:
        assert cli.main(argv) == 0
    except SystemExit as exc:  # --help
        assert exc.code == 0
    out = capsys.readouterr().out
    assert max(map(len, out.splitlines())) <= 100
    assert "``" not in out and ":func:" not in out and ":mod:" not in out


@pytest.mark.parametrize("argv", [["samplers", "--verbose"], ["study", "list", "--verbose"]])
def test_verbose_listing_wraps_the_details(argv, capsys):
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert max(map(len, out.splitlines())) <= 100 and "…" not in out


def test_estimate_reports_bad_settings(tiny_scene, tmp_path, capsys):
    rc = cli.main(["estimate", str(tiny_scene), "--sampler", "pmc", "--out",
                   str(tmp_path / "x.nc"), "--set", "n_samples=-3", "--quiet"])
    assert rc == 2 and "n_samples" in capsys.readouterr().err
    rc = cli.main(["estimate", str(tiny_scene), "--sampler", "nope", "--out",
                   str(tmp_path / "x.nc"), "--quiet"])
    assert rc == 2 and "available" in capsys.readouterr().err
