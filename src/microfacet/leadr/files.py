"""LEAN/LEADR files: moment pyramids as multi-part EXR, height and normal maps in.

Pyramid file: one OpenEXR multi-part file, one part per MIP level named ``mip0``,
``mip1``, ..., each a scanline image (uncompressed by default: the fastest write, see
``write_pyramid``) with float32 channels
``E1 E2 E3 E4 E5`` (moments of the unit uv square's slopes at every level). Every part
shares level 0's display window (OpenEXR requires it); the data window of part ``k`` is
its own ``W_k x H_k``. :func:`pyramid_file` lays out the uncompressed file, byte for byte as
OpenEXR writes it, in memory mapped onto the file, for :func:`microfacet.leadr.bake` to
fill (OpenExr file layout, "Multi-Part Files" and "Scan Lines").

Examples
--------
>>> CHANNELS
('E1', 'E2', 'E3', 'E4', 'E5')
"""
from __future__ import annotations

import contextlib
import mmap
import os
import struct
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import OpenEXR

from ..errors import HeightMapWarning, MicrofacetError
from ..io.atomic import atomic_path
from ..io.exr import check_exr_magic, exr_compression, exr_read_errors, exr_threads, exr_write_errors, write_exr
from ..io.image import read_image
from ..io.png import write_png_data
from .mip import mip_sizes

__all__ = ["write_pyramid", "pyramid_file", "read_pyramid", "load_height_map", "load_normal_map", "write_normal_map",
           "CHANNELS"]

CHANNELS = ("E1", "E2", "E3", "E4", "E5")


