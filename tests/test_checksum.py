"""Content checksums in written netCDF files, and the readers on damaged files (fuzzed)."""

from __future__ import annotations

import errno
import warnings
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrfpe import checksum, netcdf
from mrfpe import posterior as P
from mrfpe.brdf.scene import Scene

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def _post():
    rng = np.random.default_rng(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", P.PosteriorWarning)
        return P.build(rng.random((40, 3)), rng.normal(size=40), param_names=["a", "b", "c"],
                       log_weight=rng.normal(size=40), sampler="t", config={"n": 40}, seed=3,
                       target={"class": "T"})


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A posterior and a scene written by mrfpe, with their bytes."""
    from mrfpe.brdf.synthetic import make_scene

    d = tmp_path_factory.mktemp("written")
    P.save(_post(), d / "post.nc")
    make_scene(brdf="ward", theta=[0.3, 0.2, 0.1], shape=(6, 6), n_labels=3,
               seed=0).save(d / "scene.nc")
    return {name: (d / f"{name}.nc").read_bytes() for name in ("post", "scene")}


def test_every_written_file_is_sealed_and_reads_as_before(tmp_path):
    path = tmp_path / "p.nc"
    P.save(_post(), path)
    data = path.read_bytes()
    assert data[-checksum.TRAILER_BYTES:].startswith(checksum.PREFIX)
    assert checksum.verify(path)
    with netCDF4.Dataset(path) as nc:  # HDF5 ignores the bytes after its end of file
        assert "sampler" in nc.ncattrs()
    xr.testing.assert_identical(P.load(path), _post())
    xr.open_dataset(path).load()  # plain xarray too


def test_a_changed_value_is_refused_naming_the_file(tmp_path):
    """The audit's case: a flipped data value loads silently without a checksum."""
    path = tmp_path / "p.nc"
    post = _post()
    P.save(post, path)
    data = path.read_bytes()
    value = np.float64(post["theta"].values[0, 0]).tobytes()
    assert data.count(value) >= 1
    path.write_bytes(data.replace(value, np.float64(0.5).tobytes(), 1))  # HDF5 cannot notice
    for read in (P.load, netcdf.read_attrs, lambda p: netcdf.open_dataset(p, "posterior")):
        with pytest.raises(ValueError, match=rf"^{path}: damaged file"):
            read(path)


def test_a_damaged_trailer_is_refused(tmp_path):
    path = tmp_path / "p.nc"
    P.save(_post(), path)
    data = path.read_bytes()
    path.write_bytes(data[:-10] + b"x" * 10)
    with pytest.raises(ValueError, match=rf"^{path}: damaged file"):
        P.load(path)


def test_files_without_a_checksum_still_load(tmp_path):
    """Files of earlier versions (no checksum) are accepted; the committed results too."""
    path = tmp_path / "old.nc"
    xr.Dataset({"x": ("i", np.arange(3.0))}, attrs={"k": "v"}).to_netcdf(path)
    assert netcdf.read_attrs(path) == {"k": "v"}
    committed = sorted(RESULTS.glob("**/trials/*.nc"))[:3]
    for p in committed:
        netcdf.open_dataset(p, "trial")


def _damage(data: bytes, kind: str, pos: float, length: int, byte: int) -> bytes:
    i = int(pos * (len(data) - 1))
    if kind == "truncate":
        return data[:i]
    if kind == "flip":
        return data[:i] + bytes([data[i] ^ (1 << (byte % 8))]) + data[i + 1:]
    if kind == "splice":  # a block overwritten with copies of another part of the file
        j = (i + length * 7) % max(1, len(data) - length)
        return data[:i] + data[j:j + length] + data[i + length:]
    return bytes(byte for _ in range(length))  # "random": not a netCDF file at all


@settings(max_examples=200, deadline=None, derandomize=True,  # the same 200 files in CI
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["truncate", "flip", "splice", "random"]),
       pos=st.floats(0, 1), length=st.integers(1, 512), byte=st.integers(0, 255),
       which=st.sampled_from(["post", "scene"]))
def test_property_damaged_files_are_refused_or_unchanged(written, tmp_path_factory, kind, pos,
                                                         length, byte, which):
    """Every reader either refuses a damaged file with a ValueError naming it, or returns
    exactly what was written (a change in unused bytes): never different data."""
    original = written[which]
    path = tmp_path_factory.mktemp("fuzz") / f"{which}.nc"
    path.write_bytes(_damage(original, kind, pos, length, byte))
    clean = path.with_name("clean.nc")
    clean.write_bytes(original)
    if which == "post":
        readers = [P.load, netcdf.read_attrs]
        compare = [lambda a, b: xr.testing.assert_identical(a, b), lambda a, b: a == b]
    else:
        readers = [Scene.load, lambda p: netcdf.open_dataset(p, "scene")]
        compare = [lambda a, b: xr.testing.assert_identical(a.to_dataset(), b.to_dataset()),
                   lambda a, b: xr.testing.assert_identical(a, b)]
    for read, same in zip(readers, compare):
        try:
            got = read(path)
        except ValueError as exc:
            assert str(exc).startswith(str(path)), exc
            continue
        same(got, read(clean))


