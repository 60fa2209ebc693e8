"""Reading input files with errors that name the file and say what is wrong.

Examples
--------
>>> from microfacet.io.read import GZIP_MAGIC, MEASURED_BRDF
>>> GZIP_MAGIC.hex(), MEASURED_BRDF
('1f8b', 'a measured BRDF (MERL, RGL .bsdf, UTIA)')
"""
from __future__ import annotations

import os
import zlib
from pathlib import Path

from ..errors import MicrofacetError

__all__ = ["read_bytes", "decompressed", "read_decompressed", "GZIP_MAGIC", "MEASURED_BRDF"]

GZIP_MAGIC = b"\x1f\x8b"
#: What :func:`microfacet.measured.load` expects, in messages.
MEASURED_BRDF = "a measured BRDF (MERL, RGL .bsdf, UTIA)"


def read_bytes(path: str | os.PathLike, kind: str, size: int | None = None) -> bytes:
    """The first ``size`` bytes of ``path`` (all of it if ``None``); a missing file, a folder
    or an unreadable file raises :class:`MicrofacetError` naming it (``kind``: what was
    expected, e.g. ``"a PNG file"``).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    kind : str
        What the file should be, for messages.
    size : int, optional
        Bytes to read; None: all.

    Returns
    -------
    bytes
        The content.

    Examples
    --------
    >>> from pathlib import Path
    >>> _ = Path("data.bin").write_bytes(b"0123456789")
    >>> read_bytes("data.bin", "a data file", size=4)
    b'0123'
    >>> read_bytes("absent.bin", "a data file")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: absent.bin: no such file
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            return f.read() if size is None else f.read(size)
    except FileNotFoundError:
        raise MicrofacetError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise MicrofacetError(f"{path}: is a directory, not {kind}") from None
    except OSError as e:
        raise MicrofacetError(f"{path}: cannot read ({e.strerror or e})") from None


def decompressed(data: bytes, path: str | os.PathLike) -> bytes:
    """``data``, decompressed (all members) if it starts with the gzip magic; a corrupt or
    truncated stream raises :class:`MicrofacetError` naming ``path``. NumPy-free, and zlib
    releases the GIL: a thread can decompress while another imports modules.

    Parameters
    ----------
    data : bytes
        File content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    bytes
        The (decompressed) content.

    Examples
    --------
    >>> import gzip
    >>> decompressed(gzip.compress(b"MERL"), "x.binary.gz"), decompressed(b"raw", "x.binary")
    (b'MERL', b'raw')
    """
    if data[:2] != GZIP_MAGIC:
        return data
    try:
        d = zlib.decompressobj(wbits=31)
        out = d.decompress(data)
        while d.eof and d.unused_data[:2] == GZIP_MAGIC:        # concatenated members
            rest = d.unused_data
            d = zlib.decompressobj(wbits=31)
            out += d.decompress(rest)
    except zlib.error as e:
        raise MicrofacetError(f"{os.fspath(path)}: corrupt gzip stream ({e})") from e
    if not d.eof:
        raise MicrofacetError(f"{os.fspath(path)}: truncated gzip stream")
    return out


def read_decompressed(path: str | os.PathLike, kind: str) -> bytes:
    """:func:`read_bytes` of all of ``path``, :func:`decompressed`: a file's content, gzipped
    or not. NumPy-free and releasing the GIL, as :func:`decompressed`.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    kind : str
        What the file should be, for messages.

    Returns
    -------
    bytes
        The (decompressed) content.

    Examples
    --------
    >>> import gzip
    >>> from pathlib import Path
    >>> _ = Path("m.binary.gz").write_bytes(gzip.compress(b"payload"))
    >>> read_decompressed("m.binary.gz", MEASURED_BRDF)
    b'payload'
    """
    return decompressed(read_bytes(path, kind), path)
