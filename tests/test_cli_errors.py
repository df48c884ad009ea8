"""Bad input to the command line: one line on stderr, exit 2, before any work (issue 16)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from mrfpe import cli
from mrfpe import posterior as P


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from mrfpe.brdf import get
    from mrfpe.brdf.synthetic import make_scene

    d = tmp_path_factory.mktemp("files")
    theta = np.asarray(get("ward").to_natural(np.array([0.5, 0.4, 0.5]))).reshape(-1)
    make_scene(brdf="ward", theta=theta, shape=(8, 8), n_labels=4, seed=0).save(d / "scene.nc")
    assert cli.main(["estimate", str(d / "scene.nc"), "--out", str(d / "post.nc"), "--quiet",
                     "--set", "n_samples=16", "--set", "n_iterations=2"]) == 0
    data = (d / "post.nc").read_bytes()
    (d / "truncated.nc").write_bytes(data[: len(data) // 3])
    (d / "garbage.nc").write_text("not netcdf\n")
    return d


def run(argv, capsys):
    rc = cli.main(argv)
    captured = capsys.readouterr()
    return rc, captured.err.strip()


@pytest.fixture
def no_sampling(monkeypatch):
    """Fail the test if a sampler or a study trial starts: the errors must come first."""
    from mrfpe.samplers.base import Sampler
    from mrfpe.samplers.pmc import PMC
    from mrfpe.study import runner

    def refuse(*a, **k):
        raise AssertionError("work started before the inputs were checked")

    for cls in (Sampler, PMC):
        monkeypatch.setattr(cls, "run", refuse)
    monkeypatch.setattr(runner, "execute", refuse)


@pytest.mark.parametrize(("argv", "message"), [
    (["estimate", "{d}/scene.nc", "--out", "/nonexistent-dir-xyz/e.nc"],
     "/nonexistent-dir-xyz/e.nc: cannot write the --out posterior file: directory "
     "/nonexistent-dir-xyz does not exist"),
    (["estimate", "{d}/scene.nc", "--out", "{d}"], "is a directory"),
    (["estimate", "{d}/truncated.nc", "--out", "{d}/e.nc"],
     "truncated.nc: not a readable netCDF scene file (NetCDF: HDF error)"),
    (["estimate", "{d}/post.nc", "--out", "{d}/e.nc"], "post.nc: not a scene file"),
    (["estimate", "{d}/missing.nc", "--out", "{d}/e.nc"], "missing.nc: no such scene file"),
    (["estimate", "{d}/scene.nc", "--out", "{d}/e.nc", "--set", "n_sample=3"],
     "did you mean 'n_samples'"),
    (["estimate", "{d}/scene.nc", "--out", "{d}/e.nc", "--set", "n_samples"],
     "--set: expected key=value; got 'n_samples'"),
    (["estimate", "{d}/scene.nc", "--out", "{d}/e.nc", "--target", "nope"], "unknown target"),
    (["compare", "{d}/truncated.nc", "{d}/post.nc"],
     "truncated.nc: not a readable netCDF posterior file (NetCDF: HDF error)"),
    (["compare", "{d}/garbage.nc", "{d}/post.nc"],
     "garbage.nc: not a readable netCDF posterior file (NetCDF: Unknown file format)"),
    (["compare", "{d}/scene.nc", "{d}/post.nc"], "scene.nc: not a posterior file"),
    (["compare", "{d}/post.nc", "{d}/post.nc", "--param", "eps"],
     "--param: expected key=value; got 'eps'"),
    (["compare", "{d}/post.nc", "{d}/post.nc", "--distance", "nope"], "nope"),
    (["study", "run", "importance_sampling", "--set", "sigm=1", "--out", "{d}/s"],
     "unknown setting 'sigm' for study 'importance_sampling' (did you mean 'sigma'?)"),
    (["study", "run", "pmc_convergence", "--set", 'variants=["bogus"]', "--out", "{d}/s"],
     "'bogus' is not one of mixture, thesis2, thesis2_literal, thesis1"),
    (["study", "run", "pmc_conv", "--out", "{d}/s"], "did you mean 'pmc_convergence'"),
])
def test_bad_input_is_one_line_and_exit_2(files, argv, message, capsys, no_sampling):
    rc, err = run([a.format(d=files) for a in argv], capsys)
    assert rc == 2
    assert message.format(d=files) in err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_debug_shows_the_traceback(files):
    with pytest.raises(ValueError, match="not a readable netCDF posterior file"):
        cli.main(["--debug", "compare", str(files / "truncated.nc"), str(files / "post.nc")])


def test_version(capsys):
    from mrfpe import __version__

    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"mrfpe {__version__}"


def test_unexpected_errors_are_one_line_exit_1(monkeypatch, capsys):
    def boom(args):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(cli, "_samplers", boom)
    rc, err = run(["samplers"], capsys)
    assert rc == 1 and "internal error: RuntimeError: disk on fire" in err and "--debug" in err


def _actions(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _actions(sub)
        else:
            yield parser.prog, action


def test_every_option_has_help_text():
    missing = [f"{prog} {a.dest}" for prog, a in _actions(cli.build_parser())
               if not a.help and a.dest != "help"]
    assert missing == []


def test_study_show_lists_settings(capsys):
    assert cli.main(["study", "show", "pmc_convergence"]) == 0
    out = capsys.readouterr().out
    assert max(map(len, out.splitlines())) <= 100
    out = " ".join(out.split())  # the meanings are wrapped
    assert "variants" in out and "a grid axis" in out
    assert "one of: mixture, thesis2, thesis2_literal, thesis1" in out


def test_posterior_files_still_round_trip(files):
    P.validate(P.load(files / "post.nc"))