def test_disk_full_is_named_and_leaves_nothing(tmp_path, monkeypatch):
    """The netCDF library says "HDF error"; mrfpe names the file and the full disk."""
    def full(self, path, **kw):
        Path(path).write_bytes(b"\x89HDF partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", full)
    with pytest.raises(netcdf.DiskFullError, match=rf"^{tmp_path}/p.nc: no space left on the "
                                                    "device to write the posterior file"):
        P.save(_post(), tmp_path / "p.nc")
    assert list(tmp_path.iterdir()) == []


def test_hdf_error_on_a_full_file_system_is_named(tmp_path, monkeypatch):
    """No errno (HDF5's way): the free space decides."""
    def hdf_error(self, path, **kw):
        raise RuntimeError("NetCDF: HDF error")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", hdf_error)
    monkeypatch.setattr(netcdf, "_free_bytes", lambda d: 0)
    with pytest.raises(netcdf.DiskFullError, match="no space left"):
        netcdf.write_atomic(_post(), tmp_path / "p.nc")
    monkeypatch.setattr(netcdf, "_free_bytes", lambda d: 1 << 40)
    with pytest.raises(RuntimeError, match="HDF error"):  # plenty of space: not a full disk
        netcdf.write_atomic(_post(), tmp_path / "p.nc")


def _sealed_small(tmp_path: Path) -> Path:
    path = tmp_path / "small.nc"
    netcdf.write_atomic(xr.Dataset({"x": ("i", np.arange(4.0))}), path)
    return path


def test_every_single_byte_change_in_the_trailer_is_refused(tmp_path):
    """Exhaustive: each of the trailer's bytes set to each of its 255 other values.

    The audit's case: one flipped byte of the marker made a sealed file read as
    unsealed, so damaged data behind it loaded unchecked.
    """
    path = _sealed_small(tmp_path)
    data = path.read_bytes()
    start = len(data) - checksum.TRAILER_BYTES
    passed = []
    with open(path, "r+b") as f:
        for i in range(start, len(data)):
            for value in range(256):
                if value == data[i]:
                    continue
                f.seek(i)
                f.write(bytes([value]))
                f.flush()
                try:
                    checksum.verify(path)
                    passed.append((i - start, value))
                except checksum.ChecksumError as exc:
                    assert str(exc).startswith(f"{path}: damaged file"), exc
            f.seek(i)
            f.write(data[i:i + 1])
    assert passed == []
    assert checksum.verify(path)  # restored: sealed and intact


@pytest.mark.parametrize("where", range(len(checksum.PREFIX)))
def test_a_damaged_marker_does_not_let_a_changed_value_through(tmp_path, where):
    """The audit's exact case through every reader: a value changed *and* one byte of
    the trailer's marker flipped (the lowest bit, e.g. ``m`` -> ``l``)."""
    path = tmp_path / "p.nc"
    post = _post()
    P.save(post, path)
    data = bytearray(path.read_bytes())
    value = np.float64(post["theta"].values[0, 0]).tobytes()
    at = data.index(value)
    data[at:at + 8] = np.float64(0.5).tobytes()
    data[len(data) - checksum.TRAILER_BYTES + where] ^= 1
    path.write_bytes(bytes(data))
    for read in (P.load, netcdf.read_attrs, lambda p: netcdf.open_dataset(p, "posterior")):
        with pytest.raises(ValueError, match=rf"^{path}: damaged file: its checksum trailer"):
            read(path)


def test_files_sealed_by_earlier_versions_still_load(tmp_path):
    """The trailer's format is unchanged: one appended by hand, as earlier versions did,
    reads; so does an unsealed file."""
    import hashlib

    path = tmp_path / "old.nc"
    _post().to_netcdf(path)
    unsealed = path.read_bytes()
    assert checksum.verify(path) is False
    netcdf.read_attrs(path)
    sealed = unsealed + b"\nmrfpe-sha256:" + hashlib.sha256(unsealed).hexdigest().encode() + b"\n"
    path.write_bytes(sealed)
    assert checksum.verify(path) is True
    P.load(path)


@pytest.mark.parametrize("tail", [
    b"\n" + b"0123456789abcdef" * 4 + b"\n",  # a digest without a marker
    b"\nmrfpe-sXXXXX:" + b"0" * 64 + b"\n",  # the marker five bytes away
    b"\0" * checksum.TRAILER_BYTES,
])
def test_ends_far_from_a_trailer_are_unsealed(tmp_path, tail):
    """Where recognition stops: bytes after HDF5's end of file that are not within
    ``MARKER_SLACK`` bytes of a marker leave a file unsealed, as other programs write it."""
    path = tmp_path / "other.nc"
    xr.Dataset({"x": ("i", np.arange(3.0))}).to_netcdf(path)
    path.write_bytes(path.read_bytes() + tail)
    assert checksum.verify(path) is False
    np.testing.assert_array_equal(netcdf.open_dataset(path)["x"].values, np.arange(3.0))


def test_a_marker_four_bytes_away_is_a_damaged_trailer(tmp_path):
    """The other side of the boundary: ``MARKER_SLACK`` changed bytes are still a trailer."""
    assert checksum.MARKER_SLACK == 4
    path = _sealed_small(tmp_path)
    data = path.read_bytes()
    tail = b"\nmrfpe-shXXXX:" + data[-65:]
    path.write_bytes(data[:-checksum.TRAILER_BYTES] + tail)
    with pytest.raises(checksum.ChecksumError, match=rf"^{path}: damaged file"):
        checksum.verify(path)
