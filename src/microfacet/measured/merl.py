"""MERL isotropic BRDFs (Matusik et al. 2003): ``.binary`` files, plain or gzip-compressed.

Format: 3 little-endian int32 ``(90, 90, 180)`` (bins of theta_h, theta_d, phi_d), then
``3 * 90 * 90 * 180`` little-endian float64, planar R, G, B; sample
``(i_h, i_d, i_phi)`` sits at index ``i_phi + 180 (i_d + 90 i_h)``, at

* ``theta_h = (i_h / 90)^2 pi / 2`` (non-linear: the index is ``90 sqrt(theta_h / (pi/2))``),
* ``theta_d = i_d / 90 * pi / 2``,
* ``phi_d = i_phi / 180 * pi`` (folded to ``[0, pi)`` by reciprocity, ``phi_d ~ phi_d + pi``),

in the Rusinkiewicz halfway/difference coordinates of ``(wi, wo)`` (thesis Eq. 1.8).
Physical value = raw x ``(1/1500, 1.15/1500, 1.66/1500)`` per channel; negative raw
values mark samples that were not measured.

Evaluation is trilinear in the index coordinates ``(u_h, u_d, u_phi)``: periodic in
``phi_d`` (period 180 bins), clamped to the last bin beyond ``theta_h, theta_d`` index 89.
**Unmeasured samples are missing data**: they get weight 0 and the weights of the
measured corners are renormalized; where all 8 corners are unmeasured the BRDF is 0.
:meth:`MERLBRDF.coverage` returns the measured share of the interpolation weights
(1: fully measured, 0: no data) so a fitter can drop or down-weight such directions;
``valid`` is the per-sample mask. Samples where both directions graze the horizon are
noisy in real MERL data (and unreliable in the neural-fit files of ``../shared/data``);
the reader returns them as stored: weighting or clipping them is the fitter's choice.

Examples
--------
>>> SHAPE, SCALE * 1500
((90, 90, 180), array([1.  , 1.15, 1.66]))
"""
from __future__ import annotations

import hashlib
import threading

import numpy as np

from .._colour import LUMINANCE
from ..geometry import half_vector
from .base import MeasuredBRDF, as_dirs, check_finite, compiled_kernels, file_error
from .grids import MERL_SHAPE

__all__ = ["MERLBRDF", "SHAPE", "SCALE", "SEAM_LIMIT", "is_merl", "read_merl"]

SHAPE = MERL_SHAPE                                      # (theta_h, theta_d, phi_d) bins
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
HEADER = np.array(SHAPE, dtype="<i4").tobytes()
N_SAMPLES = SHAPE[0] * SHAPE[1] * SHAPE[2]
N_BYTES = len(HEADER) + 3 * N_SAMPLES * 8             # 34,992,012
#: A :meth:`MERLBRDF.fold_seam` above this (a jump of 10 % across the fold) marks a table
#: that is not reciprocal (one bin's step is ~1e-4; the corpus networks' median seam is 0.02).
SEAM_LIMIT = 0.1


def is_merl(data: bytes) -> bool:
    """Whether ``data`` (uncompressed) look like a MERL file: the header ``(90, 90, 180)``,
    or any 3 positive int32 bin counts that match the file size (then :func:`read_merl`
    reports the unsupported resolution).

    Parameters
    ----------
    data : bytes
        Uncompressed file content.

    Returns
    -------
    bool
        Whether it looks like a MERL file.

    Examples
    --------
    >>> import numpy as np
    >>> header = np.array(SHAPE, "<i4").tobytes()
    >>> is_merl(header + bytes(3 * 90 * 90 * 180 * 8)), is_merl(header)
    (True, True)
    """
    if data[:12] == HEADER:
        return True
    dims = np.frombuffer(data[:12], dtype="<i4") if len(data) >= 12 else np.zeros(0)
    return len(dims) == 3 and bool(np.all(dims > 0)) and 12 + 24 * int(np.prod(dims, dtype=np.int64)) == len(data)


