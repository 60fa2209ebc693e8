"""UTIA isotropic/anisotropic BRDFs (Filip & Vavra 2014): headerless ``.bin`` files.

Format: little-endian float64 of shape ``(3, 6, 48, 6, 48)`` = ``[channel, theta_i,
phi_i, theta_v, phi_v]``; ``theta = 0, 15, ..., 75`` degrees, ``phi = 0, 7.5, ...,
352.5`` degrees; 1,990,656 bytes. Physical RGB value = ``100 srgb_decode(max(raw, 0) /
140)`` (the database's own reader: clamp, divide by 140, inverse sRGB transfer, x 100).

Evaluation is quadrilinear in ``(theta_i, phi_i, theta_v, phi_v)``, periodic in the
azimuths; **elevations beyond 75 degrees are clamped to the 75 degree samples** (the data
stop there, extrapolation would be guesswork), so grazing directions get the 75 degree
values.

Examples
--------
>>> SHAPE, N_BYTES
((3, 6, 48, 6, 48), 1990656)
"""
from __future__ import annotations

import numpy as np

from ..geometry import cartesian_to_spherical
from .base import MeasuredBRDF, check_finite, compiled_kernels, file_error
from .grids import UTIA_PHI_STEP, UTIA_SHAPE, UTIA_THETA_STEP

__all__ = ["UTIABRDF", "SHAPE", "N_BYTES", "is_utia", "read_utia", "srgb_decode"]

SHAPE = UTIA_SHAPE                            # [channel, theta_i, phi_i, theta_v, phi_v]
N_BYTES = int(np.prod(SHAPE)) * 8             # 1,990,656
THETA_STEP = np.float64(UTIA_THETA_STEP)
PHI_STEP = np.float64(UTIA_PHI_STEP)


def is_utia(data: bytes) -> bool:
    """UTIA files have no header: recognised by their exact size.

    Parameters
    ----------
    data : bytes
        File content.

    Returns
    -------
    bool
        Whether its size is a UTIA file's.

    Examples
    --------
    >>> is_utia(bytes(N_BYTES)), is_utia(bytes(100))
    (True, False)
    """
    return len(data) == N_BYTES


def srgb_decode(c: np.ndarray) -> np.ndarray:
    """Inverse sRGB transfer (IEC 61966-2-1): ``c / 12.92`` up to 0.04045, else
    ``((c + 0.055) / 1.055)^2.4``.

    Parameters
    ----------
    c : ndarray
        sRGB-encoded values in ``[0, 1]``.

    Returns
    -------
    ndarray
        Linear values.

    Examples
    --------
    >>> import numpy as np
    >>> srgb_decode(np.array([0.0, 0.04, 0.5, 1.0])).round(4)
    array([0.    , 0.0031, 0.214 , 1.    ])
    """
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def read_utia(data: bytes, path) -> np.ndarray:
    """Physical RGB values, channels last: ``(6, 48, 6, 48, 3)``.

    Parameters
    ----------
    data : bytes
        Uncompressed file content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    (6, 48, 6, 48, 3) ndarray
        Physical RGB values.

    Examples
    --------
    >>> import numpy as np
    >>> raw = np.full(SHAPE, 70.0)                # raw values are sRGB-encoded, x 140
    >>> values = read_utia(raw.astype("<f8").tobytes(), "flat.bin")
    >>> values.shape, round(float(values[0, 0, 0, 0, 0]), 4)
    ((6, 48, 6, 48, 3), 21.4041)
    >>> read_utia(bytes(16), "short.bin")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: short.bin: UTIA .bin file has 16 bytes, expected 1990656 (float64 (3, 6, 48, 6, 48))
    """
    if len(data) != N_BYTES:
        raise file_error(path, f"UTIA .bin file has {len(data)} bytes, expected {N_BYTES} "
                               f"(float64 {SHAPE})")
    raw = np.frombuffer(data, dtype="<f8").reshape(SHAPE)
    check_finite(path, raw, "UTIA data")
    with np.errstate(over="ignore"):
        rgb = 100.0 * srgb_decode(np.maximum(raw, 0.0) / 140.0)
    check_finite(path, rgb, f"UTIA data (raw values up to {raw.max():.3g}) decoded to RGB")
    return np.moveaxis(rgb, 0, -1)


def _theta_axis(theta):
    """Nodes and upper weight along theta (15 degree steps), clamped to ``[0, 75]`` degrees."""
    u = np.clip(theta / THETA_STEP, 0.0, SHAPE[1] - 1.0)
    i0 = np.minimum(np.floor(u).astype(np.intp), SHAPE[1] - 2)
    return i0, i0 + 1, u - i0


def _phi_axis(phi):
    """Nodes and upper weight along the periodic phi axis (7.5 degree steps)."""
    u = np.mod(phi / PHI_STEP, SHAPE[2])
    i0 = np.floor(u).astype(np.intp)
    return i0 % SHAPE[2], (i0 + 1) % SHAPE[2], u - i0


class UTIABRDF(MeasuredBRDF):
    """A UTIA BRDF, quadrilinearly interpolated in ``(theta_i, phi_i, theta_v, phi_v)``.

    Parameters
    ----------
    values : (6, 48, 6, 48, 3) ndarray
        Physical RGB values (:func:`read_utia`).
    path : str or os.PathLike
        The file, for messages and ``repr``.

    Attributes
    ----------
    values : ndarray, (6, 48, 6, 48, 3)
        Physical RGB values ``[theta_i, phi_i, theta_v, phi_v, channel]``.

    Examples
    --------
    >>> import numpy as np
    >>> values = np.full((6, 48, 6, 48, 3), 0.2)
    >>> values[..., 0] = 0.4
    >>> brdf = UTIABRDF(values, "synthetic.bin")
    >>> brdf.eval(np.array([[0.6, 0.0, 0.8], [0.0, 0.0, -1.0]]), np.array([0.0, 0.0, 1.0]))
    array([[0.4, 0.2, 0.2],
           [0. , 0. , 0. ]])
    """

    format = "utia"

    def __init__(self, values: np.ndarray, path=""):
        super().__init__(path)
        self.values = values
        self._flat = np.ascontiguousarray(values.reshape(-1, 3))

    def _kernel(self):
        k = compiled_kernels()
        return None if k is None else (k.eval_table, k.sample_table, (k.UTIA, self._flat))

    def _eval_numpy(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo)``, RGB ``(..., 3)``: quadrilinear interpolation of the samples
        (``wi`` is UTIA's illumination, ``wo`` its view); 0 below either horizon."""
        wi, wo = np.broadcast_arrays(wi, wo)
        (ti, pi_), (tv, pv) = cartesian_to_spherical(wi), cartesian_to_spherical(wo)
        axes = (_theta_axis(ti), _phi_axis(pi_), _theta_axis(tv), _phi_axis(pv))
        strides = (SHAPE[2] * SHAPE[3] * SHAPE[4], SHAPE[3] * SHAPE[4], SHAPE[4], 1)
        f = np.zeros(wi.shape[:-1] + (3,))
        for corner in range(16):                        # the 2^4 corners of the cell
            idx, w = 0, 1.0
            for axis, ((i0, i1, t), stride) in enumerate(zip(axes, strides)):
                up = (corner >> axis) & 1
                idx = idx + stride * (i1 if up else i0)
                w = w * (t if up else 1.0 - t)
            f += w[..., None] * self._flat[idx]
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(up[..., None], f, 0.0)
