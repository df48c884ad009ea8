"""A content checksum inside every netCDF file mrfpe writes.

HDF5 keeps checksums on some of its metadata but none on the data: a flipped
bit in a variable, or a spliced block that happens to parse, loads without an
error. :func:`stamp` adds a SHA-256 of the file's whole content (dimensions,
variables with their types, shapes, attributes and raw values, the global
attributes) as the global attribute :data:`ATTR`; :func:`verify` recomputes it
and raises when it differs. Files written before checksums existed carry none
and are accepted as they are.

A leaf module (numpy, netCDF4 and hashlib only): :mod:`mrfpe.netcdf` calls it
on every write and every read.
"""

from __future__ import annotations

import hashlib
import os
from typing import Any

import numpy as np

__all__ = ["ATTR", "ChecksumError", "digest", "stamp", "verify"]

#: The global attribute holding ``"sha256:<hex>"``.
ATTR = "mrfpe_checksum"
_ALGORITHM = "sha256"


class ChecksumError(ValueError):
    """A file's content does not match the checksum stored in it."""


def _feed_value(h: Any, value: Any) -> None:
    """Hash one attribute value or variable's data, type included (1 and 1.0 differ)."""
    a = np.asarray(value)
    if a.dtype.kind in "OUS":  # strings (netCDF vlen or char): their UTF-8 bytes, lengths first
        items = [x.decode("utf-8", "surrogateescape") if isinstance(x, bytes) else str(x)
                 for x in a.reshape(-1)]
        h.update(f"str{a.shape}".encode())
        for s in items:
            b = s.encode("utf-8", "surrogatepass")
            h.update(len(b).to_bytes(8, "little") + b)
        return
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(np.ascontiguousarray(a).tobytes())


def _feed_attrs(h: Any, obj: Any, skip: str = "") -> None:
    for name in sorted(obj.ncattrs()):
        if name == skip:
            continue
        h.update(b"\x00attr:" + name.encode())
        _feed_value(h, obj.getncattr(name))


def digest(nc: Any) -> str:
    """``"sha256:<hex>"`` of an open ``netCDF4.Dataset``'s content, :data:`ATTR` excluded."""
    h = hashlib.new(_ALGORITHM)

    def group(g: Any, path: str) -> None:
        h.update(f"\x00group:{path}".encode())
        for name in sorted(g.dimensions):
            h.update(f"\x00dim:{name}={len(g.dimensions[name])}".encode())
        _feed_attrs(h, g, skip=ATTR if path == "/" else "")
        for name in sorted(g.variables):
            var = g.variables[name]
            var.set_auto_maskandscale(False)
            var.set_auto_chartostring(False)
            h.update(f"\x00var:{name}:{var.dtype}:{var.dimensions}".encode())
            _feed_attrs(h, var)
            _feed_value(h, var[...])
        for name in sorted(g.groups):
            group(g.groups[name], f"{path}{name}/")

    group(nc, "/")
    return f"{_ALGORITHM}:{h.hexdigest()}"


def stamp(path: str | os.PathLike) -> str:
    """Compute the checksum of the netCDF file at ``path`` and store it in the file."""
    import netCDF4

    with netCDF4.Dataset(path, "r+") as nc:
        value = digest(nc)
        nc.setncattr(ATTR, value)
    return value


def verify(nc: Any, where: str) -> bool:
    """Check an open ``netCDF4.Dataset`` against its stored checksum.

    Returns ``False`` when the file carries no checksum (written before
    checksums existed), ``True`` when it matches.

    Raises
    ------
    ChecksumError
        ``"<where>: damaged file: its content does not match the checksum stored
        in it ..."`` when it does not match (or the stored value is not one).
    """
    if ATTR not in nc.ncattrs():
        return False
    stored = nc.getncattr(ATTR)
    actual = digest(nc)
    if stored != actual:
        raise ChecksumError(f"{where}: damaged file: its content does not match the checksum "
                            f"stored in it (the file was changed or corrupted after it was "
                            f"written)")
    return True
