"""mrfpe.netcdf: named read errors, write checks, atomic writes."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mrfpe import netcdf


def _ds():
    return xr.Dataset({"x": (("i",), np.arange(5.0))}, attrs={"k": "v"})


def test_write_atomic_then_open(tmp_path):
    path = netcdf.write_atomic(_ds(), tmp_path / "a.nc")
    xr.testing.assert_identical(netcdf.open_dataset(path, "test"), _ds())
    assert netcdf.read_attrs(path) == {"k": "v"}
    assert [p.name for p in tmp_path.iterdir()] == ["a.nc"]


def test_failed_write_leaves_nothing(tmp_path):
    bad = xr.Dataset({"x": ("i", np.array([object()], dtype=object))})
    with pytest.raises(Exception):  # noqa: B017 - whatever netCDF raises
        netcdf.write_atomic(bad, tmp_path / "a.nc")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("content", "reason"), [(b"garbage", "Unknown file format"),
                                                 ("half", "HDF error")])
def test_unreadable_files_are_named(tmp_path, content, reason):
    path = tmp_path / "f.nc"
    if content == "half":
        netcdf.write_atomic(_ds(), path)
        content = path.read_bytes()[:400]
    path.write_bytes(content)
    for read in (netcdf.open_dataset, netcdf.read_attrs):
        with pytest.raises(ValueError, match=rf"^{path}: not a readable netCDF scene file "
                                             rf"\(NetCDF: {reason}\)$"):
            read(path, "scene")


def test_checks(tmp_path):
    with pytest.raises(ValueError, match="no such posterior file"):
        netcdf.check_readable(tmp_path / "nope.nc", "posterior")
    with pytest.raises(ValueError, match="directory"):
        netcdf.check_readable(tmp_path, "posterior")
    with pytest.raises(ValueError, match="does not exist"):
        netcdf.check_writable(tmp_path / "no" / "x.nc")
    with pytest.raises(ValueError, match="is a directory"):
        netcdf.check_writable(tmp_path)
    assert netcdf.check_writable(tmp_path / "x.nc") == tmp_path / "x.nc"
    assert list(tmp_path.iterdir()) == []  # the probe is gone


def test_library_loaders_name_a_corrupt_file(tmp_path):
    """posterior.load and Scene.load read through open_dataset: a corrupt file is named."""
    from mrfpe import posterior as P
    from mrfpe.brdf.scene import Scene

    bad = tmp_path / "bad.nc"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"0" * 100)
    with pytest.raises(ValueError, match=r"bad\.nc: not a readable netCDF posterior"):
        P.load(bad)
    with pytest.raises(ValueError, match=r"bad\.nc: not a readable netCDF scene"):
        Scene.load(bad)


def _scene():
    from mrfpe.brdf.synthetic import make_scene

    return make_scene(brdf="ward", theta=[0.3, 0.2, 0.1], shape=(6, 6), n_labels=3, seed=0)


def _savers():
    """Every writer of netCDF files: each goes through write_atomic's path check."""
    from mrfpe import posterior as P

    post = P.build(np.random.default_rng(0).random((400, 2)), np.zeros(400),
                   param_names=["a", "b"], sampler="t")
    return {"posterior": lambda p: P.save(post, p), "scene": lambda p: _scene().save(p),
            "output": lambda p: netcdf.write_atomic(_ds(), p)}


@pytest.mark.parametrize("what", ["posterior", "scene", "output"])
def test_writers_refuse_special_files_and_missing_directories(tmp_path, what):
    save = _savers()[what]
    fifo = tmp_path / "pipe.nc"
    os.mkfifo(fifo)
    (tmp_path / "dir.nc").mkdir()
    (tmp_path / "file").write_text("x")
    cases = {
        fifo: rf"{what} path is a named pipe, not a regular file; refusing to replace it",
        tmp_path / "dir.nc": rf"{what} path is a directory; expected a file name",
        tmp_path / "no" / "a.nc": rf"cannot write the {what} file: directory {tmp_path}/no "
                                  "does not exist",
        tmp_path / "file" / "a.nc": rf"cannot write the {what} file: {tmp_path}/file is not a "
                                    "directory",
    }
    before = sorted((p.name, stat.S_IFMT(p.lstat().st_mode)) for p in tmp_path.iterdir())
    for path, message in cases.items():
        with pytest.raises(ValueError, match=rf"^{path}: {message}$"):
            save(path)
    assert sorted((p.name, stat.S_IFMT(p.lstat().st_mode))
                  for p in tmp_path.iterdir()) == before
    assert (tmp_path / "file").read_text() == "x" and not any((tmp_path / "dir.nc").iterdir())


def test_a_device_node_is_refused(tmp_path):
    """A device node made here (as root), else /dev/null: never replaced by a file."""
    dev = tmp_path / "null"
    try:
        os.mknod(dev, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except (PermissionError, OSError):
        dev = Path("/dev/null")
    with pytest.raises(ValueError, match=rf"^{dev}: output path is a character device"):
        netcdf.write_atomic(_ds(), dev)
    assert stat.S_ISCHR(dev.stat().st_mode)


def test_no_room_for_an_empty_file_is_a_full_disk(tmp_path, monkeypatch):
    """check_writable's probe on a full disk: DiskFullError (exit 1), not a usage error."""
    real_open = os.open

    def full(path, *args, **kw):
        if str(path).endswith(netcdf.TMP_SUFFIX):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_open(path, *args, **kw)

    monkeypatch.setattr(os, "open", full)
    with pytest.raises(netcdf.DiskFullError, match=rf"^{tmp_path}/a.nc: no space left"):
        netcdf.check_writable(tmp_path / "a.nc", "posterior")


def test_scene_load_refuses_a_posterior_naming_what_it_holds(tmp_path):
    from mrfpe import posterior as P

    path = tmp_path / "post.nc"
    _savers()["posterior"](path)
    with pytest.raises(ValueError) as info:
        _scene().load(path)
    assert str(info.value) == (f"{path}: not a scene file (written by Scene.save / mrfpe "
                               "demo): it holds a posterior (written by mrfpe estimate / "
                               "posterior.save)")
    P.load(path)


def test_expect_sees_the_file_before_its_data_and_its_error_passes_unchanged(tmp_path):
    path = netcdf.write_atomic(_ds(), tmp_path / "a.nc")
    seen = []

    def expect(ds):
        seen.append((list(ds.data_vars), dict(ds.attrs), ds["x"].variable._in_memory))
        raise ValueError("wrong kind")

    with pytest.raises(ValueError, match=r"^wrong kind$"):
        netcdf.open_dataset(path, "test", expect=expect)
    assert seen == [(["x"], {"k": "v"}, False)]  # the data was not read
    assert netcdf.describe_contents(_ds()) == "the variables x"
    assert netcdf.describe_contents(xr.Dataset()) == "no variables"
