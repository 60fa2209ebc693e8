"""PNG files through ``imagecodecs`` (libpng): exact data images and 8-bit sRGB previews.

Data images (height and normal maps): :func:`read_png_data` returns the stored samples
exactly (``uint8`` or ``uint16``, 8- and 16-bit gray, gray+alpha, RGB and RGBA, palette
images expanded to RGB(A)), never colour-managed; :func:`write_png_data` writes them back
bit for bit. (Pillow truncates 16-bit RGB(A) PNGs to 8 bits, so it is not used for data.)

Previews of linear images, :func:`write_png`. Tone map (documented, the same
everywhere): ``L' = clip(2^exposure L, 0, 1)``, i.e. an exposure in photographic stops
followed by a hard clip at display white, then the sRGB transfer function
(IEC 61966-2-1, ``~ gamma 2.4`` with a linear toe) and rounding to 8 bits. Values above
white saturate per channel; the EXR keeps the data.

Examples
--------
>>> from microfacet.io.png import PNG_MAGIC
>>> PNG_MAGIC.hex()
'89504e470d0a1a0a'
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import imagecodecs
import numpy as np

from ..errors import MicrofacetError
from .atomic import write_bytes
from .quiet import log_captured, native_output_captured
from .read import read_bytes

__all__ = ["tonemap", "srgb_encode", "to_srgb8", "write_png", "read_png_data", "write_png_data",
           "PNG_MAGIC"]

#: The eight-byte PNG signature (PNG spec, Sec. 5.2).
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def tonemap(linear, exposure: float = 0.0) -> np.ndarray:
    """Display-referred linear values ``clip(2^exposure L, 0, 1)``; NaN maps to 0.

    Parameters
    ----------
    linear : array_like
        Linear values.
    exposure : float
        Stops (scale ``2^exposure``).

    Returns
    -------
    ndarray
        Values in ``[0, 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> tonemap(np.array([0.25, 1.0, 4.0, np.nan]), exposure=1.0)     # 2^1 L, clipped
    array([0.5, 1. , 1. , 0. ])
    """
    scaled = np.asarray(linear, dtype=np.float64) * 2.0 ** float(exposure)
    return np.clip(np.nan_to_num(scaled, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


def srgb_encode(v) -> np.ndarray:
    """sRGB OETF (IEC 61966-2-1): ``12.92 v`` for ``v <= 0.0031308``, else
    ``1.055 v^(1/2.4) - 0.055``; ``v`` in ``[0, 1]``.

    Parameters
    ----------
    v : array_like
        Linear values in ``[0, 1]``.

    Returns
    -------
    ndarray
        Encoded values in ``[0, 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> srgb_encode(np.array([0.0, 0.001, 0.18, 1.0])).round(4)
    array([0.    , 0.0129, 0.4614, 1.    ])
    """
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(np.maximum(v, 0.0031308), 1 / 2.4) - 0.055)


def to_srgb8(linear, exposure: float = 0.0) -> np.ndarray:
    """``uint8`` sRGB preview of a linear image: :func:`tonemap`, :func:`srgb_encode`, round.

    An alpha channel (4th channel) is kept linear (scaled to 8 bits, not tone mapped).

    Parameters
    ----------
    linear : array_like
        Linear image ``(H, W)`` or ``(H, W, C)``.
    exposure : float
        Stops (scale ``2^exposure``).

    Returns
    -------
    ndarray of uint8
        The preview.

    Examples
    --------
    >>> import numpy as np
    >>> to_srgb8(np.array([[0.0, 0.18, 1.0, 2.0]]))
    array([[  0, 118, 255, 255]], dtype=uint8)
    """
    a = np.asarray(linear, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 4:
        rgb = to_srgb8(a[..., :3], exposure)
        alpha = np.rint(255.0 * np.clip(np.nan_to_num(a[..., 3]), 0.0, 1.0)).astype(np.uint8)
        return np.concatenate([rgb, alpha[..., None]], axis=-1)
    return np.rint(255.0 * srgb_encode(tonemap(a, exposure))).astype(np.uint8)


def write_png(path: str | os.PathLike, linear, exposure: float = 0.0) -> Path:
    """Write an 8-bit sRGB PNG preview of a linear ``(H, W)`` or ``(H, W, 1|3|4)`` image,
    atomically (see the module docstring for the tone map).

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file.
    linear : array_like
        The linear image.
    exposure : float
        Stops (scale ``2^exposure``).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import numpy as np
    >>> write_png("gradient.png", np.linspace(0, 1, 64).reshape(8, 8)).name
    'gradient.png'
    >>> read_png_data("gradient.png").shape
    (8, 8)
    """
    a = np.asarray(linear)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))) or 0 in a.shape:
        raise ValueError(f"a PNG image must be (H, W) or (H, W, 1|3|4), got shape {np.shape(linear)}")
    return write_png_data(path, to_srgb8(a, exposure))


def read_png_data(path: str | os.PathLike) -> np.ndarray:
    """A PNG's stored samples: ``(H, W)`` for gray, ``(H, W, C)`` otherwise (``C`` = 2, 3, 4),
    ``uint8`` or ``uint16``. Palette images are expanded to RGB(A), 1/2/4-bit gray to 8 bits.

    Raises :class:`MicrofacetError` naming the file if it is missing, not a PNG or corrupt.

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file.

    Returns
    -------
    ndarray
        ``uint8`` or ``uint16`` samples.

    Examples
    --------
    >>> import numpy as np
    >>> _ = write_png_data("height.png", np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000)
    >>> read_png_data("height.png")
    array([[    0,  1000,  2000,  3000],
           [ 4000,  5000,  6000,  7000],
           [ 8000,  9000, 10000, 11000]], dtype=uint16)
    """
    path = Path(path)
    data = read_bytes(path, "a PNG file")
    if not data.startswith(PNG_MAGIC):
        raise MicrofacetError(f"{path}: not a PNG file (bad signature)")
    text: list[str] = []
    try:        # libpng's warnings: through imagecodecs' logger, or on stderr (other builds)
        with native_output_captured(text), log_captured("imagecodecs", text):
            a = imagecodecs.png_decode(data)
    except Exception:  # PngError, ValueError, ...: libpng's message may hold garbage bytes, so not echoed
        raise MicrofacetError(f"{path}: unreadable or corrupt PNG (libpng could not decode it)") from None
    notes = [" ".join(ln.strip().removeprefix("PNG warning:").split()) for ln in "\n".join(text).splitlines() if ln.strip()]
    if notes:
        warnings.warn(f"{path}: read despite libpng warnings: {'; '.join(notes[:5])}"
                      f"{f' (and {len(notes) - 5} more)' if len(notes) > 5 else ''}", UserWarning, stacklevel=2)
    if a.dtype not in (np.uint8, np.uint16) or a.ndim not in (2, 3) or 0 in a.shape:
        raise MicrofacetError(f"{path}: unsupported PNG sample layout ({a.dtype}, shape {a.shape})")
    return a


def write_png_data(path: str | os.PathLike, image) -> Path:
    """Write ``uint8`` or ``uint16`` samples ``(H, W)`` or ``(H, W, 1|2|3|4)`` as a PNG
    exactly (gray, gray+alpha, RGB, RGBA; no colour management), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file.
    image : array_like
        ``uint8`` or ``uint16`` samples.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import numpy as np
    >>> _ = write_png_data("rgb.png", np.zeros((2, 2, 3), np.uint8))
    >>> read_png_data("rgb.png").shape, read_png_data("rgb.png").dtype
    ((2, 2, 3), dtype('uint8'))
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (2, 3, 4)) or 0 in a.shape:
        raise ValueError(f"a PNG image must be (H, W) or (H, W, 1|2|3|4), got shape {np.shape(image)}")
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG data must be uint8 or uint16, got {a.dtype}")
    return write_bytes(path, imagecodecs.png_encode(np.ascontiguousarray(a), level=6))
