"""Exact PNG data images (8- and 16-bit gray, gray+alpha, RGB, RGBA), e.g. height and normal maps.

Pillow reads 16-bit gray PNGs exactly but truncates 16-bit RGB(A) ones to 8 bits, so
16-bit colour PNGs are decoded here (zlib + the five PNG row filters, compiled) and
written here too; everything else goes through Pillow. Values are returned as stored
(``uint8`` or ``uint16``), never colour-managed.
"""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numba
import numpy as np
from PIL import Image

from ..errors import MicrofacetError
from .atomic import write_bytes
from .read import read_bytes

__all__ = ["read_png_data", "write_png_data", "PNG_MAGIC"]

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}            # PNG colour type -> samples per pixel


def _chunks(data: bytes, path: Path):
    pos = len(PNG_MAGIC)
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if len(body) != length:
            raise MicrofacetError(f"{path}: truncated PNG ({kind.decode('latin-1')} chunk)")
        yield kind, body
        pos += 12 + length


@numba.njit(cache=True)
def _unfilter(raw, h, stride, bpp):  # pragma: no cover - compiled
    out = np.zeros((h, stride), dtype=np.uint8)
    for j in range(h):
        f = raw[j * (stride + 1)]
        row = raw[j * (stride + 1) + 1:(j + 1) * (stride + 1)]
        for x in range(stride):
            a = np.int32(out[j, x - bpp]) if x >= bpp else 0
            b = np.int32(out[j - 1, x]) if j > 0 else 0
            c = np.int32(out[j - 1, x - bpp]) if (j > 0 and x >= bpp) else 0
            if f == 0:
                p = 0
            elif f == 1:
                p = a
            elif f == 2:
                p = b
            elif f == 3:
                p = (a + b) // 2
            elif f == 4:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                p = a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
            else:
                return out, False
            out[j, x] = (np.int32(row[x]) + p) & 255
    return out, True


def _read_png16_colour(path: Path, data: bytes) -> np.ndarray:
    header, idat = None, []
    for kind, body in _chunks(data, path):
        if kind == b"IHDR":
            if len(body) != 13:
                raise MicrofacetError(f"{path}: corrupt PNG (IHDR chunk of {len(body)} bytes, expected 13)")
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
    w, h, depth, ctype, _, _, interlace = header
    if interlace:
        raise MicrofacetError(f"{path}: interlaced 16-bit colour PNGs are not supported")
    c = _CHANNELS[ctype]
    stride = w * c * 2
    try:
        raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    except zlib.error as e:
        raise MicrofacetError(f"{path}: corrupt PNG data ({e})") from None
    if raw.size < h * (stride + 1):
        raise MicrofacetError(f"{path}: truncated PNG data")
    rows, ok = _unfilter(raw, h, stride, c * 2)
    if not ok:
        raise MicrofacetError(f"{path}: corrupt PNG data (bad row filter)")
    return rows.view(">u2").astype(np.uint16).reshape(h, w, c)


def read_png_data(path: str | os.PathLike) -> np.ndarray:
    """A PNG's stored samples: ``(H, W)`` for gray, ``(H, W, C)`` otherwise (``C`` = 2, 3, 4),
    ``uint8`` or ``uint16``. Palette images are expanded to RGB(A).

    Raises :class:`MicrofacetError` naming the file if it is missing, not a PNG or corrupt.
    """
    path = Path(path)
    data = read_bytes(path, "a PNG file")
    if not data.startswith(PNG_MAGIC):
        raise MicrofacetError(f"{path}: not a PNG file (bad signature)")
    if len(data) < 33 or data[12:16] != b"IHDR":
        raise MicrofacetError(f"{path}: truncated PNG (no IHDR)")
    w, h, depth, ctype = struct.unpack(">IIBB", data[16:26])
    if depth == 16 and ctype in (2, 4, 6):
        return _read_png16_colour(path, data)
    try:
        with Image.open(path) as im:
            im.load()
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode == "1":
                im = im.convert("L")
            a = np.asarray(im)
    except Exception as e:  # Pillow raises many types for corrupt files
        raise MicrofacetError(f"{path}: unreadable or corrupt PNG ({e})") from None
    if depth == 16 and a.dtype != np.uint16:
        a = a.astype(np.uint16)               # 'I' mode of 16-bit gray in some Pillow versions
    return a


def write_png_data(path: str | os.PathLike, image) -> Path:
    """Write ``uint8`` or ``uint16`` samples ``(H, W)`` or ``(H, W, 1|2|3|4)`` as a PNG
    exactly (no colour management), atomically."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4) or 0 in a.shape:
        raise ValueError(f"a PNG image must be (H, W) or (H, W, 1|2|3|4), got shape {np.shape(image)}")
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG data must be uint8 or uint16, got {a.dtype}")
    h, w, c = a.shape
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    depth = 8 * a.dtype.itemsize
    rows = np.ascontiguousarray(a.astype(">u2") if depth == 16 else a).reshape(h, -1).view(np.uint8)
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rows], axis=1).tobytes()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    data = (PNG_MAGIC + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    return write_bytes(path, data)
