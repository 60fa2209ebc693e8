"""Reader of the ``tensor_file`` container (Mitsuba 3 ``TensorFile``, RGL material database).

Layout (little-endian): 12 bytes ``b"tensor_file\\0"``, u8 version ``(1, 0)``, u32 field
count, then per field: u16 name length, name (UTF-8), u16 ndim, u8 dtype
(``Struct::Type``: 1 u8, 2 i8, 3 u16, 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f16,
10 f32, 11 f64), u64 absolute data offset, ndim x u64 shape; each field's data are
stored row-major at its offset.

Examples
--------
>>> MAGIC[:11], len(MAGIC), DTYPES[10]
(b'tensor_file', 12, '<f4')

"""
from __future__ import annotations

import math
import struct

import numpy as np

from .base import file_error

__all__ = ["MAGIC", "DTYPES", "is_tensor_file", "read_tensor_file", "write_tensor_file"]

MAGIC = b"tensor_file\0"
VERSION = (1, 0)
DTYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8",
          9: "<f2", 10: "<f4", 11: "<f8"}
_CODES = {np.dtype(v).str: k for k, v in DTYPES.items()}


def is_tensor_file(data: bytes) -> bool:
    """Whether ``data`` start with the ``tensor_file`` magic.

    Parameters
    ----------
    data : bytes
        File content.

    Returns
    -------
    bool
        Whether it starts with the magic.

    Examples
    --------
    >>> is_tensor_file(write_tensor_file({})), is_tensor_file(b"GIF89a")
    (True, False)
    """
    return data[:12] == MAGIC


def read_tensor_file(data: bytes, path) -> dict[str, np.ndarray]:
    """All fields of a tensor file, as read-only arrays viewing ``data``.

    Raises ``MicrofacetError`` (naming ``path``) on a bad magic, version, dtype, a
    truncated header or a field whose data run past the end of the file.

    Parameters
    ----------
    data : bytes
        File content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    dict of str to ndarray
        The fields, read-only.

    Examples
    --------
    >>> import numpy as np
    >>> data = write_tensor_file({"theta_i": np.array([0.0, 0.5], np.float32)})
    >>> read_tensor_file(data, "t.bsdf")
    {'theta_i': array([0. , 0.5], dtype=float32)}
    >>> read_tensor_file(data[:30], "t.bsdf")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: t.bsdf: tensor_file header truncated or corrupt (...)
    """
    if not is_tensor_file(data):
        raise file_error(path, "not a tensor_file (bad magic)")
    try:
        version = tuple(data[12:14])
        if version != VERSION:
            raise file_error(path, f"tensor_file version {version}, expected {VERSION}")
        (n_fields,), pos = struct.unpack_from("<I", data, 14), 18
        fields = {}
        for _ in range(n_fields):
            name, ndim, code, offset, shape, pos = _field_header(data, pos)
            if code not in DTYPES:
                raise file_error(path, f"tensor_file field {name!r} has unknown dtype code {code}")
            dtype = np.dtype(DTYPES[code])
            count = math.prod(shape)                      # exact: declared sizes may be huge
            if max(shape, default=0) > len(data):         # also with another dimension 0
                raise file_error(path, f"tensor_file field {name!r} declares an impossible shape {shape} "
                                       f"for a file of {len(data)} bytes")
            if offset + count * dtype.itemsize > len(data):
                raise file_error(path, f"tensor_file truncated: field {name!r} {shape} needs bytes "
                                       f"up to {offset + count * dtype.itemsize}, file has {len(data)}")
            fields[name] = np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape)
    except (struct.error, UnicodeDecodeError) as e:
        raise file_error(path, f"tensor_file header truncated or corrupt ({e})") from e
    return fields


def _field_header(data: bytes, pos: int):
    """One field descriptor at ``pos``: ``(name, ndim, dtype code, offset, shape, next pos)``."""
    (n,) = struct.unpack_from("<H", data, pos)
    if pos + 2 + n > len(data):
        raise struct.error("field name runs past the end of the file")
    name = data[pos + 2:pos + 2 + n].decode("utf-8")
    ndim, code, offset = struct.unpack_from("<HBQ", data, pos + 2 + n)
    pos += 2 + n + 11
    shape = struct.unpack_from(f"<{ndim}Q", data, pos)
    return name, ndim, code, offset, shape, pos + 8 * ndim


def write_tensor_file(fields: dict[str, np.ndarray]) -> bytes:
    """The bytes of a tensor file holding ``fields`` (8-byte aligned data); for tests and
    tools that write RGL-style files.

    Parameters
    ----------
    fields : dict of str to ndarray
        The fields.

    Returns
    -------
    bytes
        The file content.

    Examples
    --------
    >>> import numpy as np
    >>> data = write_tensor_file({"jacobian": np.array([1], np.uint8), "ndf": np.ones((2, 2), np.float32)})
    >>> len(data), data[:11]
    (104, b'tensor_file')

    """
    arrays = {k: np.ascontiguousarray(v) for k, v in fields.items()}
    header = bytearray(MAGIC + bytes(VERSION) + struct.pack("<I", len(arrays)))
    size = len(header) + sum(2 + len(k.encode()) + 11 + 8 * a.ndim for k, a in arrays.items())
    offset, blobs = -(-size // 8) * 8, []
    for name, a in arrays.items():
        key = name.encode()
        header += struct.pack("<H", len(key)) + key
        header += struct.pack("<HBQ", a.ndim, _CODES[a.dtype.newbyteorder("<").str], offset)
        header += struct.pack(f"<{a.ndim}Q", *a.shape)
        blob = a.astype(a.dtype.newbyteorder("<")).tobytes()
        blobs.append(blob + bytes(-len(blob) % 8))
        offset += len(blobs[-1])
    return bytes(header) + bytes(-len(header) % 8) + b"".join(blobs)
