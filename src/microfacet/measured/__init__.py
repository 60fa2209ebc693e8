"""Measured BRDFs: MERL ``.binary(.gz)``, RGL ``.bsdf`` and UTIA ``.bin`` readers.

``load(path)`` recognises the format by content, not by file name:

* gzip magic ``1f 8b`` → decompressed, then recognised as below;
* ``b"tensor_file\\0"`` → RGL material database file (:mod:`.rgl`);
* MERL header ``int32 (90, 90, 180)`` → MERL file (:mod:`.merl`);
* exactly 1,990,656 bytes (headerless float64 ``3 x 6 x 48 x 6 x 48``) → UTIA (:mod:`.utia`).

Every reader returns a :class:`microfacet.BRDF` (``eval``, ``eval_cos``, ``sample``,
``pdf``; cosine-weighted sampling) and raises :class:`microfacet.MicrofacetError`
naming the file and what is wrong with it. Files are only read.
"""
from __future__ import annotations

import os

from ..io.read import MEASURED_BRDF, read_decompressed
from .base import MeasuredBRDF, file_error
from .merl import MERLBRDF, is_merl, read_merl
from .rgl import RGLBRDF, read_rgl
from .tensor_file import is_tensor_file, read_tensor_file, write_tensor_file
from .utia import N_BYTES as UTIA_BYTES
from .utia import UTIABRDF, is_utia, read_utia

__all__ = ["load", "load_bytes", "detect", "MeasuredBRDF", "MERLBRDF", "RGLBRDF", "UTIABRDF",
           "read_tensor_file", "write_tensor_file"]


def detect(data: bytes) -> str:
    """Format of uncompressed file bytes: ``"rgl"``, ``"merl"``, ``"utia"`` or ``""``.

    Parameters
    ----------
    data : bytes
        Uncompressed file content.

    Returns
    -------
    str
        The format, or ``""`` if none matches.

    Examples
    --------
    >>> import numpy as np
    >>> detect(write_tensor_file({})), detect(np.array([90, 90, 180], "<i4").tobytes()), detect(b"abc")
    ('rgl', 'merl', '')
    """
    if is_tensor_file(data):
        return "rgl"
    if is_merl(data):
        return "merl"
    if is_utia(data):
        return "utia"
    return ""


def load(path: str | os.PathLike) -> MeasuredBRDF:
    """Read a measured BRDF, recognising its format by content.

    Parameters
    ----------
    path : str or PathLike
        A MERL ``.binary`` (plain or gzip-compressed), RGL ``.bsdf`` or UTIA ``.bin`` file.

    Returns
    -------
    MERLBRDF, RGLBRDF or UTIABRDF

    Raises
    ------
    MicrofacetError
        Unreadable or unknown file, bad header or size, truncated data, NaN/inf values.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.kernels_extra import synthetic_rgl
    >>> with open("synthetic.bsdf", "wb") as f:      # a small RGL file made here
    ...     _ = f.write(write_tensor_file(synthetic_rgl(np.random.default_rng(0))))
    >>> brdf = load("synthetic.bsdf")
    >>> brdf, brdf.format, brdf.description
    (RGLBRDF('synthetic.bsdf'), 'rgl', 'synthetic material')
    >>> brdf.eval(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])).round(3)
    array([0.718, 0.845, 0.802])
    >>> load("merl/chrome.binary")   # needs a MERL file  # doctest: +SKIP
    MERLBRDF('merl/chrome.binary')
    """
    return load_bytes(read_decompressed(path, MEASURED_BRDF), path)


def load_bytes(data: bytes, path: str | os.PathLike) -> MeasuredBRDF:
    """:func:`load` of the file's uncompressed bytes ``data`` (``path`` names it in errors).

    Parameters
    ----------
    data : bytes
        Uncompressed file content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    MeasuredBRDF
        A :class:`MERLBRDF`, :class:`RGLBRDF` or :class:`UTIABRDF`.

    Examples
    --------
    >>> load_bytes(b"not a BRDF", "x.bin")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: x.bin: unknown measured-BRDF format (10 bytes; expected a MERL .binary(.gz) with header (90, 90, 180), an RGL tensor_file .bsdf, or a 1990656-byte UTIA .bin)
    """
    kind = detect(data)
    if kind == "rgl":
        return RGLBRDF(read_rgl(data, path), path)
    if kind == "merl":
        return MERLBRDF(*read_merl(data, path), path)
    if kind == "utia":
        return UTIABRDF(read_utia(data, path), path)
    raise file_error(path, f"unknown measured-BRDF format ({len(data)} bytes; expected a MERL "
                           ".binary(.gz) with header (90, 90, 180), an RGL tensor_file .bsdf, "
                           f"or a {UTIA_BYTES}-byte UTIA .bin)")



