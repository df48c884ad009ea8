"""Exact netCDF4 round trip of a posterior: :func:`save` and :func:`load`.

netCDF attributes hold strings, numbers and 1-D numeric arrays. Everything
else a posterior carries as an attribute (bools such as ``diag_reliable``,
``None``, dicts, lists of strings such as ``diag_messages``) is written as JSON
and its name listed in the file attribute ``_mrfpe_json_attrs``, so :func:`load`
decodes exactly those. Float NaN and ±inf (data or attributes) are kept.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

__all__ = ["load", "save"]

_JSON_ATTRS = "_mrfpe_json_attrs"


def _is_nc_attr(v: Any) -> bool:
    if isinstance(v, bool | np.bool_):
        return False
    if isinstance(v, str | int | float | np.integer | np.floating):
        return True
    if isinstance(v, np.ndarray | list | tuple):
        a = np.asarray(v)
        return a.ndim == 1 and a.size > 0 and a.dtype.kind in "iuf"
    return False


def _encode_attrs(attrs: dict) -> dict:
    """netCDF attributes; values netCDF cannot hold (bool, None, dict) go as JSON."""
    out, encoded = {}, []
    for k, v in attrs.items():
        if _is_nc_attr(v):
            out[k] = v
        else:
            out[k] = json.dumps(v.item() if isinstance(v, np.generic) else v)
            encoded.append(k)
    if encoded:
        out[_JSON_ATTRS] = json.dumps(encoded)
    return out


def _decode_attrs(attrs: dict) -> dict:
    attrs = dict(attrs)
    encoded = json.loads(attrs.pop(_JSON_ATTRS, "[]"))
    out = {}
    for k, v in attrs.items():
        if k in encoded:
            out[k] = json.loads(v)
        elif isinstance(v, np.generic):
            out[k] = v.item()  # netCDF returns numpy scalars; build() stores python ones
        else:
            out[k] = v
    return out


def save(post: xr.Dataset, path: Any) -> None:
    """Write a posterior to netCDF4 so that :func:`load` returns it unchanged.

    Float variables keep NaN and ±inf (no fill-value masking on read), string
    coordinates come back as fixed-width unicode, and attributes netCDF cannot
    store (bool, None, dicts, lists of strings) are stored as JSON and decoded.
    The write is atomic (:func:`mrfpe.netcdf.write_atomic`): an interrupted save
    never leaves a partial file at ``path``.

    Raises
    ------
    ValueError
        Before anything is written, naming ``path``, when it is a directory, a
        named pipe or a device, or its directory is missing or not writable
        (:func:`mrfpe.netcdf.check_writable`); nothing there is touched.
    mrfpe.netcdf.DiskFullError
        When the file system is full; nothing is left behind.
    """
    from mrfpe.netcdf import check_writable, write_atomic

    check_writable(path, "posterior")  # before the copy and the encoding
    ds = post.copy()
    ds.attrs = _encode_attrs(post.attrs)
    for name, var in ds.variables.items():
        var.attrs = _encode_attrs(post[name].attrs)
        var.encoding = {}
        if var.dtype.kind == "f":
            var.encoding["_FillValue"] = None  # NaN is data, not "missing"
    write_atomic(ds, path, "posterior", format="NETCDF4")


#: What marks a file as a posterior: read before the data, so another file is refused cheaply.
_MARK_VARIABLE, _MARK_ATTR = "theta", "sampler"
_NOT_A_POSTERIOR = "not a posterior file (written by mrfpe estimate / posterior.save)"


def _expect_posterior(path: Any) -> Callable[[xr.Dataset], None]:
    """A check for :func:`mrfpe.netcdf.open_dataset`: the file holds a posterior."""
    from mrfpe.netcdf import describe_contents

    def check(ds: xr.Dataset) -> None:
        if _MARK_VARIABLE in ds.variables and _MARK_ATTR in ds.attrs:
            return
        if _MARK_ATTR in ds.attrs:  # says it is one, but lacks the samples
            holds = f"no variable {_MARK_VARIABLE!r}"
        else:
            holds = describe_contents(ds)
        raise ValueError(f"{path}: {_NOT_A_POSTERIOR}: it holds {holds}")

    return check


def load(path: Any) -> xr.Dataset:
    """Read a posterior written by :func:`save` (fully into memory; the file is closed).

    A missing, truncated, corrupt or damaged file (:func:`mrfpe.netcdf.open_dataset`),
    a netCDF file that holds no posterior (a scene, say: one without a ``theta``
    variable and a ``sampler`` attribute, refused before its data is read), or
    attributes that do not decode, raise ``ValueError`` naming it. The schema
    itself is checked by :func:`mrfpe.posterior.validate`.
    """
    from mrfpe.netcdf import open_dataset

    ds = open_dataset(path, "posterior", expect=_expect_posterior(path), mask_and_scale=False,
                      decode_times=False, decode_timedelta=False)
    try:
        return _decode(ds)
    except Exception as exc:  # a damaged JSON attribute, a non-string list, ...
        raise ValueError(f"{path}: {_NOT_A_POSTERIOR}: {type(exc).__name__}: {exc}") from None


def _decode(ds: xr.Dataset) -> xr.Dataset:
    ds.attrs = _decode_attrs(ds.attrs)
    for name, var in ds.variables.items():
        var.attrs = _decode_attrs(var.attrs)
        var.encoding = {}
        if var.dtype.kind == "O":  # variable-length strings -> fixed-width unicode
            ds[name] = var.astype(str)
    for name in list(ds.coords):
        if ds[name].dtype.kind == "O":
            ds = ds.assign_coords({name: ds[name].values.astype(str)})
    return ds
