"""Normal maps: the one decoder of the library (``bake``, ``glints``, :mod:`microfacet.leadr`,
:mod:`microfacet.glints`), so that every command reads a given map the same way.

Encodings (``encoding``)
------------------------
- ``"biased"`` (alias ``"offset"``): each channel stores ``(n + 1) / 2``, as ``v / 255`` or
  ``v / 65535`` in an 8/16-bit PNG or as a float in an EXR; ``n = 2 v - 1``.
- ``"signed"``: a float EXR storing ``n`` itself.
- ``"auto"`` (default), by content, one decision for the whole map: integer samples are
  biased. Float samples are signed if a tangent channel (R or G) holds a value below
  ``-0.01`` (biased values lie in ``[0, 1]``). Otherwise, when ``z`` is stored, the reading
  whose vectors are closer to unit length (median of ``| |n| - 1 |`` over up to 65536
  evenly spaced texels) wins, biased on a tie; when ``z`` is rebuilt, the map is biased if
  the means of R and G both lie within 0.25 of 0.5 (a biased map's mean is 0.5 plus half
  its mean tangent component) and signed otherwise (e.g. a nearly flat map of ``n``).

The z channel (``z``)
---------------------
- ``"stored"``: the third channel holds ``n_z`` (same encoding as R and G).
- ``"reconstruct"``: ``n_z = sqrt(1 - n_x^2 - n_y^2)`` from R and G.
- ``"auto"`` (default): reconstruct for two-channel maps and for maps whose third channel
  is constant while R or G varies (a placeholder blue channel, as in
  ``glitterman_isotropic_large.png``); stored otherwise. A fourth channel (alpha) is ignored.

Per texel (never a switch of the whole map's reading)
-----------------------------------------------------
- Stored ``z``: the vector ``(n_x, n_y, n_z)`` is renormalized to unit length, which keeps
  its slope ``(-n_x / n_z, -n_y / n_z)``: maps of non-unit vectors (8-bit quantization,
  ``glitterman_scratches.png`` with lengths 0.49-1.46) read as their directions.
- A texel is **repaired** when it has no usable direction: ``n_z <= 0`` (facing away), a
  zero vector, ``x^2 + y^2 > 1`` when ``z`` is reconstructed, or any normal more than
  :data:`MAX_THETA_DEG` = 89 degrees from the macro normal. It is clamped to 89 degrees
  (slope ``tan 89deg = 57.3``), keeping its azimuth ``atan2(n_y, n_x)``; a texel without
  an azimuth (a zero vector or one pointing straight down) becomes ``(0, 0, 1)``. The
  other texels are untouched.

Report and warnings
-------------------
:func:`decode_normals` returns a :class:`NormalMapReport` and, with ``warn=True``, emits
each of its one-line :class:`~microfacet.errors.NormalMapWarning` s naming the file: the
number (and percentage) of repaired texels; decoded vectors far from unit length on
average (mean length ``|v|`` outside ``1 +- 0.1``, stored ``z``; the shipped 8-bit
``glitterman_scratches.png`` has 1.015, a biased map read as signed about 1.22); most
texels facing away (more than half with ``n_z <= 0``, or ``x^2 + y^2 > 1`` when ``z`` is
reconstructed). The last two mean the map looks inconsistent: a wrong ``encoding`` or ``z``.

Examples
--------
>>> from microfacet.io.normalmap import ENCODINGS, Z_SOURCES, MAX_THETA_DEG
>>> ENCODINGS, Z_SOURCES, MAX_THETA_DEG
(('auto', 'biased', 'signed', 'offset'), ('auto', 'stored', 'reconstruct'), 89.0)
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import MicrofacetError, NormalMapWarning
from .image import read_image

__all__ = ["decode_normals", "read_normals", "read_slopes", "normals_to_slopes", "NormalMapReport",
           "ENCODINGS", "Z_SOURCES", "MAX_THETA_DEG"]

#: Accepted ``encoding`` values (``"offset"`` is an alias of ``"biased"``).
ENCODINGS = ("auto", "biased", "signed", "offset")
#: Accepted ``z`` values.
Z_SOURCES = ("auto", "stored", "reconstruct")
#: Repaired texels face at most this far from the macro normal (degrees).
MAX_THETA_DEG = 89.0
_COS_MAX, _SIN_MAX = np.cos(np.radians(MAX_THETA_DEG)), np.sin(np.radians(MAX_THETA_DEG))
_SIGNED_BELOW = -0.01      # a float tangent channel below this is signed data
_BIASED_MEAN_TOL = 0.25    # |mean(R, G) - 0.5| of biased float data
_LENGTH_SAMPLES = 65536    # texels (at most about) whose lengths decide the encoding
_LENGTH_TOL = 0.1          # | mean |v| - 1 | above this: far from unit length
_CONSTANT = 1e-6           # a float channel whose range is below this is constant
_TINY = np.finfo(np.float64).tiny


@dataclass(frozen=True)
class NormalMapReport:
    """How a normal map was decoded (module docstring).

    ``encoding`` and ``z`` are the readings used (``"biased"``/``"signed"``,
    ``"stored"``/``"reconstruct"``), ``detected`` whether the encoding was chosen by
    content; ``repaired`` counts the clamped texels, ``facing_away`` those with ``n_z <= 0``
    (or ``x^2 + y^2 > 1`` with ``z`` reconstructed); ``mean_length`` is the mean length of the
    decoded vectors before renormalization (``None`` when ``z`` is reconstructed).

    Parameters
    ----------
    source : str
        The file name (or a description of the array).
    shape : (int, int)
        ``(H, W)`` of the map.
    encoding : str
        ``"biased"`` or ``"signed"``.
    detected : bool
        Whether the encoding was chosen by content.
    z : str
        ``"stored"`` or ``"reconstruct"``.
    repaired : int
        Texels clamped.
    facing_away : int
        Texels facing away (see above).
    mean_length : float or None
        Mean decoded length before renormalization.

    Examples
    --------
    >>> import numpy as np
    >>> _, report = decode_normals(np.full((2, 2, 3), (128, 128, 255), np.uint8), source="flat.png")
    >>> report.source, report.shape, report.encoding, report.repaired
    ('flat.png', (2, 2), 'biased', 0)
    """
    source: str
    shape: tuple[int, int]
    encoding: str
    detected: bool
    z: str
    repaired: int
    facing_away: int
    mean_length: float | None

    @property
    def texels(self) -> int:
        return self.shape[0] * self.shape[1]

    @property
    def warnings(self) -> tuple[str, ...]:
        """One-line warnings: repaired texels, far from unit length, most facing away."""
        out = []
        reading = f"{self.encoding} encoding, z {self.z}"
        if self.repaired:
            out.append(f"{self.source}: {self.repaired} of {self.texels} texels "
                       f"({100.0 * self.repaired / self.texels:.3g} %) repaired: facing away or beyond "
                       f"{MAX_THETA_DEG:g} deg from the normal, clamped to {MAX_THETA_DEG:g} deg")
        if self.mean_length is not None and abs(self.mean_length - 1.0) > _LENGTH_TOL:
            out.append(f"{self.source}: decoded normals are far from unit length (mean length "
                       f"{self.mean_length:.3g}, {reading}); is the encoding right?")
        if 2 * self.facing_away > self.texels:
            out.append(f"{self.source}: most normals ({100.0 * self.facing_away / self.texels:.3g} %) "
                       f"face away from the surface ({reading}); are the encoding and z channel right?")
        return tuple(out)

    def __str__(self) -> str:
        how = "by content" if self.detected else "as given"
        return (f"{self.source}: {self.shape[1]} x {self.shape[0]}, {self.encoding} encoding ({how}), "
                f"z {self.z}, {self.repaired} of {self.texels} texels repaired")


def _unit_length_error(n: np.ndarray) -> float:
    """Median of ``| |n| - 1 |`` of vectors ``n (N, 3)``."""
    return float(np.median(np.abs(np.linalg.norm(n, axis=-1) - 1.0)))


def _resolve_encoding(a: np.ndarray, encoding: str, z: str, where: str) -> tuple[str, bool]:
    """``(encoding, detected)`` of samples ``a`` whose ``n_z`` is ``z`` (module docstring,
    "Encodings")."""
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS}, got {encoding!r}")
    encoding = "biased" if encoding == "offset" else encoding
    if a.dtype.kind == "u":
        if encoding == "signed":
            raise MicrofacetError(f"{where}8/16-bit normal maps store (n + 1) / 2; 'signed' needs float data")
        return "biased", encoding == "auto"
    if encoding != "auto":
        return encoding, False
    tangent = a[..., :2]
    if tangent.min() < _SIGNED_BELOW:
        return "signed", True
    if z == "stored":
        v = a.reshape(-1, 3)[::max(1, a.shape[0] * a.shape[1] // _LENGTH_SAMPLES)].astype(np.float64)
        return ("signed" if _unit_length_error(v) < _unit_length_error(2.0 * v - 1.0) else "biased"), True
    mean = tangent.mean(axis=(0, 1))
    return ("biased" if np.all(np.abs(mean - 0.5) <= _BIASED_MEAN_TOL) else "signed"), True


def _components(a: np.ndarray, encoding: str) -> np.ndarray:
    """Decoded components ``n`` ``(H, W, 3)`` float64 of samples ``a (H, W, 2|3)``: ``2 v - 1``
    (biased) or ``v`` (signed), ``v`` scaled to ``[0, 1]`` for integers; a missing third
    channel is 0 (rebuilt later). One buffer, decoded in place."""
    n = np.zeros(a.shape[:2] + (3,))
    c = a.shape[2]
    n[..., :c] = a
    if a.dtype.kind == "u":
        n[..., :c] *= 1.0 / np.iinfo(a.dtype).max
    if encoding == "biased":
        n[..., :c] *= 2.0
        n[..., :c] -= 1.0
    return n


def _placeholder_z(a: np.ndarray) -> bool:
    """Whether the third channel of samples ``a (H, W, 3)`` is constant while R or G varies."""
    tol = 0 if a.dtype.kind == "u" else _CONSTANT
    return bool(np.ptp(a[..., 2]) <= tol < max(np.ptp(a[..., 0]), np.ptp(a[..., 1])))


def _clamp_to_max_angle(n: np.ndarray) -> int:
    """Clamp, in place, the unit normals ``n (..., 3)`` with ``n_z < cos 89deg`` (or NaN) to
    89 degrees, keeping the azimuth; ``(0, 0, 1)`` when there is none. Returns their count."""
    bad = ~(n[..., 2] >= _COS_MAX)
    m = n[bad]
    t = np.hypot(m[:, 0], m[:, 1])
    has_azimuth = t > 0
    scale = np.divide(_SIN_MAX, t, out=np.zeros_like(t), where=has_azimuth)
    m[:, 0] *= scale
    m[:, 1] *= scale
    m[:, 2] = np.where(has_azimuth, _COS_MAX, 1.0)
    n[bad] = m
    return int(bad.sum())


def decode_normals(image, encoding: str = "auto", z: str = "auto", *, source: str | None = None,
                   warn: bool = True) -> tuple[np.ndarray, NormalMapReport]:
    """Unit normals ``(H, W, 3)`` float64 of a normal map's samples, and how it was read.

    The inverse of the encoding of Dupuy 2015, Listing 3.6 (``(n + 1) / 2`` per channel) or
    of a float map of ``n``. Every texel is a unit vector at most 89 degrees from
    ``(0, 0, 1)`` (so its slope, Eq. 2.9, is finite): non-unit vectors are renormalized and
    unusable ones repaired, each on its own (module docstring).

    Parameters
    ----------
    image : array_like
        ``(H, W, C)``, ``C`` = 2, 3 or 4, ``uint8``/``uint16`` or float (as stored in the file).
    encoding : {"auto", "biased", "signed", "offset"}
        ``(n + 1) / 2`` stored, ``n`` stored, or by content (module docstring).
    z : {"auto", "stored", "reconstruct"}
        Where ``n_z`` comes from (module docstring).
    source : str, optional
        The file name, for messages.
    warn : bool
        Emit the report's warnings (:class:`~microfacet.errors.NormalMapWarning`).

    Returns
    -------
    normals : (H, W, 3) float64
        Unit normals.
    report : NormalMapReport
        How the map was read (encoding, z source, texels repaired or facing away).

    Raises
    ------
    MicrofacetError
        Naming ``source``, for a wrong shape, dtype or non-finite samples.
    ValueError
        For an unknown ``encoding`` or ``z``.

    Examples
    --------
    >>> import numpy as np
    >>> texels = np.full((2, 2, 3), (128, 128, 255), np.uint8)     # the flat colour of a biased map
    >>> normals, report = decode_normals(texels)
    >>> normals[0, 0].round(3), report.encoding
    (array([0.004, 0.004, 1.   ]), 'biased')
    """
    where = f"{source}: " if source else ""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] not in (2, 3, 4) or 0 in a.shape:
        raise MicrofacetError(f"{where}a normal map needs 2 to 4 channels (H, W, R G[ B[ A]]), got shape {a.shape}")
    if a.dtype not in (np.uint8, np.uint16) and a.dtype.kind != "f":
        raise MicrofacetError(f"{where}normal maps are uint8, uint16 or float, got {a.dtype}")
    if z not in Z_SOURCES:
        raise ValueError(f"z must be one of {Z_SOURCES}, got {z!r}")
    c = min(a.shape[2], 3)
    a = a[..., :c]
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise MicrofacetError(f"{where}a normal map must be finite (found NaN or inf)")
    if z == "stored" and c < 3:
        raise MicrofacetError(f"{where}z='stored' needs a third channel, the map has {c}")
    if z == "auto":
        z = "stored" if c == 3 and not _placeholder_z(a) else "reconstruct"
    encoding, detected = _resolve_encoding(a, encoding, z, where)
    n = _components(a, encoding)
    if z == "stored":
        facing_away = int(np.count_nonzero(n[..., 2] <= 0))
        length = np.sqrt(np.einsum("...i,...i->...", n, n))
        mean_length = float(length.mean())
        np.divide(n, np.maximum(length, _TINY)[..., None], out=n)      # zero vectors stay 0: repaired
    else:
        r2 = n[..., 0] ** 2 + n[..., 1] ** 2
        facing_away = int(np.count_nonzero(r2 > 1.0))
        n[..., 2] = np.sqrt(np.maximum(1.0 - r2, 0.0))
        mean_length = None
    repaired = _clamp_to_max_angle(n)
    report = NormalMapReport(source or "array", tuple(int(s) for s in a.shape[:2]), encoding, detected,
                             z, repaired, facing_away, mean_length)
    if warn:
        for message in report.warnings:
            warnings.warn(message, NormalMapWarning, stacklevel=2)
    return n, report


def read_normals(path_or_image, encoding: str = "auto", z: str = "auto", *,
                 warn: bool = True) -> tuple[np.ndarray, NormalMapReport]:
    """Unit normals ``(H, W, 3)`` and report of a normal map file (8/16-bit PNG or EXR, by
    content) or array: :func:`decode_normals` of its samples.

    Parameters
    ----------
    path_or_image : str, os.PathLike or array_like
        A PNG/EXR file or its samples.
    encoding, z, warn
        As :func:`decode_normals`.

    Returns
    -------
    normals : (H, W, 3) ndarray
        Unit normals.
    report : NormalMapReport
        How the map was read.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.io import write_png_data
    >>> _ = write_png_data("flat.png", np.full((4, 4, 3), (128, 128, 255), np.uint8))
    >>> normals, report = read_normals("flat.png")
    >>> normals.shape, report.shape
    ((4, 4, 3), (4, 4))
    """
    if isinstance(path_or_image, (str, os.PathLike)):
        return decode_normals(read_image(path_or_image), encoding, z, source=str(path_or_image), warn=warn)
    return decode_normals(path_or_image, encoding, z, warn=warn)


def normals_to_slopes(normals) -> np.ndarray:
    """Slopes ``(..., 2)`` ``(-n_x / n_z, -n_y / n_z)`` of upper normals ``(..., 3)`` (thesis
    Eq. 2.9, as :func:`microfacet.geometry.normal_to_slope`, into one array); decoded normals
    have ``|slope| <= tan 89deg``.

    Parameters
    ----------
    normals : (..., 3) array_like
        Unit normals with ``n_z > 0``.

    Returns
    -------
    (..., 2) ndarray
        Slopes.

    Examples
    --------
    >>> import numpy as np
    >>> normals_to_slopes(np.array([[0.6, 0.0, 0.8], [0.0, 0.0, 1.0]])).round(3)
    array([[-0.75, -0.  ],
           [-0.  , -0.  ]])
    """
    n = np.asarray(normals, dtype=np.float64)
    slopes = np.divide(n[..., :2], n[..., 2:3])
    return np.negative(slopes, out=slopes)


def read_slopes(path_or_image, encoding: str = "auto", z: str = "auto", *,
                warn: bool = True) -> tuple[np.ndarray, NormalMapReport]:
    """Texel slopes ``(H, W, 2)`` float64 and report of a normal map file or array
    (:func:`read_normals`, :func:`normals_to_slopes`).

    Parameters
    ----------
    path_or_image : str, os.PathLike or array_like
        A PNG/EXR file or its samples.
    encoding, z, warn
        As :func:`decode_normals`.

    Returns
    -------
    slopes : (H, W, 2) ndarray
        Texel slopes.
    report : NormalMapReport
        How the map was read.

    Examples
    --------
    >>> import numpy as np
    >>> n = np.zeros((2, 2, 3)); n[..., 0], n[..., 2] = -0.6, 0.8     # tilted toward -x
    >>> slopes, report = read_slopes(n, encoding="signed")
    >>> slopes[0, 0].round(3)
    array([ 0.75, -0.  ])
    """
    n, report = read_normals(path_or_image, encoding, z, warn=warn)
    return normals_to_slopes(n), report
