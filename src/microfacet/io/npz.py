"""Reading ``.npz`` archives written by microfacet, with errors that name the file.

Examples
--------
>>> from microfacet.io.npz import ZIP_MAGIC
>>> [m.hex() for m in ZIP_MAGIC]
['504b0304', '504b0506']
"""
from __future__ import annotations

import math
import mmap
import os
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .read import read_bytes

__all__ = ["load_npz", "ZIP_MAGIC"]

#: First bytes of a zip archive (``.npz``): a local file header, or the end record of an empty one.
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def load_npz(path: str | os.PathLike, kind: str) -> dict[str, np.ndarray]:
    """All arrays of the ``.npz`` archive ``path``, read without pickle.

    ``kind`` says what the file should be (e.g. ``"a microfacet fit file"``). Anything
    that is not a readable archive of plain arrays (a missing file, other bytes, a
    truncated or corrupt archive, object arrays) raises :class:`MicrofacetError`
    naming the file and saying that it is not ``kind`` (never NumPy's "pickled data ...
    allow_pickle" message, which describes how it tried to read it).

    Parameters
    ----------
    path : str or os.PathLike
        The archive.
    kind : str
        What the file should be, for messages.

    Returns
    -------
    dict of str to ndarray
        The arrays by name.

    Examples
    --------
    >>> import numpy as np
    >>> np.savez("fit.npz", table=np.arange(3.0))
    >>> load_npz("fit.npz", "a fit file")["table"]
    array([0., 1., 2.])
    >>> load_npz("missing.npz", "a fit file")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: missing.npz: no such file
    """
    path = Path(path)
    head = read_bytes(path, kind, 4)
    if head not in ZIP_MAGIC:
        raise MicrofacetError(f"{path}: not {kind} (not a .npz archive: starts with "
                              f"{head.hex() or 'nothing, empty file'})")
    try:
        with open(path, "rb") as f, zipfile.ZipFile(f) as zf:
            out = {}
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                name = info.filename[:-4]
                if info.compress_type == zipfile.ZIP_STORED:
                    out[name] = _read_stored(f, info)
                else:
                    with zf.open(info) as m:
                        out[name] = np.lib.format.read_array(m, allow_pickle=False)
            return out
    except Exception as e:    # zipfile, zlib, EOFError, ValueError of np.load on corrupt archives
        why = "holds object arrays" if "pickle" in str(e) else f"{type(e).__name__}: {e}"
        raise MicrofacetError(f"{path}: not {kind} (corrupt .npz archive: {why})") from None


def _read_stored(f, info: zipfile.ZipInfo) -> np.ndarray:
    """The array of the uncompressed (``ZIP_STORED``) archive member ``info`` of the open
    archive file ``f``: a view of a private (copy-on-write, so writeable) memory map of the
    member alone, unmapped with the array, so that no bytes are copied
    (:class:`zipfile.ZipExtFile`, which ``np.load`` reads through, copies every chunk
    twice); the ``.npy`` header is read as :func:`numpy.lib.format.read_array`
    reads it and the member's CRC-32 is checked as :mod:`zipfile` checks it (APPNOTE.TXT
    4.3.7: the 30-byte local file header, with the name and extra-field lengths at offsets
    26 and 28, precedes the data)."""
    f.seek(info.header_offset)
    local = f.read(30)
    if len(local) != 30 or local[:4] != b"PK\x03\x04":
        raise zipfile.BadZipFile(f"bad local file header of {info.filename}")
    start = info.header_offset + 30 + sum(struct.unpack("<HH", local[26:30]))
    f.seek(start)
    version = np.lib.format.read_magic(f)
    shape, fortran, dtype = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                             else np.lib.format.read_array_header_2_0)(f)
    if dtype.hasobject:
        raise ValueError(f"{info.filename}: object arrays cannot be loaded without pickle")
    nhead = f.tell() - start
    count = math.prod(shape)
    nbytes = count * dtype.itemsize
    if nhead + nbytes != info.file_size:
        raise ValueError(f"{info.filename}: array size does not match the archive member")
    data = start + nhead
    skip = data % mmap.ALLOCATIONGRANULARITY                       # map offsets are aligned
    mm = mmap.mmap(f.fileno(), skip + nbytes, access=mmap.ACCESS_COPY, offset=data - skip) if nbytes else None
    a = np.frombuffer(mm, dtype, count, skip) if nbytes else np.empty(count, dtype)
    a = a.reshape(shape[::-1]).T if fortran else a.reshape(shape)
    f.seek(start)
    crc = zlib.crc32(f.read(nhead))
    if nbytes:
        with memoryview(mm) as view, view[skip:] as body:
            crc = zlib.crc32(body, crc)
    if crc != info.CRC:
        raise zipfile.BadZipFile(f"Bad CRC-32 for file {info.filename!r}")
    return a
