"""netCDF files in and out, with errors that name the file and what was expected.

A leaf module (numpy, xarray, netCDF4 only): the command line, the study
runner, :func:`mrfpe.posterior.load` and :meth:`mrfpe.scene.Scene.load` read
through :func:`open_dataset`, so a truncated or corrupt file gives one line --
``run.nc: not a readable netCDF posterior file (NetCDF: HDF error)`` -- instead
of a bare ``OSError: HDF error`` from deep inside the HDF5 library.
:func:`write_atomic` never leaves a partial file under the final name.
"""

from __future__ import annotations

import os
import re
import uuid
from pathlib import Path
from typing import Any

import xarray as xr

__all__ = ["TMP_SUFFIX", "check_readable", "check_writable", "open_dataset", "read_attrs",
           "tmp_path_for", "write_atomic"]

#: Temporary files are ``.<name>.<8 hex>.tmp`` beside their target (same file system,
#: so ``os.replace`` is atomic); a run killed mid-write leaves only such a file behind.
TMP_SUFFIX = ".tmp"

# "[Errno -101] NetCDF: HDF error: '/x/y.nc'" -> "NetCDF: HDF error"
_ERRNO = re.compile(r"^\[Errno -?\d+\]\s*")


def _reason(exc: BaseException, path: Path) -> str:
    text = str(exc).strip() or type(exc).__name__
    text = _ERRNO.sub("", text)
    for form in (f": '{path}'", f": {path!s}", f" '{path}'", str(path)):
        text = text.replace(form, "")
    return text.strip(" :") or type(exc).__name__


def _unreadable(path: Path, what: str, exc: BaseException) -> ValueError:
    return ValueError(f"{path}: not a readable netCDF {what} file ({_reason(exc, path)})")


def check_readable(path: str | os.PathLike, what: str = "input") -> Path:
    """``path`` as a :class:`Path` if it is an existing, readable file; else ``ValueError``.

    Cheap (no netCDF parsing): for checking every input before expensive work.
    """
    p = Path(path)
    if not p.exists():
        raise ValueError(f"{p}: no such {what} file")
    if not p.is_file():
        raise ValueError(f"{p}: expected a netCDF {what} file, found a directory")
    if not os.access(p, os.R_OK):
        raise ValueError(f"{p}: {what} file is not readable (permission denied)")
    return p


def check_writable(path: str | os.PathLike, what: str = "output") -> Path:
    """``path`` as a :class:`Path` if a file can be created there; else ``ValueError``.

    The parent directory must exist (it is not created) and accept a new file:
    the check creates and removes an empty temporary file, so permission and
    read-only file systems are caught before any work, not after it.
    """
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{p}: {what} path is a directory; expected a file name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"{p}: cannot write the {what} file: directory {parent} does not exist")
    probe = tmp_path_for(p)
    try:
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except OSError as exc:
        raise ValueError(f"{p}: cannot write the {what} file ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return p


def open_dataset(path: str | os.PathLike, what: str = "data", **kwargs: Any) -> xr.Dataset:
    """Read a netCDF file fully into memory (the file is closed on return).

    ``kwargs`` go to :func:`xarray.open_dataset` (engine ``netcdf4`` unless
    given). A missing, truncated or corrupt file raises ``ValueError(f"{path}:
    not a readable netCDF {what} file (reason)")``: the HDF5 error surfaces
    while opening *or* while reading the data, so both are covered.
    """
    p = check_readable(path, what)
    kwargs.setdefault("engine", "netcdf4")
    try:
        with xr.open_dataset(p, **kwargs) as f:
            return f.load()
    except (OSError, RuntimeError, KeyError, IndexError, ValueError) as exc:
        # netCDF4 raises OSError (HDF errors) or RuntimeError (NetCDF: ...); xarray's
        # decoders a ValueError/KeyError on garbage metadata. All mean: not this file.
        raise _unreadable(p, what, exc) from exc


def read_attrs(path: str | os.PathLike, what: str = "data") -> dict[str, Any]:
    """The global attributes of a netCDF file (netCDF4 directly: ~10× faster than xarray).

    Raises ``ValueError`` as :func:`open_dataset` does. Only the header is read:
    a file truncated in its data may pass; :func:`open_dataset` catches it.
    """
    import netCDF4

    p = check_readable(path, what)
    try:
        with netCDF4.Dataset(p) as nc:
            return {k: nc.getncattr(k) for k in nc.ncattrs()}
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        raise _unreadable(p, what, exc) from exc


def tmp_path_for(path: str | os.PathLike) -> Path:
    """A fresh temporary name beside ``path``: ``.<name>.<8 hex>.tmp``."""
    p = Path(path)
    return p.with_name(f".{p.name}.{uuid.uuid4().hex[:8]}{TMP_SUFFIX}")


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - e.g. platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def write_atomic(ds: xr.Dataset, path: str | os.PathLike, **kwargs: Any) -> Path:
    """Write ``ds`` to ``path`` so that ``path`` is either absent, old, or complete.

    Writes a temporary file beside it, ``fsync``s it, then ``os.replace``s it
    over ``path`` (and syncs the directory): a kill or power loss mid-write
    leaves at most a ``*.tmp`` file, never a partial ``path``. ``kwargs`` go to
    :meth:`xarray.Dataset.to_netcdf` (engine ``netcdf4`` unless given).
    """
    p = Path(path)
    kwargs.setdefault("engine", "netcdf4")
    tmp = tmp_path_for(p)
    try:
        ds.to_netcdf(tmp, **kwargs)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, p)
        _fsync_dir(p.parent)
    finally:
        if tmp.exists():
            tmp.unlink()
    return p
