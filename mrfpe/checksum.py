"""A checksum sealing every netCDF file mrfpe writes, checked before the file is parsed.

HDF5 keeps checksums on some of its metadata but none on the data: a flipped bit
in a variable, or a spliced block that happens to parse, loads without an error
-- and some damaged metadata sends the HDF5 library into an endless loop while
it parses an attribute. :func:`stamp` therefore appends a trailer to the
finished file,

    ``b"\\nmrfpe-sha256:" + <64 hex digits> + b"\\n"``,

the SHA-256 of every byte before it. HDF5 ignores bytes after its end of file,
so netCDF4, xarray and every other reader open a sealed file as before.
:func:`verify` recomputes the digest from the raw bytes *before* the file is
handed to HDF5 and raises :class:`ChecksumError` when it differs, so a damaged
sealed file is refused without being parsed. A file without a trailer (written
before checksums existed, or by another program) is accepted as it is; a
truncated sealed file has lost its trailer, and HDF5 refuses it at once (its end
of file lies before the address its superblock records).

A damaged trailer must not pass for a missing one, or a file whose trailer and
data were both hit would load unchecked. The last :data:`TRAILER_BYTES` bytes
are therefore a trailer when their first 14 bytes (the prefix's place) match
:data:`PREFIX` in all but at most :data:`MARKER_SLACK` bytes -- ten or more bytes
of it in place by chance has a probability near 1e-21 -- and a trailer that is
not exact in every byte (prefix, 64 lowercase hex digits, newline) is an error.
A whole prefix elsewhere in the last 4 KiB (bytes appended after a trailer) is an
error too. The format is unchanged, so files sealed by earlier versions read as
before.

A leaf module (hashlib and os only): :mod:`mrfpe.netcdf` calls it on every write
and every read.
"""

from __future__ import annotations

import hashlib
import os

__all__ = ["MARKER_SLACK", "PREFIX", "TRAILER_BYTES", "ChecksumError", "digest", "stamp", "verify"]

#: What a trailer starts with.
PREFIX = b"\nmrfpe-sha256:"
#: Length of a trailer: the prefix, 64 hex digits and a newline.
TRAILER_BYTES = len(PREFIX) + 64 + 1
#: How many bytes of the prefix's place may differ from :data:`PREFIX` for the end of a
#: file still to count as a (damaged) trailer rather than no trailer.
MARKER_SLACK = 4
_CHUNK = 1 << 20


class ChecksumError(ValueError):
    """A file's bytes do not match the checksum sealed into it."""


def digest(path: str | os.PathLike, n_bytes: int) -> str:
    """SHA-256 (hex) of the first ``n_bytes`` bytes of the file at ``path``."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        left = n_bytes
        while left > 0:
            block = f.read(min(_CHUNK, left))
            if not block:
                break
            h.update(block)
            left -= len(block)
    return h.hexdigest()


#: How far from the end a damaged trailer's prefix is still recognised.
_SEARCH = 4096


def _trailer(path: str | os.PathLike, where: str) -> tuple[int, str] | None:
    """``(bytes before the trailer, stored hex digest)``, or None for an unsealed file.

    A trailer-shaped end (its prefix within :data:`MARKER_SLACK` bytes of
    :data:`PREFIX`) that is not exact, or a prefix elsewhere near the end, means a
    sealed file whose end was damaged: :class:`ChecksumError`.
    """
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        f.seek(max(0, size - _SEARCH))
        tail = f.read()
    end = tail[-TRAILER_BYTES:]
    if len(end) == TRAILER_BYTES:
        marker, text = end[:len(PREFIX)], end[len(PREFIX):-1]
        if sum(a != b for a, b in zip(marker, PREFIX)) <= MARKER_SLACK:
            # a trailer: any byte out of place is damage, not the absence of a seal
            if marker != PREFIX or end[-1:] != b"\n" or not _HEX.issuperset(text):
                raise _damaged_trailer(where)
            return size - TRAILER_BYTES, text.decode("ascii")
    if PREFIX[1:] in tail:
        raise _damaged_trailer(where)
    return None


_HEX = frozenset(b"0123456789abcdef")


def _damaged_trailer(where: str) -> ChecksumError:
    return ChecksumError(f"{where}: damaged file: its checksum trailer is damaged (the file "
                         f"was changed or corrupted after it was written)")


def stamp(path: str | os.PathLike) -> str:
    """Seal the finished file at ``path``: append the trailer; return the digest."""
    value = digest(path, os.path.getsize(path))
    with open(path, "ab") as f:
        f.write(PREFIX + value.encode("ascii") + b"\n")
    return value


def verify(path: str | os.PathLike, where: str | None = None) -> bool:
    """Check the file at ``path`` against its trailer, without parsing it.

    Returns ``False`` when the file carries no trailer (written before checksums
    existed, or by another program), ``True`` when the bytes match it.

    Raises
    ------
    ChecksumError
        ``"<where>: damaged file: its bytes do not match the checksum sealed into
        it ..."`` when they do not match.
    """
    found = _trailer(path, str(where or path))
    if found is None:
        return False
    n_bytes, stored = found
    if digest(path, n_bytes) != stored:
        raise ChecksumError(f"{where or path}: damaged file: its bytes do not match the "
                            f"checksum sealed into it (the file was changed or corrupted "
                            f"after it was written)")
    return True
