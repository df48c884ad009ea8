"""mrfpe.netcdf: named read errors, write checks, atomic writes."""

from __future__ import annotations

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
