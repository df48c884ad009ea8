"""netCDF files in and out, with errors that name the file and what was expected.

A leaf module (numpy, xarray, netCDF4 only): the command line, the study
runner, :func:`mrfpe.posterior.load` and :meth:`mrfpe.brdf.scene.Scene.load` read
through :func:`open_dataset`, so a truncated or corrupt file gives one line --
``run.nc: not a readable netCDF posterior file (NetCDF: HDF error)`` -- instead
of a bare ``OSError: HDF error`` from deep inside the HDF5 library.
:func:`write_atomic` refuses a path it must not replace (a directory, a named pipe,
a device) or cannot write (a missing directory) before writing anything, never
leaves a partial file under the final name, seals every file with a checksum of
its bytes (:mod:`mrfpe.checksum`) that every reader verifies before parsing, and
names a full disk as such (:class:`DiskFullError`).
"""

from __future__ import annotations

import errno
import os
import re
import stat
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import xarray as xr

from mrfpe.checksum import ChecksumError, stamp, verify

__all__ = ["TMP_SUFFIX", "ChecksumError", "DiskFullError", "check_readable", "check_writable",
           "describe_contents", "disk_full", "open_dataset", "read_attrs", "tmp_path_for",
           "write_atomic", "write_text_atomic"]


class DiskFullError(OSError):
    """A write failed because the file system is full (``errno.ENOSPC``), with the path named."""

    def __init__(self, message: str):
        super().__init__(errno.ENOSPC, message)

    def __str__(self) -> str:
        return str(self.strerror)


def _free_bytes(directory: Path) -> int | None:
    try:
        st = os.statvfs(directory)
    except OSError:  # pragma: no cover - e.g. platforms without statvfs
        return None
    return st.f_bavail * st.f_frsize


def disk_full(exc: BaseException, path: str | os.PathLike, what: str,
              needed: int = 0) -> DiskFullError | None:
    """A :class:`DiskFullError` naming ``path`` if ``exc`` came from a full disk, else ``None``.

    The HDF5 library reports a full disk as a bare "HDF error", without ``errno``:
    then the free space of ``path``'s file system decides (less than ``needed``
    bytes plus 1 MiB left means the write could not fit).
    """
    if isinstance(exc, DiskFullError):
        return exc
    p = Path(path)
    free = _free_bytes(p.parent if str(p.parent) else Path("."))
    full = getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT) or (
        isinstance(exc, OSError | RuntimeError) and free is not None
        and free < needed + (1 << 20))
    if not full:
        return None
    left = "" if free is None else f", {free} bytes free"
    return DiskFullError(f"{p}: no space left on the device to write the {what} file{left}; "
                         "free some space and run again")

#: Temporary files are ``.<name>.<8 hex>.tmp`` beside their target (same file system,
#: so ``os.replace`` is atomic); a run killed mid-write leaves only such a file behind.
TMP_SUFFIX = ".tmp"

# "[Errno -101] NetCDF: HDF error: '/x/y.nc'" -> "NetCDF: HDF error"
_ERRNO = re.compile(r"^\[Errno -?\d+\]\s*")


def _reason(exc: BaseException, path: Path) -> str:
    text = str(exc).strip() or type(exc).__name__
    text = _ERRNO.sub("", text)
    # the libraries quote the path, relative or made absolute: drop whole quoted forms
    # only (a bare replace of "s.nc" would leave "/abs/dir/" behind)
    forms = {str(path), os.path.abspath(path), str(path.resolve())}
    for form in sorted(forms, key=len, reverse=True):
        for quoted in (f": '{form}'", f" '{form}'", f": {form}"):
            if text.endswith(quoted):
                text = text[: -len(quoted)]
    return text.strip(" :") or type(exc).__name__


def _unreadable(path: Path, what: str, exc: BaseException) -> ValueError:
    return ValueError(f"{path}: not a readable netCDF {what} file ({_reason(exc, path)})")


def _kind(p: Path) -> str:
    """What ``p`` is, in words, when it is not a regular file."""
    mode = p.stat().st_mode
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a named pipe"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "no regular file"  # pragma: no cover