def write_pyramid(path: str | os.PathLike, pyramid, compression: str = "none",
                  allow_nonfinite: bool = False) -> Path:
    """Write a moment pyramid (list of ``(H_k, W_k, 5)``, level 0 first) as a multi-part
    float32 EXR (module docstring), atomically, on all cores; returns ``path``.

    Refuses (``ValueError`` naming the file and level) NaN, infinite values and values beyond
    float32's range, which :func:`read_pyramid` would refuse, unless ``allow_nonfinite`` (as
    :func:`microfacet.io.write_exr`; e.g. to test readers). ``compression`` is a lossless
    name of :data:`microfacet.io.exr.COMPRESSIONS`. The default
    ``none`` is chosen because float32 moments barely compress: ``zip`` saves few bytes at
    several times the write time (``benchmarks/bench_leadr.py``).

    Parameters
    ----------
    path : str or PathLike
        The ``.exr`` file to write.
    pyramid : list of ndarray
        Levels ``(H_k, W_k, 5)``, level 0 first (:func:`microfacet.leadr.bake`).
    compression : str
        A lossless name of :data:`microfacet.io.exr.COMPRESSIONS`.
    allow_nonfinite : bool
        Write NaN, infinite and out-of-range values instead of refusing them.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Non-finite or out-of-range moments (naming the file and level), a lossy or unknown
        ``compression``.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> write_pyramid("bumps.exr", pyramid).name
    'bumps.exr'
    >>> [level.shape for level in read_pyramid("bumps.exr")]
    [(16, 16, 5), (8, 8, 5), (4, 4, 5), (2, 2, 5), (1, 1, 5)]
    """
    compression_type = exr_compression(compression)
    levels = [np.asarray(level) for level in pyramid]
    if not levels:
        raise ValueError("empty pyramid")
    for k, level in enumerate(levels):
        if level.ndim != 3 or level.shape[2] != 5 or 0 in level.shape:
            raise ValueError(f"pyramid level {k} must be (H, W, 5), got shape {level.shape}")
    h0, w0 = levels[0].shape[:2]
    window = (np.array([0, 0], np.int32), np.array([w0 - 1, h0 - 1], np.int32))
    parts = []
    for k, level in enumerate(levels):
        header = {"compression": compression_type, "type": OpenEXR.scanlineimage,
                  "displayWindow": window}
        with np.errstate(over="ignore", invalid="ignore"):
            channels = {name: np.ascontiguousarray(level[..., c], dtype=np.float32)
                        for c, name in enumerate(CHANNELS)}
        bad = sum(np.count_nonzero(~np.isfinite(a)) for a in channels.values())
        if bad and not allow_nonfinite:             # as write_exr: read_pyramid refuses them
            raise ValueError(f"{path}: pyramid level {k} has {bad} NaN or infinite values (after "
                             "conversion to float32); nothing written (allow_nonfinite=True writes them)")
        parts.append(OpenEXR.Part(header, channels, f"mip{k}"))
    with exr_write_errors(path), atomic_path(path) as tmp, exr_threads():
        OpenEXR.File(parts).write(str(tmp))
    return Path(path)


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    """An EXR header attribute: name, type (null-terminated), size (int32), value."""
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _part_header(k: int, height: int, width: int, display: tuple[int, int], multi: bool) -> bytes:
    """The header of part ``mip{k}`` (an uncompressed float32 scanline image ``height x width``
    with channels :data:`CHANNELS`, display window ``display = (H_0, W_0)``) of a ``multi``-part
    file or a single-part one: OpenEXR's attributes, in its (alphabetical) order, then the null
    byte that ends a header."""
    chlist = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for c in CHANNELS) + b"\0"
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    name = f"mip{k}".encode()
    return b"".join([
        _attribute("channels", "chlist", chlist),
        _attribute("chunkCount", "int", struct.pack("<i", height)) if multi else b"",
        _attribute("compression", "compression", b"\0"), _attribute("dataWindow", "box2i", window),
        _attribute("displayWindow", "box2i", struct.pack("<4i", 0, 0, display[1] - 1, display[0] - 1)),
        _attribute("lineOrder", "lineOrder", b"\0"), _attribute("name", "string", name),
        _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _attribute("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
        _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
        _attribute("type", "string", b"scanlineimage"), b"\0"])


@contextlib.contextmanager
def pyramid_file(path: str | os.PathLike, height: int, width: int) -> Iterator[list[np.ndarray]]:
    """Storage for the moment pyramid of an ``height x width`` map inside the file it will be:
    yields its levels, ``(H_k, W_k, 5)`` float32 views of an uncompressed pyramid EXR (the
    file :func:`write_pyramid` writes with ``compression="none"``, byte for byte) mapped in
    memory, to be filled (``microfacet.leadr.bake(..., out=levels)``). On leaving the block
    the file replaces ``path`` atomically (flushed to disk); on an exception nothing is left.
    A bake filling it touches each byte once, where an array then written to a file takes
    its memory twice (the array's pages and the file's), which costs most of a large bake.
    Do not write into the levels after the block: they remain mapped onto the file.

    Parameters
    ----------
    path : str or path-like
        The pyramid EXR to write.
    height, width : int
        Size of level 0 in texels.

    Yields
    ------
    list of numpy.ndarray
        The levels ``(H_k, W_k, 5)`` float32, mapped onto the file, level 0 first.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> height = gaussian_heightfield((16, 16), 0.3, seed=0)
    >>> with pyramid_file("bumps.exr", 16, 16) as levels:     # baked straight into the file's storage
    ...     _ = bake(height, out=levels)
    >>> [level.shape for level in read_pyramid("bumps.exr")]
    [(16, 16, 5), (8, 8, 5), (4, 4, 5), (2, 2, 5), (1, 1, 5)]
    """
    sizes = mip_sizes(height, width)
    multi = len(sizes) > 1                   # a 1 x 1 map has one level: a single-part file
    prefix = 3 if multi else 2               # chunk: [part,] y, size (int32), then E1..E5 of line y
    headers = b"v/1\x01" + struct.pack("<i", 2 | (0x1000 if multi else 0)) + b"".join(    # version 2
        _part_header(k, h, w, sizes[0], multi) for k, (h, w) in enumerate(sizes)) + (b"\0" if multi else b"")
    offset = len(headers) + 8 * sum(h for h, _ in sizes)                    # the offset tables
    starts, tables = [], []
    for h, w in sizes:
        starts.append(offset)
        tables.append(offset + 4 * (prefix + 5 * w) * np.arange(h, dtype=np.uint64))
        offset += 4 * (prefix + 5 * w) * h
    with atomic_path(path) as tmp, open(tmp, "r+b") as f:
        if hasattr(os, "posix_fallocate"):               # a full disk fails here, not in the mapping
            os.posix_fallocate(f.fileno(), 0, offset)
        else:                                           # (macOS, Windows)
            f.truncate(offset)
        f.write(headers + np.concatenate(tables).astype("<u8").tobytes())
        f.flush()
        memory = mmap.mmap(f.fileno(), offset)
        levels = []
        for k, ((h, w), start) in enumerate(zip(sizes, starts)):
            lines = np.ndarray((h, prefix + 5 * w), np.float32, memory, start)
            lines.view(np.int32)[:, :prefix] = np.stack([np.full(h, k), np.arange(h), np.full(h, 20 * w)],
                                                        axis=1)[:, 3 - prefix:]
            levels.append(lines[:, prefix:].reshape(h, 5, w).transpose(0, 2, 1))
        yield levels                                     # atomic_path's fsync writes the mapped pages


#: What a pyramid is, in error messages.
_PYRAMID = "a moment pyramid EXR (from 'microfacet bake')"


def read_pyramid(path: str | os.PathLike) -> list[np.ndarray]:
    """Read a pyramid written by :func:`write_pyramid`: a list of ``(H_k, W_k, 5)`` float32.

    Raises :class:`MicrofacetError` naming the file when it is not an EXR, is corrupt, or
    its parts are not ``mip0, mip1, ...`` with channels ``E1..E5``, the MIP sizes of
    level 0 and finite values.

    Parameters
    ----------
    path : str or path-like
        A pyramid EXR.

    Returns
    -------
    list of numpy.ndarray
        The levels ``(H_k, W_k, 5)`` float32, level 0 first.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> back = read_pyramid(write_pyramid("bumps.exr", pyramid))
    >>> all(np.array_equal(a, b) for a, b in zip(pyramid, back)), back[0].dtype
    (True, dtype('float32'))
    """
    path = Path(path)
    check_exr_magic(path, _PYRAMID)
    with exr_read_errors(path), exr_threads():
        parts = [(p.name(), {n: np.asarray(c.pixels) for n, c in p.channels.items()})
                 for p in OpenEXR.File(str(path), separate_channels=True).parts]
    names = [name for name, _ in parts]
    if not parts or names != [f"mip{k}" for k in range(len(parts))]:
        raise MicrofacetError(f"{path}: not {_PYRAMID}: parts {names[:4]}, expected mip0, mip1, ...")
    levels = []
    for name, channels in parts:
        missing = [c for c in CHANNELS if c not in channels]
        if missing:
            raise MicrofacetError(f"{path}: part {name} lacks channels {' '.join(missing)}")
        levels.append(np.stack([channels[c].astype(np.float32) for c in CHANNELS], axis=-1))
    expected = mip_sizes(*levels[0].shape[:2])
    found = [level.shape[:2] for level in levels]
    if found != expected:
        raise MicrofacetError(f"{path}: MIP level sizes {found} do not match level 0's {expected}")
    for name, level in zip(names, levels):
        if not np.all(np.isfinite(level)):
            raise MicrofacetError(f"{path}: part {name} holds NaN or infinite moments")
    return levels


def _looks_like_normal_map(rgb: np.ndarray) -> bool:
    """Whether colour samples ``(H, W, 3)`` (not gray) decode, on a grid of at most 128²
    texels, into a normal map the decoder finds consistent: none repaired, unit length."""
    from ..io.normalmap import decode_normals
    step = max(1, max(rgb.shape[:2]) // 128)
    sample = rgb[::step, ::step]
    if np.ptp(sample.astype(np.float64), axis=2).max() == 0:        # gray
        return False
    return not decode_normals(sample, warn=False)[1].warnings


def load_height_map(path: str | os.PathLike) -> np.ndarray:
    """Heights ``(H, W)`` float64 of a PNG (8/16-bit gray or RGB(A), scaled to ``[0, 1]``)
    or EXR (``Y``, or the mean of ``R, G, B``) image. Colour PNGs use the mean of R, G, B
    (equal in a gray image); alpha is ignored. A colour map that decodes as a normal map
    (:func:`_looks_like_normal_map`) is read as heights all the same, with a
    :class:`~microfacet.errors.HeightMapWarning` (its slopes would be meaningless).

    Parameters
    ----------
    path : str or path-like
        A PNG or EXR file.

    Returns
    -------
    numpy.ndarray, shape (H, W)
        Heights (float64; a PNG's in ``[0, 1]``).

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.io import write_png_data
    >>> _ = write_png_data("height.png", (np.arange(16)[None, :] * 4096).astype(np.uint16).repeat(4, 0))
    >>> h = load_height_map("height.png")
    >>> h.shape, round(float(h.max()), 4)
    ((4, 16), 0.9375)
    """
    levels, top = height_levels(read_image(Path(path)), path)
    return np.divide(levels, top, dtype=np.float64)


def height_levels(a: np.ndarray, path: str | os.PathLike) -> tuple[np.ndarray, float]:
    """``(levels, top)``: the heights ``levels / top`` (:func:`load_height_map`) of the image
    ``a`` read from ``path`` (which names it in messages), ``levels`` as the image stores them:
    an integer image's gray levels (or their sum over R, G, B, in ``uint32``) and ``top`` its
    largest level (times 3), so that ``microfacet.leadr.bake(levels, scale / top)`` bakes the
    heights without a float64 copy of them (4096²: 128 MB)."""
    path = Path(path)
    if a.ndim == 3 and a.shape[2] >= 3 and _looks_like_normal_map(a[..., :3]):
        warnings.warn(f"{path}: looks like a tangent-space normal map (its colours decode to unit "
                      "normals) but is read as heights (the mean of R, G, B); bake it with --normal-map "
                      "(microfacet.leadr.normal_map_to_moments)", HeightMapWarning, stacklevel=3)
    if min(a.shape[:2]) < 1:
        raise MicrofacetError(f"{path}: empty image")
    integer = a.dtype in (np.uint8, np.uint16)
    top = float(np.iinfo(a.dtype).max) if integer else 1.0
    if a.ndim == 3:
        if a.shape[2] in (1, 2):
            a = a[..., 0]
        elif integer:
            a, top = a[..., :3].sum(axis=2, dtype=np.uint32), 3.0 * top
        else:
            a = a[..., :3].mean(axis=2)
    return a, top


def load_normal_map(path: str | os.PathLike) -> np.ndarray:
    """A normal map as stored: ``(H, W, 2|3|4)`` ``uint8``/``uint16`` from a PNG, float64
    from an EXR; decode with :func:`microfacet.leadr.decode_normal_map` (or read and decode
    in one step with :func:`microfacet.io.normalmap.read_normals`).

    Parameters
    ----------
    path : str or path-like
        A PNG or EXR file.

    Returns
    -------
    numpy.ndarray, shape (H, W, 2|3|4)
        The stored texels, not decoded.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import encode_normal_map
    >>> _ = write_normal_map("normals.png", encode_normal_map(np.zeros((16, 16, 2))))
    >>> nmap = load_normal_map("normals.png")
    >>> nmap.shape, nmap.dtype, nmap[0, 0]
    ((16, 16, 3), dtype('uint8'), array([128, 128, 255], dtype=uint8))
    """
    path = Path(path)
    a = read_image(path)
    if a.ndim != 3 or a.shape[2] not in (2, 3, 4):
        raise MicrofacetError(f"{path}: a normal map needs 2 to 4 channels (H, W, R G[ B[ A]]), got shape {a.shape}")
    return a


def write_normal_map(path: str | os.PathLike, nmap) -> Path:
    """Write a normal map from :func:`microfacet.leadr.encode_normal_map`, atomically: a
    ``uint8``/``uint16`` one as an exact 8/16-bit RGB PNG, a float one as a float32 RGB
    EXR (normal components, not offset).

    Parameters
    ----------
    path : str or path-like
        The output file (PNG for integer maps, EXR for float ones).
    nmap : ndarray, shape (H, W, 3)
        The encoded normal map (uint8, uint16 or float).

    Returns
    -------
    Path
        The file written.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import encode_normal_map
    >>> write_normal_map("normals.png", encode_normal_map(np.zeros((16, 16, 2)))).name
    'normals.png'
    """
    a = np.asarray(nmap)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"a normal map must be (H, W, 3), got shape {a.shape}")
    if a.dtype in (np.uint8, np.uint16):
        return write_png_data(path, a)
    if a.dtype.kind == "f":
        return write_exr(path, a)
    raise ValueError(f"normal maps are uint8, uint16 or float, got {a.dtype}")