def read_merl(data: bytes, path) -> tuple[np.ndarray, np.ndarray]:
    """Physical RGB values ``(90, 90, 180, 3)`` and the measured mask ``(90, 90, 180)``.

    ``data`` are the uncompressed file bytes; ``path`` only names the file in errors.

    Parameters
    ----------
    data : bytes
        Uncompressed file content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    rgb : (90, 90, 180, 3) ndarray
        Physical RGB values.
    valid : (90, 90, 180) ndarray of bool
        Measured mask.

    Examples
    --------
    >>> import gzip
    >>> data = gzip.open("merl/chrome.binary.gz").read()   # needs a MERL file  # doctest: +SKIP
    >>> values, valid = read_merl(data, "chrome.binary")   # doctest: +SKIP
    >>> values.shape, valid.shape                          # doctest: +SKIP
    ((90, 90, 180, 3), (90, 90, 180))
    """
    if len(data) < 12:
        raise file_error(path, f"not a MERL .binary file: {len(data)} bytes, too short for its header")
    dims = tuple(np.frombuffer(data[:12], dtype="<i4").tolist())
    if dims != SHAPE:
        raise file_error(path, f"MERL header gives bin counts {dims}, expected {SHAPE}")
    if len(data) != N_BYTES:
        kind = "truncated" if len(data) < N_BYTES else "has trailing bytes"
        raise file_error(path, f"MERL file {kind}: {len(data)} bytes, expected {N_BYTES}")
    raw = np.frombuffer(data, dtype="<f8", offset=12).reshape((3,) + SHAPE)
    check_finite(path, raw, "MERL data")
    rgb = np.moveaxis(raw, 0, -1) * SCALE                 # channels last: one gather per corner
    valid = (raw >= 0).all(axis=0)
    return rgb, valid


def hd_coordinates(wi, wo) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rusinkiewicz ``(theta_h, theta_d, phi_d)`` of ``(wi, wo)`` (Eq. 1.8), ``phi_d``
    folded to ``[0, pi)``.

    ``d = Rot_y(-theta_h) Rot_z(-phi_h) wi`` as :func:`microfacet.geometry.io_to_hd`, with
    the rotations written with ``cos phi_h = x_h / r``, ``sin phi_h = y_h / r``,
    ``cos theta_h = z_h``, ``sin theta_h = r = |(x_h, y_h)|`` instead of trigonometric
    calls; angles by ``atan2`` (exact near the poles, where ``arccos`` loses half the digits).
    """
    wi = np.asarray(wi, dtype=np.float64)
    h = half_vector(wi, wo)
    r = np.hypot(h[..., 0], h[..., 1])
    pole = r == 0                                      # phi_h undefined: take 0
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_ph = np.where(pole, 1.0, h[..., 0] / r)
        sin_ph = np.where(pole, 0.0, h[..., 1] / r)
    a = cos_ph * wi[..., 0] + sin_ph * wi[..., 1]      # Rot_z(-phi_h) wi
    b = cos_ph * wi[..., 1] - sin_ph * wi[..., 0]
    dx, dz = h[..., 2] * a - r * wi[..., 2], r * a + h[..., 2] * wi[..., 2]   # Rot_y(-theta_h)
    theta_h = np.arctan2(r, h[..., 2])
    theta_d = np.arctan2(np.hypot(dx, b), dz)
    return theta_h, theta_d, np.mod(np.arctan2(b, dx), np.pi)


def grid_coordinates(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous bin indices ``(u_h, u_d, u_phi)``: ``90 sqrt(2 theta_h / pi)``,
    ``90 (2 theta_d / pi)``, ``180 phi_d / pi``."""
    u_h = SHAPE[0] * np.sqrt(np.maximum(theta_h, 0.0) / (np.pi / 2))
    u_d = SHAPE[1] * (theta_d / (np.pi / 2))
    u_phi = SHAPE[2] * (np.mod(phi_d, np.pi) / np.pi)
    return u_h, u_d, u_phi


def _axis_clamped(u, n: int):
    """Lower/upper nodes and upper weight of linear interpolation on ``0..n-1``, clamped."""
    u = np.clip(u, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(u).astype(np.intp), n - 2)
    return i0, i0 + 1, u - i0


def _axis_periodic(u, n: int):
    """Nodes and weight of linear interpolation on a periodic axis of ``n`` nodes."""
    u = np.mod(u, n)
    i0 = np.floor(u).astype(np.intp) % n
    return i0, (i0 + 1) % n, u - np.floor(u)


#: Direction sets whose interpolation :class:`MERLBRDF` remembers, and the most pairs a
#: remembered set may hold (2^18 pairs: 8 MiB of results; a fit's sets hold at most 131,072).
CACHE_SIZE, CACHE_MAX_PAIRS = 4, 1 << 18
#: Pairs interpolated at a time on the NumPy path: a block's temporaries (the corners'
#: indices, weights and values, ~1 MB) stay in the CPU's caches and are reused by the
#: allocator, where those of a whole set of pairs are fresh pages at every call.
BLOCK = 8192