def check_readable(path: str | os.PathLike, what: str = "input") -> Path:
    """``path`` as a :class:`Path` if it is an existing, readable file; else ``ValueError``.

    Cheap (no netCDF parsing): for checking every input before expensive work.
    """
    p = Path(path)
    if not p.exists():
        raise ValueError(f"{p}: no such {what} file")
    if not p.is_file():
        raise ValueError(f"{p}: expected a netCDF {what} file, found {_kind(p)}")
    if not os.access(p, os.R_OK):
        raise ValueError(f"{p}: {what} file is not readable (permission denied)")
    return p


def check_writable(path: str | os.PathLike, what: str = "output") -> Path:
    """``path`` as a :class:`Path` if a file can be created there; else ``ValueError``.

    ``path`` must be a new name or a regular file (a directory, a named pipe or a
    device is never replaced), and its parent directory must exist (it is not
    created) and accept a new file: the check creates and removes an empty
    temporary file, so permission and read-only file systems are caught before
    any work, not after it. :func:`write_atomic` runs it before every write.

    Raises
    ------
    ValueError
        Naming ``path`` (``what`` says what it is for) and what was found there.
    DiskFullError
        When not even an empty file fits on the file system.
    """
    p = Path(path)
    _check_replaceable(p, what)
    probe = tmp_path_for(p)
    try:
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except OSError as exc:
        full = disk_full(exc, p, what) if exc.errno in (errno.ENOSPC, errno.EDQUOT) else None
        if full is not None:  # a full disk stays exit status 1, not a usage error
            raise full from None
        raise ValueError(f"{p}: cannot write the {what} file ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return p


def _check_replaceable(p: Path, what: str) -> None:
    """Refuse ``p`` unless it is a regular file or a new name in an existing directory."""
    try:
        mode: int | None = p.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):  # a new name: its directory decides
        mode = None
    except OSError as exc:  # e.g. a name too long, a loop of links
        raise ValueError(f"{p}: cannot write the {what} file ({exc.strerror or exc})") from None
    if mode is not None and stat.S_ISDIR(mode):
        raise ValueError(f"{p}: {what} path is a directory; expected a file name")
    if mode is not None and not stat.S_ISREG(mode):
        raise ValueError(f"{p}: {what} path is {_kind(p)}, not a regular file; refusing to "
                         "replace it")
    parent = p.parent
    if mode is None and not parent.is_dir():
        found = (f"directory {parent} does not exist" if not parent.exists()
                 else f"{parent} is not a directory")
        raise ValueError(f"{p}: cannot write the {what} file: {found}")


#: Attributes that mark each kind of file mrfpe writes, and the kind in words.
_KINDS = ((("mrfpe_scene_version", "camera"), "a scene (written by Scene.save / mrfpe demo)"),
          (("sampler",), "a posterior (written by mrfpe estimate / posterior.save)"),
          (("study", "config_hash"), "a study trial's result (written by mrfpe study run)"))


def describe_contents(ds: xr.Dataset) -> str:
    """What a netCDF file holds, in words, for a message refusing it as the wrong kind.

    The kind of mrfpe file its global attributes mark, else its variables (read
    from a lazily opened ``ds``: no data is loaded).
    """
    for marks, kind in _KINDS:
        if any(m in ds.attrs for m in marks):
            return kind
    names = [str(n) for n in ds.data_vars]
    if not names:
        return "no variables"
    return "the variables " + ", ".join(names[:6]) + (", ..." if len(names) > 6 else "")


