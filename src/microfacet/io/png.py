"""8-bit sRGB PNG previews of linear images (Pillow).

Tone map (documented, the same everywhere): ``L' = clip(2^exposure L, 0, 1)``, i.e. an
exposure in photographic stops followed by a hard clip at display white, then the sRGB
transfer function (IEC 61966-2-1, ``~ gamma 2.4`` with a linear toe) and rounding to
8 bits. Values above white saturate per channel; the EXR keeps the data.
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from PIL import Image

from .atomic import write_bytes

__all__ = ["tonemap", "srgb_encode", "to_srgb8", "write_png"]


def tonemap(linear, exposure: float = 0.0) -> np.ndarray:
    """Display-referred linear values ``clip(2^exposure L, 0, 1)``; NaN maps to 0."""
    scaled = np.asarray(linear, dtype=np.float64) * 2.0 ** float(exposure)
    return np.clip(np.nan_to_num(scaled, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


def srgb_encode(v) -> np.ndarray:
    """sRGB OETF (IEC 61966-2-1): ``12.92 v`` for ``v <= 0.0031308``, else
    ``1.055 v^(1/2.4) - 0.055``; ``v`` in ``[0, 1]``."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(np.maximum(v, 0.0031308), 1 / 2.4) - 0.055)


def to_srgb8(linear, exposure: float = 0.0) -> np.ndarray:
    """``uint8`` sRGB preview of a linear image: :func:`tonemap`, :func:`srgb_encode`, round.

    An alpha channel (4th channel) is kept linear (scaled to 8 bits, not tone mapped).
    """
    a = np.asarray(linear, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 4:
        rgb = to_srgb8(a[..., :3], exposure)
        alpha = np.rint(255.0 * np.clip(np.nan_to_num(a[..., 3]), 0.0, 1.0)).astype(np.uint8)
        return np.concatenate([rgb, alpha[..., None]], axis=-1)
    return np.rint(255.0 * srgb_encode(tonemap(a, exposure))).astype(np.uint8)


def write_png(path: str | os.PathLike, linear, exposure: float = 0.0) -> Path:
    """Write an 8-bit sRGB PNG preview of a linear ``(H, W)`` or ``(H, W, 1|3|4)`` image,
    atomically (see the module docstring for the tone map)."""
    a = np.asarray(linear)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))) or 0 in a.shape:
        raise ValueError(f"a PNG image must be (H, W) or (H, W, 1|3|4), got shape {np.shape(linear)}")
    buf = io.BytesIO()
    Image.fromarray(to_srgb8(a, exposure)).save(buf, format="PNG")
    return write_bytes(path, buf.getvalue())