def _digest(wi: np.ndarray, wo: np.ndarray) -> tuple:
    """Key of a direction set: shape and SHA-1 of the bytes of ``wi`` and ``wo`` (a small
    fraction of the interpolation's cost)."""
    h = hashlib.sha1()
    for a in (wi, wo):
        h.update(np.ascontiguousarray(a, dtype=np.float64))
    return wi.shape, h.digest()


class MERLBRDF(MeasuredBRDF):
    """A MERL ``.binary`` BRDF, trilinearly interpolated in ``(u_h, u_d, u_phi)``.

    Parameters
    ----------
    values : (90, 90, 180, 3) ndarray
        Physical RGB values (:func:`read_merl`).
    valid : (90, 90, 180) ndarray of bool
        Measured mask.
    path : str or os.PathLike
        The file, for messages and ``repr``.

    Attributes
    ----------
    values : ndarray, (90, 90, 180, 3)
        Physical RGB BRDF values (raw x scale); unmeasured samples keep their negative value.
    valid : ndarray of bool, (90, 90, 180)
        True where all three channels were measured (raw value >= 0).
    theta_h, theta_d, phi_d : ndarray
        Sample positions (radians) of the three axes.

    Examples
    --------
    >>> import numpy as np
    >>> brdf = MERLBRDF(np.full(SHAPE + (3,), 0.1), np.ones(SHAPE, bool))  # 35 MB table, ~1 s  # doctest: +SKIP
    >>> brdf.eval(np.array([0.6, 0.0, 0.8]), np.array([0.0, 0.6, 0.8]))                  # doctest: +SKIP
    array([0.1, 0.1, 0.1])
    """

    format = "merl"

    def __init__(self, values: np.ndarray, valid: np.ndarray, path=""):
        super().__init__(path)
        self.values = values
        self.valid = valid
        self.theta_h = (np.arange(SHAPE[0]) / SHAPE[0]) ** 2 * (np.pi / 2)
        self.theta_d = np.arange(SHAPE[1]) / SHAPE[1] * (np.pi / 2)
        self.phi_d = np.arange(SHAPE[2]) / SHAPE[2] * np.pi
        # one gather per corner: [R, G, B, 1] on measured samples, 0 on unmeasured ones
        table = np.empty(SHAPE + (4,))          # C order: a sample's 4 values share a cache line
        table[..., :3], table[..., 3] = values, 1.0
        self._table = table.reshape(-1, 4)
        self._table *= valid.reshape(-1, 1)
        self._cache = {}                        # digest of (wi, wo) -> (f_r, coverage)
        self._cache_lock = threading.Lock()

    def _corners(self, wi, wo):
        """Flat indices ``(8, ...)`` and trilinear weights ``(8, ...)`` of the samples
        around each direction pair."""
        u_h, u_d, u_phi = grid_coordinates(*hd_coordinates(wi, wo))
        (h0, h1, th), (d0, d1, td), (p0, p1, tp) = (
            _axis_clamped(u_h, SHAPE[0]), _axis_clamped(u_d, SHAPE[1]), _axis_periodic(u_phi, SHAPE[2]))
        idx, w = [], []
        for ih, wh in ((h0, 1 - th), (h1, th)):
            for jd, wd in ((d0, 1 - td), (d1, td)):
                for kp, wp in ((p0, 1 - tp), (p1, tp)):
                    idx.append(kp + SHAPE[2] * (jd + SHAPE[1] * ih))
                    w.append(wh * wd * wp)
        return np.stack(idx), np.stack(w)

    def _interpolate(self, wi, wo):
        """``(f_r, coverage)``: the validity-weighted trilinear interpolation, remembered for
        the last :data:`CACHE_SIZE` direction sets of at most :data:`CACHE_MAX_PAIRS` pairs
        (by content: a fit evaluates the data and their coverage on the same pairs, and its
        metrics revisit the same grid). Returns new arrays."""
        wi, wo = as_dirs(wi, "wi"), as_dirs(wo, "wo")
        wi, wo = np.broadcast_arrays(wi, wo)
        if wi.size > 3 * CACHE_MAX_PAIRS:
            return self._interpolate_uncached(wi, wo)
        key = _digest(wi, wo)
        with self._cache_lock:
            hit = self._cache.pop(key, None)
        if hit is None:
            hit = self._interpolate_uncached(wi, wo)
        with self._cache_lock:
            self._cache.pop(key, None)
            while len(self._cache) >= CACHE_SIZE:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = hit                      # most recent last
        return hit[0].copy(), hit[1].copy()

    def _interpolate_uncached(self, wi, wo):
        """:meth:`_interpolate` of broadcast unit ``wi``, ``wo``, computed in blocks of
        :data:`BLOCK` pairs (:meth:`_interpolate_block`)."""
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        f, cover = np.empty((len(wi), 3)), np.empty(len(wi))
        for s in range(0, len(wi), BLOCK):
            f[s:s + BLOCK], cover[s:s + BLOCK] = self._interpolate_block(wi[s:s + BLOCK], wo[s:s + BLOCK])
        return f.reshape(shape + (3,)), cover.reshape(shape)

    def _interpolate_block(self, wi, wo):
        """``(f_r, coverage)`` of unit ``wi``, ``wo`` ``(M, 3)``."""
        idx, w = self._corners(wi, wo)
        corners = np.take(self._table, idx, axis=0)       # (take: ~6x faster than fancy indexing here)
        f = np.einsum("k...,k...c->...c", w, corners)     # unmeasured corners weigh 0
        f, cover = f[..., :3], f[..., 3]
        f = np.divide(f, cover[..., None], out=np.zeros_like(f), where=cover[..., None] > 0)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(up[..., None], f, 0.0), np.where(up, cover, 0.0)

    def _eval_numpy(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo)``, RGB ``(..., 3)``: trilinear interpolation of the measured
        samples around the Rusinkiewicz coordinates of ``(wi, wo)``; 0 below either horizon
        or where no surrounding sample was measured."""
        return self._interpolate(wi, wo)[0]

    def _kernel(self):
        k = compiled_kernels()
        return None if k is None else (k.eval_table, k.sample_table, (k.MERL, self._table))

    def coverage(self, wi, wo) -> np.ndarray:
        """Share of the trilinear weight on measured samples, in ``[0, 1]`` (0 below the
        horizon): 1 where :meth:`eval` rests on measured data only.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions.

        Returns
        -------
        (...) ndarray
            Measured share in ``[0, 1]``.
        """
        return self._interpolate(wi, wo)[1]

    def fold_seam(self) -> float:
        """The table's jump across its ``phi_d`` fold: the median, over the rows
        ``(theta_h, theta_d)`` measured at both ends, of ``|ln Y(phi_d = 0) - ln Y(phi_d =
        179 deg)|`` (``Y``: luminance).

        A reciprocal isotropic BRDF is continuous across the fold (``f(phi_d) = f(phi_d +
        pi)`` by reciprocity and ``= f(-phi_d)`` by isotropy, so ``f(pi^-) = f(0^+)``): its
        seam is about one bin's step (:data:`SEAM_LIMIT`). A table that is not (a network
        fitted to measurements over all of ``[0, 2 pi)``, then sampled on ``[0, pi)``) jumps
        there, and no reciprocal model follows both sides: at normal view every light reads
        ``phi_d = 0``, half a degree off it half of them read the other side. Exact (a
        median over the table's samples); ~0.1 s.

        Returns
        -------
        float
            The median jump in ``ln`` luminance (0.35: a factor 1.4); NaN where no row is
            measured at both ends.

        References
        ----------
        Rusinkiewicz 1998 (the halfway/difference coordinates); Matusik et al. 2003 (the
        table, folded in ``phi_d`` by reciprocity).

        Examples
        --------
        >>> import numpy as np
        >>> phi, measured = np.arange(SHAPE[2]) / SHAPE[2] * np.pi, np.ones(SHAPE, bool)
        >>> def table(f):
        ...     return MERLBRDF(np.broadcast_to(f[:, None], SHAPE + (3,)), measured)
        >>> round(table(1.0 + 0.5 * np.cos(2.0 * phi)).fold_seam(), 4)   # reciprocal: one bin's step
        0.0002
        >>> seam = table(1.0 + 0.5 * np.cos(phi)).fold_seam()           # not: 1.5 at 0, 0.5 at pi
        >>> round(seam, 4), seam > SEAM_LIMIT
        (1.0985, True)
        """
        both = self.valid[:, :, 0] & self.valid[:, :, -1]
        luminance = self.values[:, :, [0, -1]][both] @ LUMINANCE   # (rows, 2)
        ok = np.all(luminance > 0.0, axis=1)
        if not np.any(ok):
            return float("nan")
        return float(np.median(np.abs(np.log(luminance[ok, 0] / luminance[ok, 1]))))
