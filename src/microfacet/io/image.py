"""Data images (height and normal maps) from PNG or OpenEXR files, recognised by content."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .exr import EXR_MAGIC, read_exr
from .png import PNG_MAGIC, read_png_data
from .read import read_bytes

__all__ = ["read_image"]


def read_image(path: str | os.PathLike) -> np.ndarray:
    """The samples of a PNG (``uint8``/``uint16`` as stored, :func:`read_png_data`) or an
    EXR (float64, :func:`read_exr`), chosen by the file's signature, not its name.

    Parameters
    ----------
    path : str or os.PathLike
        A PNG or EXR file.

    Returns
    -------
    ndarray
        ``(H, W)`` or ``(H, W, C)`` samples.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.io import write_png_data, write_exr
    >>> _ = write_png_data("map.png", np.full((2, 3, 3), 200, np.uint8))
    >>> read_image("map.png").dtype, read_image("map.png").shape
    (dtype('uint8'), (2, 3, 3))
    >>> _ = write_exr("map.exr", np.zeros((2, 3, 3)))
    >>> read_image("map.exr").dtype
    dtype('float64')
    """
    path = Path(path)
    head = read_bytes(path, "an image", 8)
    if head.startswith(PNG_MAGIC):
        return read_png_data(path)
    if head.startswith(EXR_MAGIC):
        return read_exr(path)
    raise MicrofacetError(f"{path}: not a PNG or OpenEXR image")
