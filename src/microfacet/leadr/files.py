"""LEAN/LEADR files: moment pyramids as multi-part EXR, height and normal maps in.

Pyramid file: one OpenEXR multi-part file, one part per MIP level named ``mip0``,
``mip1``, ..., each a scanline image (uncompressed by default: the fastest write, see
``write_pyramid``) with float32 channels
``E1 E2 E3 E4 E5`` (moments of the unit uv square's slopes at every level). Every part
shares level 0's display window (OpenEXR requires it); the data window of part ``k`` is
its own ``W_k x H_k``.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import OpenEXR

from ..errors import HeightMapWarning, MicrofacetError
from ..io.atomic import atomic_path
from ..io.exr import check_exr_magic, exr_compression, exr_threads, write_exr
from ..io.image import read_image
from ..io.png import write_png_data
from .mip import mip_sizes

__all__ = ["write_pyramid", "read_pyramid", "load_height_map", "load_normal_map", "write_normal_map",
           "CHANNELS"]

CHANNELS = ("E1", "E2", "E3", "E4", "E5")


def write_pyramid(path: str | os.PathLike, pyramid, compression: str = "none") -> Path:
    """Write a moment pyramid (list of ``(H_k, W_k, 5)``, level 0 first) as a multi-part
    float32 EXR (module docstring), atomically, on all cores; returns ``path``.

    ``compression`` is a lossless name of :data:`microfacet.io.exr.COMPRESSIONS`. The default
    ``none`` is chosen by measurement (README, "LEAN/LEADR"): float32 moments barely compress
    (``zip`` saves 0-16 % of the bytes at 4-10x the write time on a 4096² map)."""
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
        channels = {name: np.ascontiguousarray(level[..., c], dtype=np.float32)
                    for c, name in enumerate(CHANNELS)}
        parts.append(OpenEXR.Part(header, channels, f"mip{k}"))
    with atomic_path(path) as tmp, exr_threads():
        OpenEXR.File(parts).write(str(tmp))
    return Path(path)


#: What a pyramid is, in error messages.
_PYRAMID = "a moment pyramid EXR (from 'microfacet bake')"


def read_pyramid(path: str | os.PathLike) -> list[np.ndarray]:
    """Read a pyramid written by :func:`write_pyramid`: a list of ``(H_k, W_k, 5)`` float32.

    Raises :class:`MicrofacetError` naming the file when it is not an EXR, is corrupt, or
    its parts are not ``mip0, mip1, ...`` with channels ``E1..E5``, the MIP sizes of
    level 0 and finite values.
    """
    path = Path(path)
    check_exr_magic(path, _PYRAMID)
    try:
        with exr_threads():
            parts = [(p.name(), {n: np.asarray(c.pixels) for n, c in p.channels.items()})
                     for p in OpenEXR.File(str(path), separate_channels=True).parts]
    except Exception as e:  # OpenEXR raises RuntimeError/others for corrupt files
        raise MicrofacetError(f"{path}: unreadable or corrupt EXR ({e})") from None
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
    :class:`~microfacet.errors.HeightMapWarning` (its slopes would be meaningless)."""
    levels, top = height_levels(read_image(Path(path)), path)
    return np.divide(levels, top, dtype=np.float64)


def height_levels(a: np.ndarray, path: str | os.PathLike) -> tuple[np.ndarray, float]:
    """``(levels, top)``: the heights ``levels / top`` (:func:`load_height_map`) of the image ``a``
    read from ``path`` (which names it in messages), with ``levels`` as the image stores them: an integer image's gray levels (or their sum over R, G, B, in
    ``uint32``) and ``top`` its largest level (times 3), so that ``microfacet.leadr.bake(levels,
    scale / top)`` bakes the heights without a float64 copy of them (4096²: 128 MB)."""
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
    in one step with :func:`microfacet.io.normalmap.read_normals`)."""
    path = Path(path)
    a = read_image(path)
    if a.ndim != 3 or a.shape[2] not in (2, 3, 4):
        raise MicrofacetError(f"{path}: a normal map needs 2 to 4 channels (H, W, R G[ B[ A]]), got shape {a.shape}")
    return a


def write_normal_map(path: str | os.PathLike, nmap) -> Path:
    """Write a normal map from :func:`microfacet.leadr.encode_normal_map`, atomically: a
    ``uint8``/``uint16`` one as an exact 8/16-bit RGB PNG, a float one as a float32 RGB
    EXR (normal components, not offset)."""
    a = np.asarray(nmap)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"a normal map must be (H, W, 3), got shape {a.shape}")
    if a.dtype in (np.uint8, np.uint16):
        return write_png_data(path, a)
    if a.dtype.kind == "f":
        return write_exr(path, a)
    raise ValueError(f"normal maps are uint8, uint16 or float, got {a.dtype}")