def open_dataset(path: str | os.PathLike, what: str = "data",
                 expect: Callable[[xr.Dataset], None] | None = None,
                 **kwargs: Any) -> xr.Dataset:
    """Read a netCDF file fully into memory (the file is closed on return).

    ``kwargs`` go to :func:`xarray.open_dataset` (engine ``netcdf4`` unless
    given). A missing, truncated or corrupt file raises ``ValueError(f"{path}:
    not a readable netCDF {what} file (reason)")``: the HDF5 error surfaces
    while opening *or* while reading the data, so both are covered.
    ``expect``, if given, is called with the opened dataset before its data is
    read (attributes and variable names only) and raises ``ValueError`` for a
    file of the wrong kind, so such a file is refused before the expensive part.
    """
    p = check_readable(path, what)
    kwargs.setdefault("engine", "netcdf4")
    _verified_attrs(p, what)
    try:
        f = xr.open_dataset(p, **kwargs)
    except Exception as exc:
        # netCDF4 raises OSError (HDF errors) or RuntimeError (NetCDF: ...); xarray's
        # decoders anything from ValueError to AttributeError on garbage metadata.
        # All mean: not this file.
        raise _unreadable(p, what, exc) from exc
    with f:
        if expect is not None:
            expect(f)  # its own message: the file reads, but is not what was asked for
        try:
            ds = f.load()
        except Exception as exc:
            raise _unreadable(p, what, exc) from exc
    return ds


def _verified_attrs(p: Path, what: str) -> dict[str, Any]:
    """The global attributes of ``p`` after checking its bytes against its checksum.

    The checksum is checked first, on the raw bytes: a damaged sealed file never
    reaches the HDF5 parser.
    """
    import netCDF4

    verify(p, str(p))
    try:
        with netCDF4.Dataset(p) as nc:
            return {k: nc.getncattr(k) for k in nc.ncattrs()}
    except Exception as exc:
        raise _unreadable(p, what, exc) from exc


def read_attrs(path: str | os.PathLike, what: str = "data") -> dict[str, Any]:
    """The global attributes of a netCDF file (netCDF4 directly: ~10× faster than xarray).

    Raises ``ValueError`` as :func:`open_dataset` does. The content is checked
    against the file's checksum (:mod:`mrfpe.checksum`), so a damaged file is
    refused here too; a file without one (written before checksums existed) is
    checked in its header only.
    """
    return _verified_attrs(check_readable(path, what), what)


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


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(ds: xr.Dataset, path: str | os.PathLike, what: str = "output",
                 **kwargs: Any) -> Path:
    """Write ``ds`` to ``path`` so that ``path`` is either absent, old, or complete.

    Writes a temporary file beside it, seals it with a checksum of its bytes
    (:func:`mrfpe.checksum.stamp`), ``fsync``s it, then ``os.replace``s it over
    ``path`` (and syncs the directory): a kill or power loss mid-write leaves at
    most a ``*.tmp`` file, never a partial ``path``. ``kwargs`` go to
    :meth:`xarray.Dataset.to_netcdf` (engine ``netcdf4`` unless given).

    Raises
    ------
    ValueError
        Before anything is written, when ``path`` cannot take the file
        (:func:`check_writable`: a directory, a named pipe or a device, a missing
        directory, no permission), naming it.
    DiskFullError
        When the file system is full, naming ``path`` (``what`` says what it is),
        instead of the HDF5 library's bare "HDF error"; nothing is left behind.
    """
    # checked here, not only in the command line: os.replace would put a regular file in
    # place of a pipe or a device, and the library's errors name the temporary file
    p = check_writable(path, what)
    kwargs.setdefault("engine", "netcdf4")
    tmp = tmp_path_for(p)
    try:
        ds.to_netcdf(tmp, **kwargs)
        stamp(tmp)
        _fsync_file(tmp)
        os.replace(tmp, p)
        _fsync_dir(p.parent)
    except Exception as exc:
        full = disk_full(exc, p, what, needed=int(ds.nbytes))
        if full is not None:
            _discard(tmp)
            raise full from exc
        raise
    finally:
        _discard(tmp)
    return p


def _discard(tmp: Path) -> None:
    try:
        tmp.unlink()
    except FileNotFoundError:
        pass


def write_text_atomic(text: str, path: str | os.PathLike, what: str = "output") -> Path:
    """Write ``text`` to ``path`` atomically (temporary file, ``os.replace``), as
    :func:`write_atomic`; a full disk raises :class:`DiskFullError` naming ``path``."""
    p = Path(path)
    tmp = tmp_path_for(p)
    try:
        tmp.write_text(text)
        os.replace(tmp, p)
    except OSError as exc:
        full = disk_full(exc, p, what, needed=len(text.encode()))
        if full is not None:
            raise full from exc
        raise
    finally:
        _discard(tmp)
    return p
