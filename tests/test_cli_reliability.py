"""Nothing lost, nothing silently wrong, through the command line.

Each test feeds the command line an input that once lost data, printed a wrong
number or crashed after the work; the outcome now is one line naming the
argument or file, or a correct run, with nothing overwritten that was not meant
to be.
"""

from __future__ import annotations

import errno
import re
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import mrfpe.samplers as samplers
from mrfpe import cli
from mrfpe import posterior as P

from . import _processes as procs


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from mrfpe.brdf.synthetic import make_scene

    d = tmp_path_factory.mktemp("rel")
    make_scene(brdf="ward", theta=[0.3, 0.2, 0.1], shape=(8, 8), n_labels=4,
               seed=0).save(d / "scene.nc")
    return d / "scene.nc"


QUICK = ["--quiet", "--set", "n_samples=16", "--set", "n_iterations=2"]


def run(argv, capsys):
    rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err.strip()


def test_out_equal_to_the_input_is_refused(scene, capsys):
    before = scene.read_bytes()
    rc, err = run(["estimate", scene, "--out", scene, *QUICK], capsys)
    assert rc == 2 and "is the input file" in err and err.count("\n") == 0
    assert scene.read_bytes() == before


def test_out_that_is_not_a_posterior_is_kept_unless_forced(scene, tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    rc, err = run(["estimate", scene, "--out", notes, *QUICK], capsys)
    assert rc == 2 and "not a posterior file" in err and "--force" in err
    assert notes.read_text() == "my notes\n"
    assert run(["estimate", scene, "--out", notes, *QUICK, "--force"], capsys)[0] == 0
    P.validate(P.load(notes))
    # an existing posterior is replaced without --force: that is what --out asks for
    assert run(["estimate", scene, "--out", notes, *QUICK, "--seed", "1"], capsys)[0] == 0


@pytest.mark.parametrize("seed", [2**64, 2**63, -1])
def test_seed_out_of_range_is_refused_before_the_run(scene, tmp_path, capsys, seed):
    rc, err = run(["estimate", scene, "--out", tmp_path / "p.nc", *QUICK, "--seed", seed],
                  capsys)
    assert rc == 2 and "--seed must be an integer in [0, 2**63 - 1]" in err
    assert not (tmp_path / "p.nc").exists()


def test_seed_at_the_top_of_the_range_is_saved(scene, tmp_path, capsys):
    assert run(["estimate", scene, "--out", tmp_path / "p.nc", *QUICK, "--seed", 2**63 - 1],
               capsys)[0] == 0
    assert P.load(tmp_path / "p.nc").attrs["seed"] == 2**63 - 1


@pytest.mark.parametrize(("sampler", "key"), [("pmc", "n_samples"), ("mh", "n_steps"),
                                              ("emcee", "n_steps")])
def test_oversized_settings_fail_on_the_memory_budget(scene, tmp_path, capsys, sampler, key):
    t0 = time.perf_counter()
    rc, err = run(["estimate", scene, "--out", tmp_path / "p.nc", "--quiet", "--sampler",
                   sampler, "--set", f"{key}=1000000000000"], capsys)
    assert rc == 2 and "more than the memory budget" in err and f"sampler {sampler}" in err
    assert time.perf_counter() - t0 < 10


class Foreign:
    """Returns a Dataset that is not a posterior."""

    def run(self, target, *, seed=None, progress=False, callback=None):
        return xr.Dataset({"x": ("i", np.arange(3.0))})


class NaNTheta:
    """Returns a posterior-shaped Dataset of NaN samples."""

    def run(self, target, *, seed=None, progress=False, callback=None):
        post = P.build(np.full((4, 3), 0.5), np.zeros(4), param_names=target.param_names,
                       sampler="nan", config={}, seed=seed)
        post["theta"][:] = np.nan
        post["map_theta"][:] = np.nan
        return post


@pytest.mark.parametrize(("cls", "message"), [(Foreign, "lacks the variable 'theta'"),
                                              (NaNTheta, "theta contains NaN")])
def test_a_plugin_result_is_checked_before_it_is_written(scene, tmp_path, capsys, cls,
                                                         message):
    samplers.registry.register("bad_result", cls)
    try:
        rc, err = run(["estimate", scene, "--out", tmp_path / "p.nc", "--quiet", "--sampler",
                       "bad_result"], capsys)
    finally:
        samplers.registry.unregister("bad_result")
    assert rc == 2 and "sampler 'bad_result' returned an invalid posterior" in err
    assert message in err and "MAP" not in err
    assert not (tmp_path / "p.nc").exists()


def test_disk_full_names_the_file_and_leaves_nothing(scene, tmp_path, capsys, monkeypatch):
    def full(self, path, **kw):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", full)
    rc, err = run(["estimate", scene, "--out", tmp_path / "p.nc", *QUICK], capsys)
    assert rc == 1 and err.count("\n") == 0
    assert f"{tmp_path}/p.nc: no space left on the device to write the posterior file" in err
    assert "internal error" not in err and list(tmp_path.iterdir()) == []


def _tmpfs(tmp_path: Path, size: str) -> Path:
    """A small tmpfs mounted at tmp_path/fs; skips where mounting needs a privilege."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = procs.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", mnt], timeout=60,
                  check=False)
    if r.returncode:
        pytest.skip("cannot mount a tmpfs here (needs root); ENOSPC is simulated elsewhere")
    return mnt


def test_disk_full_on_a_real_small_tmpfs(scene, tmp_path, capsys):
    mnt = _tmpfs(tmp_path, "256k")
    try:
        (mnt / "scene.nc").write_bytes(scene.read_bytes())
        with open(mnt / "fill", "wb") as f:  # fill what is left
            with pytest.raises(OSError):
                f.write(b"\0" * (1 << 20))
        rc, err = run(["estimate", mnt / "scene.nc", "--out", mnt / "p.nc", *QUICK], capsys)
        assert rc == 1 and "no space left on the device" in err and f"{mnt}/p.nc" in err
        assert sorted(p.name for p in mnt.iterdir()) == ["fill", "scene.nc"]
    finally:
        procs.run(["umount", mnt], timeout=60, check=False)


def test_relative_paths_are_not_mangled(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("s.nc").write_text("garbage")
    rc, err = run(["estimate", "s.nc", "--out", "p.nc", *QUICK], capsys)
    assert rc == 2
    assert err == ("mrfpe estimate: error: s.nc: not a readable netCDF scene file "
                   "(NetCDF: Unknown file format)")


def test_a_device_is_not_called_a_directory(tmp_path, capsys):
    rc, err = run(["compare", "/dev/zero", "/dev/zero"], capsys)
    assert rc == 2 and "/dev/zero: expected a netCDF posterior file, found a character device" \
        in err


def test_real_sigint_stops_estimate_promptly_and_leaves_no_file(scene, tmp_path):
    """A real Ctrl-C (SIGINT to the process) once the sampler runs: exit 130, one line,
    no partial or temporary file."""
    out = tmp_path / "p.nc"
    # Child starts it with SIGINT at its default even where this run ignores it (a
    # background job), and bounds every wait: the run left alone takes minutes
    with procs.Child([sys.executable, "-m", "mrfpe", "estimate", scene, "--out", out, "--set",
                      "n_samples=4000", "--set", "n_iterations=10000"], cwd=tmp_path) as p:
        # past the first iteration: until then numba and lazy imports run exec'd strings,
        # and a KeyboardInterrupt out of one makes ``python -m`` exit by SIGINT (-2) though
        # main returned 130 (CPython's unhandled-interrupt flag, not the command's doing)
        p.wait_for("stderr", lambda err: re.search(r"\b[1-9]\d*/\d+ \[", err),
                   "a progress bar past the first iteration")
        t0 = time.perf_counter()
        p.send_signal(signal.SIGINT)
        rc = p.finish(timeout=30)
        elapsed = time.perf_counter() - t0
    assert rc == 130 and p.stderr.rstrip().endswith("mrfpe estimate: interrupted"), p.stderr
    assert elapsed < 5
    assert list(tmp_path.iterdir()) == []


# -- the argument space, fuzzed ------------------------------------------------------------

_WORDS = st.sampled_from(["estimate", "compare", "--out", "--set", "--seed", "--sampler",
                          "--target", "--param", "--distance", "--force", "--quiet",
                          "n_samples=3", "n_samples=-1", "n_samples=1e400", "seed=2",
                          "pmc", "nope", "mh", "kl", "emd", "-1", "18446744073709551616",
                          "{scene}", "{post}", "{dir}", "{dir}/x.nc", "/dev/null", "",
                          "n_projections=0", "x=[1,", "n_samples=null"])


@settings(max_examples=150, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(_WORDS, min_size=1, max_size=8))
def test_property_cli_never_crashes_or_touches_its_inputs(scene, tmp_path_factory, capsys,
                                                         monkeypatch, words):
    """Any argument list: exit 0, 1, 2 or argparse's exit; never a traceback, an internal
    error or a changed input. Sampling is stubbed to a valid posterior (the front matter
    is what is fuzzed)."""
    import mrfpe

    d = tmp_path_factory.mktemp("cli")
    post = d / "post.nc"
    post.write_bytes(_posterior_bytes())
    inputs = {p: p.read_bytes() for p in (scene, post)}
    monkeypatch.setattr(mrfpe, "sample", lambda *a, **k: P.load(post))
    argv = [w.format(scene=scene, post=post, dir=d) for w in words]
    try:
        rc = cli.main(argv)
    except SystemExit as exc:  # argparse: usage errors exit 2, --help 0
        rc = exc.code
    err = capsys.readouterr().err
    assert rc in (0, 1, 2), (argv, rc, err)
    assert "internal error" not in err and "Traceback" not in err, (argv, err)
    assert all(p.read_bytes() == b for p, b in inputs.items()), argv


_POST_BYTES: list[bytes] = []


def _posterior_bytes() -> bytes:
    if not _POST_BYTES:
        import tempfile
        import warnings

        rng = np.random.default_rng(0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", P.PosteriorWarning)
            post = P.build(rng.random((30, 3)), rng.normal(size=30), param_names=["a", "b", "c"],
                           sampler="pmc", config={}, seed=0, target={"class": "T"})
        with tempfile.TemporaryDirectory() as tmp:
            P.save(post, Path(tmp) / "p.nc")
            _POST_BYTES.append((Path(tmp) / "p.nc").read_bytes())
    return _POST_BYTES[0]
