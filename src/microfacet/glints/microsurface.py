"""A normal map as a mixture of Beckmann lobes and its patch NDF (Chermain, Claux and
Mérillou 2019, Sec. 3, 4.1, 4.2.2 and 5).

Conventions
-----------
- The map covers the unit uv square: ``u`` along columns, ``v`` along rows, ``v = 0`` is
  row 0 (the top row), texel ``(row, col)`` is centred at ``((col + 1/2) / W, (row + 1/2) / H)``
  as in :mod:`microfacet.leadr.mip`. The map repeats (wrap) in both directions.
- The *interpolated normal map* is the bilinear interpolation of the texels' slopes
  ``(x~, y~) = (-n_x / n_z, -n_y / n_z)`` (the quantity whose moments the lobes carry).
- Seeds ``u_i`` lie on a regular grid of ``nx x ny`` points spaced ``h`` texels apart
  (``nx = round(W / h)``, so the spacing is ``W / nx`` texels), at the centres of the grid
  cells. Lobe ``i = iy * nx + ix``. The kernel ``k_i`` is an isotropic (in texels) Gaussian
  whose half maximum lies midway between seeds (FWHM = spacing) and whose integral is the
  cell area (Sec. 3.1).
- Lobe ``i`` is the Beckmann lobe of the five slope moments of the interpolated map under
  ``k_i / h^2`` (Eq. 3-6), with the correlation clamped to ``|rho| <= 0.99`` and the
  principal standard deviations (eigenvalues of the covariance of Eq. 5) floored at
  ``sigma_eps`` (Sec. 3.2; see :func:`_floor_moments`).
- The P-NDF of a Gaussian footprint ``k_P`` (centre in uv, covariance in uv^2) is
  ``D_P(h) = sum_i W_i D_i(h)`` with ``W_i = int k_i k_P du`` in closed form (Eq. 9):
  ``W_i = A N(u_i; c, Sigma_P + sigma_k^2 I)`` with ``A`` the cell area. By default the
  weights are normalized to sum to 1 (Sec. 4.1, "the sum of all weights is normalized");
  ``normalize=False`` gives the raw closed form, whose sum is 1 up to the ripple of the sum
  of the kernels (a few percent for footprints of about one texel) and the truncation.
- Acceleration (Sec. 5): lobes whose footprint weight is beyond ``cutoff`` standard
  deviations of ``Sigma_P + sigma_k^2 I`` (per axis) are dropped, which, the seeds being
  a regular grid, is a rectangle of lobe indices; inside it a min/max quadtree of the
  lobes' slope boxes (``mean +- slope_cutoff`` standard deviations; default 4, where
  Sec. 5 uses the 99 % box, about 3: the 4-sigma box drops 1.3e-4 of each lobe's mass,
  the 3-sigma one 5.4e-3) prunes, per half vector, the lobes whose slope box does not
  contain the half vector's slope. The cost follows the number of contributing lobes,
  not texels. The traversal is compiled (Numba, depth-first per half vector); a NumPy
  breadth-first version is its reference, and footprints of at most 16 lobes are summed
  directly (faster than any traversal).
- Sum of the kernels: with FWHM = spacing, ``sum_i k_i(u)`` ripples between 0.889 (between
  seeds) and 1.115 (on a seed), so the raw weights of footprints of about a texel do not
  sum to 1; the default normalization removes this.
"""
from __future__ import annotations

import math
import zipfile
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path

import numba
import numpy as np

from ..errors import MicrofacetError
from ..io.atomic import atomic_path
from ..io.npz import load_npz
from ..io.normalmap import read_slopes
from ..leadr.mip import mip_pyramid, mip_sizes
from ..leadr.moments import from_moments

__all__ = ["LobeMixture", "load_slopes", "interpolate_slopes", "lobe_moments", "lobe_moments_reference",
           "FORMAT_VERSION", "FWHM_PER_SIGMA", "SPACING_RANGE", "lobe_grid"]

FORMAT_VERSION = 2       # 2: float32 central moments, uncompressed; 1 (float64 raw) still loads
#: Full width at half maximum of a Gaussian in units of its standard deviation.
FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))
MAX_RHO = 0.99
_MAGIC = "microfacet.glints.Microsurface"
#: The tag that marks a file written by :meth:`Microsurface.save` (read by the fit files too).
MAGIC = _MAGIC
#: Accepted seed spacings ``h`` in texels: up to 16 lobes per texel and axis, at most one per 1e4 texels.
SPACING_RANGE = (1.0 / 16.0, 1e4)


def lobe_grid(resolution, h) -> tuple[int, int]:
    """Lobe grid ``(ny, nx) = (max(1, round(H / h)), max(1, round(W / h)))`` of a map of
    ``resolution`` ``(H, W)`` texels and seed spacing ``h`` (Sec. 3: one lobe per ``h x h``
    texels); ``ValueError`` naming ``h`` outside :data:`SPACING_RANGE`.

    Parameters
    ----------
    resolution : (int, int)
        ``(H, W)`` of the normal map.
    h : float
        Seed spacing in texels.

    Returns
    -------
    (int, int)
        ``(ny, nx)`` seeds.

    Examples
    --------
    >>> lobe_grid((512, 256), 2.0)
    (256, 128)
    """
    lo, hi = SPACING_RANGE
    try:
        v = float(h)
    except (TypeError, ValueError):
        raise ValueError(f"h (seed spacing, texels) must be a number, got {h!r}") from None
    if not lo <= v <= hi:
        raise ValueError(f"h (seed spacing, texels) must lie in [{lo:g}, {hi:g}], got {h!r}")
    hgt, wid = (int(n) for n in resolution)
    return max(1, int(round(hgt / v))), max(1, int(round(wid / v)))


def _check_layout(grid_shape, slopes_shape, h) -> None:
    """``ValueError`` unless ``slopes`` is an ``(H, W, 2)`` map whose :func:`lobe_grid` at ``h``
    is the lobe grid ``grid_shape[:2]``."""
    if len(slopes_shape) != 3 or slopes_shape[2] != 2 or 0 in slopes_shape:
        raise ValueError(f"slopes must be an (H, W, 2) array, got shape {tuple(slopes_shape)}")
    expected = lobe_grid(slopes_shape[:2], h)
    if tuple(grid_shape[:2]) != expected:
        raise ValueError(f"the lobe grid {grid_shape[0]} x {grid_shape[1]} does not match the "
                         f"{slopes_shape[0]} x {slopes_shape[1]} slope map at h={float(h):g} "
                         f"(expected {expected[0]} x {expected[1]})")


# --------------------------------------------------------------------------- normal maps
def load_slopes(path_or_array, encoding: str = "auto", z: str = "auto") -> np.ndarray:
    """Texel slopes ``(H, W, 2)`` float64 of a normal map (a PNG/EXR file or an array
    ``(H, W, 2|3|4)``), decoded by the library's one normal-map decoder
    (:func:`microfacet.io.normalmap.read_slopes`: ``encoding`` ``"auto"``, ``"biased"``
    (alias ``"offset"``) or ``"signed"``; ``z`` ``"auto"``, ``"stored"`` or ``"reconstruct"``;
    per-texel repair with a warning).

    Parameters
    ----------
    path_or_array : str, os.PathLike or (H, W, C) array
        The normal map.
    encoding : str
        ``"auto"``, ``"biased"``/``"offset"`` (``(n + 1) / 2``) or ``"signed"``.
    z : str
        ``"auto"``, ``"stored"`` or ``"reconstruct"`` (from x and y).

    Returns
    -------
    (H, W, 2) ndarray
        Slopes ``(x~, y~) = (-n_x / n_z, -n_y / n_z)``.

    Examples
    --------
    >>> import numpy as np
    >>> n = np.broadcast_to([-0.48, 0.36, 0.8], (2, 2, 3))      # signed unit normals
    >>> load_slopes(n, encoding="signed")[0, 0].round(6).tolist()
    [0.6, -0.45]
    """
    return read_slopes(path_or_array, encoding, z)[0]


def interpolate_slopes(slopes, uv) -> np.ndarray:
    """Slopes ``(..., 2)`` of the bilinearly interpolated (wrapped) map at ``uv (..., 2)``
    (texel centres at ``(i + 1/2) / W``; module conventions).

    Parameters
    ----------
    slopes : (H, W, 2) array_like
        Texel slopes (:func:`load_slopes`).
    uv : (..., 2) array_like
        Texture coordinates (wrapped).

    Returns
    -------
    (..., 2) ndarray
        The interpolated slopes.

    Examples
    --------
    Halfway between the centres of texels 0 and 1 of a row, and across the wrap:

    >>> s = np.zeros((1, 4, 2)); s[0, :, 0] = [0.0, 1.0, 2.0, 3.0]
    >>> interpolate_slopes(s, [[0.25, 0.5], [0.0, 0.5]])[:, 0].tolist()
    [0.5, 1.5]
    """
    s = np.asarray(slopes, dtype=np.float64)
    uv = np.asarray(uv, dtype=np.float64)
    hgt, wid = s.shape[:2]
    x, y = uv[..., 0] * wid - 0.5, uv[..., 1] * hgt - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0, y0 = x0.astype(np.int64) % wid, y0.astype(np.int64) % hgt
    x1, y1 = (x0 + 1) % wid, (y0 + 1) % hgt
    top = s[y0, x0] * (1 - fx) + s[y0, x1] * fx
    bottom = s[y1, x0] * (1 - fx) + s[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def _quadrature(sigma: float, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """1D offsets (texels) and normalized Gaussian weights: a uniform grid of ``samples``
    points per texel over ``+-3.5 sigma``."""
    k = int(np.ceil(3.5 * sigma * samples))
    o = np.arange(-k, k + 1) / samples
    g = np.exp(-0.5 * (o / sigma) ** 2)
    return o, g / g.sum()


def lobe_moments_reference(slopes, nx: int, ny: int, samples: int = 4) -> np.ndarray:
    """Raw moments ``(ny, nx, 5)`` of the interpolated map under each seed's normalized
    kernel (Eq. 3-6) by tensor quadrature, vectorized over seeds (NumPy reference of the
    compiled :func:`_lobe_moments`).

    Parameters
    ----------
    slopes : (H, W, 2) array_like
        Texel slopes.
    nx, ny : int
        Seeds per axis.
    samples : int
        Quadrature points per texel and axis.

    Returns
    -------
    (ny, nx, 5) ndarray
        ``E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~]`` per seed (unfloored).

    Examples
    --------
    A constant map: every lobe's mean is the slope, its variance 0:

    >>> s = np.broadcast_to([0.2, -0.1], (4, 4, 2))
    >>> lobe_moments_reference(s, 2, 2)[0, 0].round(6).tolist()
    [0.2, -0.1, 0.04, 0.01, -0.02]
    """
    s = np.asarray(slopes, dtype=np.float64)
    hgt, wid = s.shape[:2]
    hx, hy = wid / nx, hgt / ny
    sigma = hx / FWHM_PER_SIGMA        # texels (isotropic in texels; hx ~ hy)
    o, g = _quadrature(sigma, samples)
    tx = (np.arange(nx) + 0.5) * hx
    ty = (np.arange(ny) + 0.5) * hy
    out = np.zeros((ny, nx, 5))
    for a, ga in zip(o, g):
        for b, gb in zip(o, g):
            uv = np.stack(np.broadcast_arrays(((tx + a) / wid)[None, :], ((ty + b) / hgt)[:, None]), -1)
            m = interpolate_slopes(s, uv)
            x, y = m[..., 0], m[..., 1]
            out += (ga * gb) * np.stack([x, y, x * x, y * y, x * y], -1)
    return out


@numba.njit(cache=True, inline="always")
def bilinear_slopes(s, x, y):  # pragma: no cover - compiled
    """Slope ``(x~, y~)`` of the bilinearly interpolated, wrapped map ``s (H, W, 2)`` at the
    continuous texel coordinates ``(x, y)`` (texel centres at integers; compiled
    :func:`interpolate_slopes` at ``uv = ((x + 1/2) / W, (y + 1/2) / H)``)."""
    hgt, wid = s.shape[0], s.shape[1]
    x0f, y0f = np.floor(x), np.floor(y)
    fx, fy = x - x0f, y - y0f
    x0, y0 = int(x0f) % wid, int(y0f) % hgt
    x1, y1 = (x0 + 1) % wid, (y0 + 1) % hgt
    sx = ((s[y0, x0, 0] * (1 - fx) + s[y0, x1, 0] * fx) * (1 - fy)
          + (s[y1, x0, 0] * (1 - fx) + s[y1, x1, 0] * fx) * fy)
    sy = ((s[y0, x0, 1] * (1 - fx) + s[y0, x1, 1] * fx) * (1 - fy)
          + (s[y1, x0, 1] * (1 - fx) + s[y1, x1, 1] * fx) * fy)
    return sx, sy


@numba.njit(parallel=True, cache=True)
def _lobe_moments(s, nx, ny, o, g):  # pragma: no cover - compiled
    hgt, wid = s.shape[0], s.shape[1]
    hx, hy = wid / nx, hgt / ny
    out = np.zeros((ny, nx, 5))
    for iy in numba.prange(ny):
        for ix in range(nx):
            acc = np.zeros(5)
            for b in range(o.size):
                y = (iy + 0.5) * hy + o[b] - 0.5
                for a in range(o.size):
                    w = g[a] * g[b]
                    sx, sy = bilinear_slopes(s, (ix + 0.5) * hx + o[a] - 0.5, y)
                    acc[0] += w * sx
                    acc[1] += w * sy
                    acc[2] += w * sx * sx
                    acc[3] += w * sy * sy
                    acc[4] += w * sx * sy
            for c in range(5):
                out[iy, ix, c] = acc[c]
    return out


@numba.njit(parallel=True, cache=True)
def _lobe_moments_shared(s, nx, ny, px, py, g, samples, rows):  # pragma: no cover - compiled
    """The moments of :func:`_lobe_moments` (Eq. 3-6, same quadrature) when the quadrature
    points of neighbouring seeds coincide (``h * samples`` an integer: seed ``i``'s point
    ``a`` is fine sample ``i p + a - k`` of a grid of ``samples`` points per texel):
    each fine row of the interpolated map is evaluated once, convolved along x with the
    weights ``g``, and the rows are then convolved along y (the tensor weights
    ``g_a g_b`` are separable). Streams over chunks of ``rows`` seed rows, so the
    buffers stay ``O(rows * samples * nx)``. ~10x fewer interpolations than the direct sum."""
    hgt, wid = s.shape[0], s.shape[1]
    k = (g.size - 1) // 2
    mx_ = nx * px                        # fine samples per period along x
    bx, by = 0.5 * wid / nx - 0.5, 0.5 * hgt / ny - 0.5
    nf = mx_ + 2 * k                     # fine samples -k .. mx_ + k - 1 (wrapped)
    c0 = np.empty(nf, np.int64)
    c1 = np.empty(nf, np.int64)
    fx = np.empty(nf)
    for m in range(nf):
        x = bx + (m - k) / samples
        xf = np.floor(x)
        fx[m] = x - xf
        c0[m] = int(xf) % wid
        c1[m] = (c0[m] + 1) % wid
    out = np.zeros((ny, nx, 5))
    for ch in numba.prange((ny + rows - 1) // rows):
        r0 = ch * rows
        r1 = min(ny, r0 + rows)
        n0 = r0 * py - k
        buf = np.empty(((r1 - 1) * py + k - n0 + 1, nx, 5))
        f = np.empty((nf, 5))
        for j in range(buf.shape[0]):
            y = by + (n0 + j) / samples
            yf = np.floor(y)
            fy = y - yf
            y0 = int(yf) % hgt
            y1 = (y0 + 1) % hgt
            for m in range(nf):
                a0, a1, t = c0[m], c1[m], fx[m]
                sx = ((s[y0, a0, 0] * (1 - t) + s[y0, a1, 0] * t) * (1 - fy)
                      + (s[y1, a0, 0] * (1 - t) + s[y1, a1, 0] * t) * fy)
                sy = ((s[y0, a0, 1] * (1 - t) + s[y0, a1, 1] * t) * (1 - fy)
                      + (s[y1, a0, 1] * (1 - t) + s[y1, a1, 1] * t) * fy)
                f[m, 0], f[m, 1], f[m, 2], f[m, 3], f[m, 4] = sx, sy, sx * sx, sy * sy, sx * sy
            for ix in range(nx):
                m0 = ix * px
                acc0 = acc1 = acc2 = acc3 = acc4 = 0.0
                for a in range(g.size):
                    w = g[a]
                    acc0 += w * f[m0 + a, 0]
                    acc1 += w * f[m0 + a, 1]
                    acc2 += w * f[m0 + a, 2]
                    acc3 += w * f[m0 + a, 3]
                    acc4 += w * f[m0 + a, 4]
                buf[j, ix, 0], buf[j, ix, 1], buf[j, ix, 2], buf[j, ix, 3], buf[j, ix, 4] = acc0, acc1, acc2, acc3, acc4
        for iy in range(r0, r1):
            for b in range(g.size):
                j = iy * py + b - k - n0
                w = g[b]
                for ix in range(nx):
                    for c in range(5):
                        out[iy, ix, c] += w * buf[j, ix, c]
    return out


def lobe_moments(slopes, nx: int, ny: int, samples: int = 4) -> np.ndarray:
    """Raw moments ``(ny, nx, 5)`` of the interpolated map under each seed's normalized
    kernel (Eq. 3-6), compiled: :func:`_lobe_moments_shared` when ``h * samples`` is an
    integer along both axes, else the direct sum :func:`_lobe_moments`. Both equal
    :func:`lobe_moments_reference` to rounding. Float32 slopes are read as they are (the
    arithmetic is float64), others as float64.

    Parameters
    ----------
    slopes : (H, W, 2) array_like
        Texel slopes.
    nx, ny : int
        Seeds per axis.
    samples : int
        Quadrature points per texel and axis.

    Returns
    -------
    (ny, nx, 5) ndarray
        Raw moments per seed (unfloored).

    Examples
    --------
    >>> s = 0.1 * np.random.default_rng(0).standard_normal((8, 8, 2))
    >>> bool(np.allclose(lobe_moments(s, 4, 4), lobe_moments_reference(s, 4, 4)))
    True
    """
    s = np.asarray(slopes)
    s = np.ascontiguousarray(s, dtype=np.float32 if s.dtype == np.float32 else np.float64)
    hgt, wid = s.shape[:2]
    o, g = _quadrature((wid / nx) / FWHM_PER_SIGMA, int(samples))
    px, py = wid * samples / nx, hgt * samples / ny
    if abs(px - round(px)) < 1e-9 and abs(py - round(py)) < 1e-9:
        return _lobe_moments_shared(s, nx, ny, int(round(px)), int(round(py)), g, int(samples), 16)
    return _lobe_moments(s, nx, ny, o, g)


@numba.njit(cache=True)
def _floor_lobe(E, i, e2):  # pragma: no cover - compiled
    """:func:`_floor_moments` of lobe ``i`` of ``E (N, 5)`` in place (``e2 = sigma_eps^2``)."""
    m1, m2 = E[i, 0], E[i, 1]
    vx = max(E[i, 2] - m1 * m1, 0.0)
    vy = max(E[i, 3] - m2 * m2, 0.0)
    c0 = E[i, 4] - m1 * m2
    if vx * vy - c0 * c0 >= e2 * (vx + vy) and c0 * c0 <= MAX_RHO * MAX_RHO * vx * vy \
            and vx > 0.0 and vy > 0.0:
        return          # l2 >= det / (vx + vy) >= e2 and |rho| <= 0.99: already floored, unchanged
    lim = MAX_RHO * math.sqrt(vx * vy)
    cxy = min(max(c0, -lim), lim)
    half = 0.5 * (vx + vy)
    r = math.hypot(0.5 * (vx - vy), cxy)
    l2 = half - r
    if l2 < e2 * (1.0 - 1e-10):
        f1, f2 = max(half + r, e2), max(l2, e2)
        t = 0.5 * math.atan2(2.0 * cxy, vx - vy)
        c, sn = math.cos(t), math.sin(t)
        vx = max(f1 * c * c + f2 * sn * sn, e2)
        vy = max(f1 * sn * sn + f2 * c * c, e2)
        lim = MAX_RHO * math.sqrt(vx * vy)
        cxy = min(max((f1 - f2) * c * sn, -lim), lim)
    E[i, 2], E[i, 3], E[i, 4] = vx + m1 * m1, vy + m2 * m2, cxy + m1 * m2


@numba.njit(parallel=True, cache=True)
def _floor_moments_compiled(E, sigma_eps):  # pragma: no cover - compiled
    """:func:`_floor_moments` in place on ``E (N, 5)``, one lobe at a time (no temporaries)."""
    e2 = sigma_eps * sigma_eps
    for i in numba.prange(E.shape[0]):
        _floor_lobe(E, i, e2)


def _floor_moments(E: np.ndarray, sigma_eps: float) -> np.ndarray:
    """Moments whose slope covariance has ``|rho| <= 0.99`` and both *principal* standard
    deviations at least ``sigma_eps``.

    Sec. 3.2 (after Eq. 6) replaces a vanishing slope standard deviation by
    ``sigma_eps`` ("a negligible, tiny bit of roughness"): a floor, not a convolution, so
    lobes already rougher than ``sigma_eps`` are unchanged (``Sigma_i + sigma_eps^2 I``
    would widen every lobe of Eq. 4-5). The floor is applied to the eigenvalues of the
    2 x 2 covariance ``Sigma_i`` of Eq. 5, ``lambda -> max(lambda, sigma_eps^2)`` (the
    missing variance is added along each principal axis, eigenvectors kept): flooring
    ``sigma_x`` and ``sigma_y`` separately lets a correlated lobe (|rho| -> 0.99) be
    thinner than ``sigma_eps`` across its minor axis (std ``sigma sqrt(1 - |rho|)``).
    For uncorrelated lobes (``c_xy = 0``) this is the per-axis floor. The correlation is
    first clamped at 0.99 (flooring the minor eigenvalue then only lowers ``|rho|``);
    the returned moments ``E3..E5`` carry the floored covariance, so every consumer
    (parameters, slope boxes, sampling, MIP) sees the same lobe.
    """
    E = np.array(E, dtype=np.float64)
    e1, e2 = E[..., 0], E[..., 1]
    vx = np.maximum(E[..., 2] - e1 * e1, 0.0)
    vy = np.maximum(E[..., 3] - e2 * e2, 0.0)
    lim = MAX_RHO * np.sqrt(vx * vy)
    cxy = np.clip(E[..., 4] - e1 * e2, -lim, lim)
    # eigen-decomposition of [[vx, cxy], [cxy, vy]]: l1 >= l2, major axis angle t
    half = 0.5 * (vx + vy)
    r = np.hypot(0.5 * (vx - vy), cxy)
    l1, l2 = half + r, half - r
    f1, f2 = np.maximum(l1, sigma_eps**2), np.maximum(l2, sigma_eps**2)
    t = 0.5 * np.arctan2(2.0 * cxy, vx - vy)
    c, s = np.cos(t), np.sin(t)
    fx, fy, fxy = f1 * c * c + f2 * s * s, f1 * s * s + f2 * c * c, (f1 - f2) * c * s
    # rounding guard: keep the per-axis floor and the correlation bound exact
    fx, fy = np.maximum(fx, sigma_eps**2), np.maximum(fy, sigma_eps**2)
    lim = MAX_RHO * np.sqrt(fx * fy)
    fxy = np.clip(fxy, -lim, lim)
    # lobes already at the floor (to rounding) are kept bit for bit: idempotent, so
    # moments saved floored reload unchanged
    low = l2 < sigma_eps**2 * (1.0 - 1e-10)
    vx, vy, cxy = np.where(low, fx, vx), np.where(low, fy, vy), np.where(low, fxy, cxy)
    E[..., 2], E[..., 3], E[..., 4] = vx + e1 * e1, vy + e2 * e2, cxy + e1 * e2
    return E


# --------------------------------------------------------------------------- lobes
def _lobe_params(E: np.ndarray) -> np.ndarray:
    """Per-lobe evaluation parameters ``(..., 6)``: mean (2), inverse covariance
    ``(ixx, iyy, ixy)`` and ``-log(2 pi sqrt(det))``."""
    e1, e2 = E[..., 0], E[..., 1]
    vx, vy, cxy = E[..., 2] - e1 * e1, E[..., 3] - e2 * e2, E[..., 4] - e1 * e2
    det = vx * vy - cxy * cxy
    return np.stack([e1, e2, vy / det, vx / det, -cxy / det,
                     -np.log(2.0 * np.pi * np.sqrt(det))], -1)


def _p22(params: np.ndarray, x, y) -> np.ndarray:
    """Gaussian slope PDF (Eq. 4) of lobes ``params (..., 6)`` at slopes ``x, y``."""
    dx, dy = x - params[..., 0], y - params[..., 1]
    q = params[..., 2] * dx * dx + params[..., 3] * dy * dy + 2.0 * params[..., 4] * dx * dy
    return np.exp(params[..., 5] - 0.5 * q)


def _half_slopes(h) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slopes of unit normals ``h (..., 3)`` and ``1 / cos^4`` (0 below the horizon)."""
    h = np.asarray(h, dtype=np.float64)
    if h.shape[-1:] != (3,):
        raise ValueError(f"h must have a last axis of size 3, got shape {h.shape}")
    z = h[..., 2]
    up = z > 0
    zs = np.where(up, z, 1.0)
    inv4 = np.where(up, 1.0 / zs**4, 0.0)
    return -h[..., 0] / zs, -h[..., 1] / zs, inv4


def _check_footprint(center, cov) -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(center, dtype=np.float64)
    s = np.asarray(cov, dtype=np.float64)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center must be a finite uv pair (2,), got {center!r}")
    if s.shape != (2, 2) or not np.all(np.isfinite(s)):
        raise ValueError(f"cov must be a finite (2, 2) covariance in uv^2, got shape {s.shape}")
    if abs(s[0, 1] - s[1, 0]) > 1e-12 * max(1.0, abs(s).max()) or s[0, 0] < 0 or s[1, 1] < 0 \
            or s[0, 0] * s[1, 1] - s[0, 1] ** 2 < -1e-15 * max(1.0, abs(s).max()) ** 2:
        raise ValueError("cov must be symmetric positive semi-definite")
    return c, 0.5 * (s + s.T)


# --------------------------------------------------------------------------- hierarchy
def _box_pyramid(lo: np.ndarray, hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Min/max pyramid of slope boxes ``(ny, nx, 2)``: node ``(l, y, x)`` bounds the lobes
    ``[y 2^l, (y+1) 2^l) x [x 2^l, (x+1) 2^l)``; the top level is 1 x 1."""
    levels = [(lo, hi)]
    while levels[-1][0].shape[0] > 1 or levels[-1][0].shape[1] > 1:
        a, b = levels[-1]
        ny, nx = a.shape[:2]
        py, px = ny % 2, nx % 2
        if py or px:
            a = np.pad(a, ((0, py), (0, px), (0, 0)), constant_values=np.inf)
            b = np.pad(b, ((0, py), (0, px), (0, 0)), constant_values=-np.inf)
        m, n = a.shape[0] // 2, a.shape[1] // 2
        levels.append((a.reshape(m, 2, n, 2, 2).min(axis=(1, 3)),
                       b.reshape(m, 2, n, 2, 2).max(axis=(1, 3))))
    return levels


def _traverse(levels, block, xq, yq):
    """Breadth-first traversal of the box pyramid for the lobe rectangle ``block =
    (x0, x1, y0, y1)`` (inclusive) and query slopes ``xq, yq (M,)``: the pairs (query,
    lobe ``(y, x)``) whose slope box contains the query's slope."""
    x0, x1, y0, y1 = block
    span = max(x1 - x0, y1 - y0) + 1
    lev = min(int(np.ceil(np.log2(span))) if span > 1 else 0, len(levels) - 1)
    nys = np.arange(y0 >> lev, (y1 >> lev) + 1)
    nxs = np.arange(x0 >> lev, (x1 >> lev) + 1)
    ny_, nx_ = np.meshgrid(nys, nxs, indexing="ij")
    q = np.repeat(np.arange(xq.size), ny_.size)
    ny_ = np.tile(ny_.ravel(), xq.size)
    nx_ = np.tile(nx_.ravel(), xq.size)
    dy, dx = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])
    while True:
        lo, hi = levels[lev]
        inside = ((lo[ny_, nx_, 0] <= xq[q]) & (xq[q] <= hi[ny_, nx_, 0])
                  & (lo[ny_, nx_, 1] <= yq[q]) & (yq[q] <= hi[ny_, nx_, 1]))
        q, ny_, nx_ = q[inside], ny_[inside], nx_[inside]
        if lev == 0 or q.size == 0:
            return q, ny_, nx_
        lev -= 1
        size_y, size_x = levels[lev][0].shape[:2]
        q = np.repeat(q, 4)
        ny_ = (2 * ny_[:, None] + dy).ravel()
        nx_ = (2 * nx_[:, None] + dx).ravel()
        keep = ((ny_ < size_y) & (nx_ < size_x)
                & ((ny_ + 1) << lev > y0) & ((ny_ << lev) <= y1)
                & ((nx_ + 1) << lev > x0) & ((nx_ << lev) <= x1))
        q, ny_, nx_ = q[keep], ny_[keep], nx_[keep]


def _flatten(levels):
    """The box pyramid as flat arrays for the compiled traversal: ``lo, hi (nodes, 2)``,
    level offsets, widths and heights."""
    offs, nxs, nys, los, his = [], [], [], [], []
    n = 0
    for lo, hi in levels:
        offs.append(n)
        nys.append(lo.shape[0])
        nxs.append(lo.shape[1])
        los.append(lo.reshape(-1, 2))
        his.append(hi.reshape(-1, 2))
        n += lo.shape[0] * lo.shape[1]
    return (np.ascontiguousarray(np.concatenate(los)), np.ascontiguousarray(np.concatenate(his)),
            np.array(offs, np.int64), np.array(nxs, np.int64), np.array(nys, np.int64))


@numba.njit(parallel=True, cache=True)
def _traverse_sum(queries, tree, lobes, window, out):  # pragma: no cover
    """Compiled depth-first version of :func:`_traverse` that also sums ``W D_i``
    (slope-space P22) into ``out`` per query: ``queries = (x~, y~)`` the query slopes, ``tree``
    the flat box pyramid of :func:`_flatten` ``(lo, hi, offs, nxs, nys)``, ``lobes = (params, W)``
    the lobes' P22 parameters (``(n, 6)``, :func:`_p22`) and the footprint weights ``W`` of the
    seed window ``window = (x0, x1, y0, y1)`` (inclusive)."""
    xq, yq = queries
    lo, hi, offs, nxs, nys = tree
    params, W = lobes
    x0, x1, y0, y1 = window
    top = offs.size - 1
    span = max(x1 - x0, y1 - y0) + 1
    start = 0
    while (1 << start) < span and start < top:
        start += 1
    nx0 = nxs[0]
    for qi in numba.prange(xq.size):
        x, y = xq[qi], yq[qi]
        stack = np.empty((4 * (top + 2) + 8, 3), np.int64)
        sp = 0
        for ny_ in range(y0 >> start, (y1 >> start) + 1):
            for nx_ in range(x0 >> start, (x1 >> start) + 1):
                stack[sp, 0], stack[sp, 1], stack[sp, 2] = start, ny_, nx_
                sp += 1
        acc = 0.0
        while sp > 0:
            sp -= 1
            lev, ny_, nx_ = stack[sp, 0], stack[sp, 1], stack[sp, 2]
            k = offs[lev] + ny_ * nxs[lev] + nx_
            if not (lo[k, 0] <= x and x <= hi[k, 0] and lo[k, 1] <= y and y <= hi[k, 1]):
                continue
            if lev == 0:
                i = ny_ * nx0 + nx_
                dx, dy = x - params[i, 0], y - params[i, 1]
                qf = params[i, 2] * dx * dx + params[i, 3] * dy * dy + 2.0 * params[i, 4] * dx * dy
                acc += W[ny_ - y0, nx_ - x0] * np.exp(params[i, 5] - 0.5 * qf)
                continue
            cl = lev - 1
            for dy_ in range(2):
                cy = 2 * ny_ + dy_
                if cy >= nys[cl] or ((cy + 1) << cl) <= y0 or (cy << cl) > y1:
                    continue
                for dx_ in range(2):
                    cx = 2 * nx_ + dx_
                    if cx >= nxs[cl] or ((cx + 1) << cl) <= x0 or (cx << cl) > x1:
                        continue
                    stack[sp, 0], stack[sp, 1], stack[sp, 2] = cl, cy, cx
                    sp += 1
        out[qi] += acc


#: Side, in lobes, of the blocks of :meth:`LobeMixture._block_bounds` (the pruning grid of
#: the compiled image kernel, :func:`microfacet.glints.pbrdf._footprint_sums`).
BLOCK = 8


@numba.njit(parallel=True, cache=True)
def _block_bounds_compiled(E, B):  # pragma: no cover - compiled
    """Per ``B x B`` block of the lobe grid ``E (ny, nx, 5)`` (raw moments, Eq. 5): the
    bounds ``(min x~n, max x~n, min y~n, max y~n, max sigma_x, max sigma_y, max |c_xy|)``
    of its lobes' mean slopes and slope covariances (blocks at the far edges may be
    partial)."""
    ny, nx = E.shape[0], E.shape[1]
    nby, nbx = (ny + B - 1) // B, (nx + B - 1) // B
    out = np.empty((nby, nbx, 7))
    for by in numba.prange(nby):
        for bx in range(nbx):
            b = np.array([np.inf, -np.inf, np.inf, -np.inf, 0.0, 0.0, 0.0])
            for iy in range(by * B, min(by * B + B, ny)):
                for ix in range(bx * B, min(bx * B + B, nx)):
                    m1, m2 = E[iy, ix, 0], E[iy, ix, 1]
                    b[0], b[1] = min(b[0], m1), max(b[1], m1)
                    b[2], b[3] = min(b[2], m2), max(b[3], m2)
                    b[4] = max(b[4], E[iy, ix, 2] - m1 * m1)
                    b[5] = max(b[5], E[iy, ix, 3] - m2 * m2)
                    b[6] = max(b[6], abs(E[iy, ix, 4] - m1 * m2))
            b[4], b[5] = math.sqrt(b[4]), math.sqrt(b[5])
            out[by, bx] = b
    return out


# --------------------------------------------------------------------------- storage
class _LazyPyramid(Sequence):
    """The lobe-moment MIP levels of Sec. 4.2.2 (:func:`~microfacet.leadr.mip.mip_pyramid`),
    built on first access; the number of levels is known without building them."""

    def __init__(self, grid: np.ndarray):
        self._grid, self._levels = grid, None
        self._n = len(mip_sizes(*grid.shape[:2]))

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):
        if self._levels is None:
            self._levels = mip_pyramid(self._grid)
        return self._levels[i]


@numba.njit(cache=True)
def _all_finite(a) -> bool:  # pragma: no cover - compiled
    """``np.isfinite(a).all()`` in one pass without a boolean temporary, stopping early."""
    for v in a.flat:
        if not np.isfinite(v):
            return False
    return True


@numba.njit(parallel=True, cache=True)
def _central_float32(E):  # pragma: no cover - compiled
    """Float32 central moments ``(mx, my, vxx, vyy, cxy)`` of raw moments ``E (ny, nx, 5)``
    (Eq. 5: ``vxx = E3 - E1^2``, ``vyy = E4 - E2^2``, ``cxy = E5 - E1 E2``)."""
    out = np.empty(E.shape, np.float32)
    for iy in numba.prange(E.shape[0]):
        for ix in range(E.shape[1]):
            m1, m2 = E[iy, ix, 0], E[iy, ix, 1]
            out[iy, ix, 0], out[iy, ix, 1] = m1, m2
            out[iy, ix, 2] = E[iy, ix, 2] - m1 * m1
            out[iy, ix, 3] = E[iy, ix, 3] - m2 * m2
            out[iy, ix, 4] = E[iy, ix, 4] - m1 * m2
    return out


@numba.njit(parallel=True, cache=True)
def _axis_alphas_float32(E):  # pragma: no cover - compiled
    """Float32 Beckmann roughness ``alpha = sqrt(2 var)`` of both slope axes of every lobe of
    raw moments ``E (N, 5)`` (Eq. 5; the std is ``alpha / sqrt(2)``), flat ``(2 N,)``."""
    out = np.empty(2 * E.shape[0], np.float32)
    for i in numba.prange(E.shape[0]):
        out[2 * i] = math.sqrt(2.0 * max(E[i, 2] - E[i, 0] * E[i, 0], 0.0))
        out[2 * i + 1] = math.sqrt(2.0 * max(E[i, 3] - E[i, 1] * E[i, 1], 0.0))
    return out


@numba.njit(parallel=True, cache=True)
def _raw_from_central(C, sigma_eps=0.0):  # pragma: no cover - compiled
    """Float64 raw moments ``E1..E5`` of central moments ``C (ny, nx, 5)`` (inverse of
    :func:`_central_float32`: ``E3 = vxx + mx^2``, ``E4 = vyy + my^2``, ``E5 = cxy + mx my``),
    floored as :func:`_floor_moments_compiled` floors them when ``sigma_eps > 0``, in the
    same pass (one lobe at a time: the same numbers as flooring afterwards)."""
    out = np.empty(C.shape, np.float64)
    flat = out.reshape(-1, 5)
    e2 = sigma_eps * sigma_eps
    for iy in numba.prange(C.shape[0]):
        for ix in range(C.shape[1]):
            m1, m2 = np.float64(C[iy, ix, 0]), np.float64(C[iy, ix, 1])
            out[iy, ix, 0], out[iy, ix, 1] = m1, m2
            out[iy, ix, 2] = C[iy, ix, 2] + m1 * m1
            out[iy, ix, 3] = C[iy, ix, 3] + m2 * m2
            out[iy, ix, 4] = C[iy, ix, 4] + m1 * m2
            if sigma_eps > 0.0:
                _floor_lobe(flat, iy * C.shape[1] + ix, e2)
    return out


# --------------------------------------------------------------------------- microsurface
class LobeMixture:
    """A normal map as a mixture of Beckmann lobes ``D_n(m, u) ~ sum_i D_i(m) k_i(u)``
    (Eq. 1-6) with an acceleration hierarchy (Sec. 5) and moment MIP levels (Sec. 4.2.2).

    Build with :meth:`from_normal_map`; see the module docstring for the conventions.

    Attributes
    ----------
    lobe_uv : (N, 2)
        Lobe centres ``u_i`` in uv; lobe ``i = iy * nx + ix``.
    lobe_moments : (N, 5)
        ``E1..E5`` of each lobe in slope space (floored, Eq. 3-6).
    kernel_sigma : (2,)
        uv standard deviations ``(sigma_u, sigma_v)`` of the kernels ``k_i``.
    resolution : (H, W)
        The normal map's size in texels.
    grid : (ny, nx)
        Number of seeds per axis.
    mip : sequence of (ny_l, nx_l, 5)
        Lobe-moment MIP levels (level 0 = the lobes, averaged 2 x 2 upwards), built on
        first access (as are ``lobe_uv`` and the hierarchy of :meth:`pndf`).
    slopes : (H, W, 2) float32
        The texel slopes (for the interpolated map, e.g. to sample a footprint), float32
        as :meth:`save` stores them, so that a built and a loaded microsurface agree.

    ``moments`` ``(ny, nx, 5)`` raw moments are floored (:func:`_floor_moments`) in a
    copy, or in place with ``copy=False`` (the builders and :meth:`load` own theirs).

    Parameters
    ----------
    moments : (ny, nx, 5) array_like
        Raw lobe moments (:func:`lobe_moments`).
    slopes : (H, W, 2) array_like
        The texel slopes they came from.
    h : float
        Seed spacing in texels (:data:`SPACING_RANGE`).
    sigma_eps : float
        Floor of the lobes' principal slope deviations.
    cutoff, slope_cutoff : float
        Truncations of the footprint weights and of the hierarchy's slope boxes (Sec. 5).
    copy : bool
        Floor a copy of ``moments`` (False: in place).

    Examples
    --------
    The kernels' FWHM is one seed spacing (:data:`FWHM_PER_SIGMA`); files are written in
    format :data:`FORMAT_VERSION`:

    >>> slopes = 0.1 * np.random.default_rng(0).standard_normal((4, 4, 2))
    >>> ms = LobeMixture.from_slopes(slopes)
    >>> ms.grid, ms.n_lobes, bool(np.allclose(ms.kernel_sigma * FWHM_PER_SIGMA, 1 / 4))
    ((4, 4), 16, True)
    >>> h = np.array([0.0, 0.0, 1.0])
    >>> ms.pndf(h, center=[0.5, 0.5], cov=np.eye(2) * 1e-3).shape
    ()
    >>> LobeMixture.load(ms.save("lobes.npz")).grid, FORMAT_VERSION, SPACING_RANGE
    ((4, 4), 2, (0.0625, 10000.0))
    """

    def __init__(self, moments, slopes, h: float = 1.0, sigma_eps: float = 0.01,
                 cutoff: float = 3.0, slope_cutoff: float = 4.0, *, copy: bool = True):
        grid = np.asarray(moments, dtype=np.float64)
        if grid.ndim != 3 or grid.shape[2] != 5 or 0 in grid.shape:
            raise ValueError(f"moments must be an (ny, nx, 5) lobe grid, got shape {grid.shape}")
        if not _all_finite(grid):
            raise ValueError("lobe moments must be finite")
        self._check_params(sigma_eps, cutoff, slope_cutoff)
        _check_layout(grid.shape, np.shape(slopes), h)
        if copy or not (grid.flags.c_contiguous and grid.flags.writeable):
            grid = np.array(grid, dtype=np.float64, order="C")
        _floor_moments_compiled(grid.reshape(-1, 5), float(sigma_eps))     # in place
        self._set(grid, slopes, h, sigma_eps, cutoff, slope_cutoff)

    @staticmethod
    def _check_params(sigma_eps, cutoff, slope_cutoff) -> None:
        if not (cutoff > 0 and slope_cutoff > 0):
            raise ValueError(f"cutoff and slope_cutoff must be > 0, got {cutoff}, {slope_cutoff}")
        if not (np.isfinite(sigma_eps) and sigma_eps > 0):
            raise ValueError(f"sigma_eps must be > 0, got {sigma_eps!r}")

    def _set(self, grid, slopes, h, sigma_eps, cutoff, slope_cutoff) -> None:
        """The attributes of a microsurface of floored, finite, C-ordered raw moments ``grid``."""
        self._grid = grid
        self.slopes = np.asarray(slopes, dtype=np.float32)       # as files store them
        self.h, self.sigma_eps = float(h), float(sigma_eps)
        self.cutoff, self.slope_cutoff = float(cutoff), float(slope_cutoff)
        ny, nx = grid.shape[:2]
        self.grid = (ny, nx)
        self.resolution = tuple(int(v) for v in self.slopes.shape[:2])
        self.kernel_sigma = np.array([1.0 / nx, 1.0 / ny]) / FWHM_PER_SIGMA
        self.lobe_moments = self._grid.reshape(-1, 5)
        self.mip = _LazyPyramid(self._grid)

    # the P-NDF's evaluation structures, built on first use (a 4096^2 map's would take GBs)
    @cached_property
    def lobe_uv(self) -> np.ndarray:
        ny, nx = self.grid
        iy, ix = np.divmod(np.arange(nx * ny), nx)
        return np.stack([(ix + 0.5) / nx, (iy + 0.5) / ny], -1)

    @cached_property
    def _params(self) -> np.ndarray:
        return _lobe_params(self._grid)

    @cached_property
    def _boxes(self):
        e1, e2 = self._grid[..., 0], self._grid[..., 1]
        std = np.sqrt(np.stack([self._grid[..., 2] - e1 * e1, self._grid[..., 3] - e2 * e2], -1))
        mean = self._grid[..., :2]
        return _box_pyramid(mean - self.slope_cutoff * std, mean + self.slope_cutoff * std)

    @cached_property
    def _flat(self):
        return _flatten(self._boxes)

    @cached_property
    def _block_bounds(self) -> np.ndarray:
        """Mean-slope and covariance bounds of the lobes of each :data:`BLOCK` x :data:`BLOCK`
        block (:func:`_block_bounds_compiled`), for pruning in the compiled image kernel."""
        return _block_bounds_compiled(self._grid, BLOCK)

    @cached_property
    def _flat_params(self) -> np.ndarray:
        return np.ascontiguousarray(self._params.reshape(-1, 6))

    # ----------------------------------------------------------------- construction
    @classmethod
    def from_normal_map(cls, path_or_array, h: float = 1.0, sigma_eps: float = 0.01, *,
                        samples: int = 4, encoding: str = "auto", z: str = "auto",
                        **kwargs) -> "LobeMixture":
        """Lobe mixture of a normal map (Sec. 3): one lobe per ``h x h`` texels.

        Parameters
        ----------
        path_or_array : path or (H, W, C) array
            Normal map (see :func:`load_slopes` for ``encoding`` and ``z``).
        h : float
            Seed spacing in texels (the paper uses 1), in :data:`SPACING_RANGE`.
        sigma_eps : float
            Floor of each lobe's principal slope standard deviations (Sec. 3.2, 0.01).
        samples : int
            Quadrature points per texel and axis for the lobe moments (Eq. 6).
        encoding : str
            ``"auto"``, ``"biased"``/``"offset"`` or ``"signed"`` (:func:`load_slopes`).
        z : str
            ``"auto"``, ``"stored"`` or ``"reconstruct"`` (:func:`load_slopes`).
        **kwargs
            ``cutoff``, ``slope_cutoff`` (float): truncation of the footprint weights (standard deviations of ``Sigma_P +
            sigma_k^2``) and of the lobes' slope boxes of the hierarchy (Sec. 5).

        Returns
        -------
        LobeMixture
            One lobe per seed, with its MIP levels and hierarchy.
        """
        return cls.from_slopes(load_slopes(path_or_array, encoding, z), h, sigma_eps,
                               samples=samples, **kwargs)

    @classmethod
    def from_slopes(cls, slopes, h: float = 1.0, sigma_eps: float = 0.01, *, samples: int = 4,
                    **kwargs) -> "LobeMixture":
        """Lobe mixture (Sec. 3, Eq. 3-6) of texel slopes ``(H, W, 2)`` (see
        :meth:`from_normal_map` for the parameters): the lobe construction alone.

        Parameters
        ----------
        slopes : array-like, shape (H, W, 2)
            Texel slopes ``(x~, y~)``.
        h : float, optional
            Seed spacing in texels (default 1), in :data:`SPACING_RANGE`.
        sigma_eps : float, optional
            Floor of each lobe's principal slope standard deviations (default 0.01).
        samples : int, optional
            Quadrature points per texel and axis for the lobe moments (default 4).
        **kwargs
            ``cutoff``, ``slope_cutoff`` as in :meth:`from_normal_map`.

        Returns
        -------
        LobeMixture
            The lobe mixture.
        """
        slopes = np.asarray(slopes)
        if slopes.ndim != 3 or slopes.shape[2] != 2 or 0 in slopes.shape:
            raise ValueError(f"slopes must be an (H, W, 2) array, got shape {slopes.shape}")
        ny, nx = lobe_grid(slopes.shape[:2], h)
        if not (np.isfinite(sigma_eps) and sigma_eps > 0):
            raise ValueError(f"sigma_eps must be > 0, got {sigma_eps!r}")
        if int(samples) < 1:
            raise ValueError(f"samples must be >= 1, got {samples!r}")
        # the lobes of the float32 slopes the microsurface keeps (and files store), so that a
        # built and a loaded one agree; the float64 input is released before the moments
        slopes = np.asarray(slopes, dtype=np.float32)
        raw = lobe_moments(slopes, nx, ny, int(samples))
        return cls(raw, slopes, h=h, sigma_eps=sigma_eps, copy=False, **kwargs)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.grid[1]} x {self.grid[0]} lobes from a {self.resolution[1]} x "
                f"{self.resolution[0]} map, h={self.h:g}, sigma_eps={self.sigma_eps:g})")

    @property
    def n_lobes(self) -> int:
        return self.lobe_moments.shape[0]

    def lobes(self, indices=None):
        """The lobes ``indices`` as one :class:`microfacet.Beckmann` with array parameters.

        Parameters
        ----------
        indices : array-like of int, optional
            Lobe indices (default ``None``: every lobe).

        Returns
        -------
        Beckmann
            The lobes, with parameters of the shape of ``indices``.
        """
        E = self.lobe_moments if indices is None else self.lobe_moments[np.asarray(indices)]
        return from_moments(E, min_alpha=np.sqrt(2.0) * self.sigma_eps * 0.5, max_rho=MAX_RHO)

    def alpha_summary(self) -> tuple[float, float]:
        """Median and largest per-axis Beckmann roughness ``alpha = sqrt(2 var)`` of the
        lobes (both axes pooled, as ``np.median`` would give them to float32 rounding),
        from a float32 copy partitioned in place (4 bytes per lobe and axis).

        Returns
        -------
        median, largest : float
            The median and largest per-axis roughness ``alpha``.
        """
        a = _axis_alphas_float32(self.lobe_moments)
        k = a.size // 2
        a.partition([k - 1, k] if a.size > 1 else [0])
        med = float(a[k]) if a.size % 2 else 0.5 * (float(a[k - 1]) + float(a[k]))
        return med, float(a.max())

    def slopes_at(self, uv) -> np.ndarray:
        """Slopes ``(..., 2)`` of the interpolated normal map at ``uv (..., 2)``.

        Parameters
        ----------
        uv : array-like, shape (..., 2)
            Texture coordinates.

        Returns
        -------
        numpy.ndarray, shape (..., 2)
            Slopes of the bilinearly interpolated normal map.
        """
        return interpolate_slopes(self.slopes, uv)

    def normal_at(self, uv) -> np.ndarray:
        """Unit normals ``(..., 3)`` of the interpolated normal map at ``uv (..., 2)``.

        Parameters
        ----------
        uv : array-like, shape (..., 2)
            Texture coordinates.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            Unit normals.
        """
        s = self.slopes_at(uv)
        inv = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
        return np.stack([-s[..., 0] * inv, -s[..., 1] * inv, inv], -1)

    # ----------------------------------------------------------------- weights (Eq. 9)
    def _blocks(self, center, cov, nx: int, ny: int, cutoff: float):
        """Lobe rectangles (non-wrapped, inclusive) and their uv shifts, and the combined
        covariance, for a footprint over a ``nx x ny`` seed grid."""
        ks = np.array([1.0 / nx, 1.0 / ny]) / FWHM_PER_SIGMA
        S = cov + np.diag(ks**2)
        r = cutoff * np.sqrt(np.diag(S))
        blocks = []
        rng = []
        for n, c, rr in ((nx, center[0], r[0]), (ny, center[1], r[1])):
            i0 = int(np.ceil((c - rr) * n - 0.5))
            i1 = int(np.floor((c + rr) * n - 0.5))
            parts = []
            for t in range(i0 // n, i1 // n + 1):
                a, b = max(i0, t * n) - t * n, min(i1, t * n + n - 1) - t * n
                if a <= b:
                    parts.append((a, b, float(t)))
            rng.append(parts)
        for ax, bx, tx in rng[0]:
            for ay, by, ty in rng[1]:
                blocks.append(((ax, bx, ay, by), (tx, ty)))
        return blocks, S

    def _weights_grid(self, center, cov, nx, ny, cutoff, normalize):
        center, cov = _check_footprint(center, cov)
        blocks, S = self._blocks(center, cov, nx, ny, cutoff)
        det = S[0, 0] * S[1, 1] - S[0, 1] ** 2
        inv = np.array([S[1, 1], S[0, 0], -S[0, 1]]) / det
        area = 1.0 / (nx * ny)
        out = []
        total = 0.0
        for (x0, x1, y0, y1), (tx, ty) in blocks:
            du = (np.arange(x0, x1 + 1) + 0.5) / nx + tx - center[0]
            dv = (np.arange(y0, y1 + 1) + 0.5) / ny + ty - center[1]
            du, dv = du[None, :], dv[:, None]
            q = inv[0] * du * du + inv[1] * dv * dv + 2 * inv[2] * du * dv
            W = area * np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(det))
            out.append(W)
            total += W.sum()
        if normalize and total > 0:
            out = [W / total for W in out]
        return blocks, out

    def weights(self, center, cov, *, normalize: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Lobes contributing to the footprint ``k_P`` and their weights (Eq. 9).

        Parameters
        ----------
        center : (2,)
            Footprint centre in uv.
        cov : (2, 2)
            Footprint covariance in uv^2 (0 is a point footprint).
        normalize : bool
            Divide the weights by their sum (default, Sec. 4.1); else the raw closed form
            ``W_i = A N(u_i; c, Sigma_P + sigma_k^2 I)``.

        Returns
        -------
        indices : (K,) int64
            Lobe indices (a lobe appears once per periodic image the footprint covers).
        W : (K,)
            Their weights.
        """
        nx = self.grid[1]
        blocks, Ws = self._weights_grid(center, cov, self.grid[1], self.grid[0], self.cutoff, normalize)
        idx, ws = [], []
        for ((x0, x1, y0, y1), _), W in zip(blocks, Ws):
            iy, ix = np.meshgrid(np.arange(y0, y1 + 1), np.arange(x0, x1 + 1), indexing="ij")
            idx.append((iy * nx + ix).ravel())
            ws.append(W.ravel())
        if not idx:
            return np.zeros(0, np.int64), np.zeros(0)
        return np.concatenate(idx).astype(np.int64), np.concatenate(ws)

    # ----------------------------------------------------------------- P-NDF (Eq. 9)
    def pndf(self, h, center, cov, *, normalize: bool = True, method: str = "auto") -> np.ndarray:
        """Patch NDF ``D_P(h) = sum_i W_i D_i(h)`` (Eq. 9) at unit normals ``h (..., 3)``.

        ``method``: ``"brute"`` sums every lobe of :meth:`weights` (NumPy);
        ``"hierarchy"`` traverses the slope-box quadtree (Sec. 5) depth-first per half
        vector (compiled), skipping lobes whose slope box (``slope_cutoff`` standard
        deviations) does not contain ``h``'s slope; ``"hierarchy-numpy"`` is the same
        traversal breadth-first in NumPy (the reference of the compiled one); ``"auto"``
        uses the compiled hierarchy when the footprint has more than 16 lobes.

        Parameters
        ----------
        h : array-like, shape (..., 3)
            Unit half vectors in the local frame.
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2 (0: a point footprint).
        normalize : bool, optional
            Normalize the weights to sum 1 (default ``True``; :meth:`weights`).
        method : {"auto", "brute", "hierarchy", "hierarchy-numpy"}, optional
            Evaluation method (default ``"auto"``).

        Returns
        -------
        numpy.ndarray, shape (...)
            ``D_P(h)`` in 1/sr.
        """
        if method not in ("auto", "brute", "hierarchy", "hierarchy-numpy"):
            raise ValueError(f"method must be 'auto', 'brute', 'hierarchy' or 'hierarchy-numpy', "
                             f"got {method!r}")
        xq, yq, inv4 = _half_slopes(h)
        shape = xq.shape
        xq, yq, inv4 = xq.ravel(), yq.ravel(), inv4.ravel()
        blocks, Ws = self._weights_grid(center, cov, self.grid[1], self.grid[0], self.cutoff, normalize)
        n = sum(W.size for W in Ws)
        if method == "auto":
            method = "hierarchy" if n > 16 else "brute"
        out = np.zeros(xq.size)
        if method == "brute":
            params = np.concatenate([self._params[y0:y1 + 1, x0:x1 + 1].reshape(-1, 6)
                                     for (x0, x1, y0, y1), _ in blocks]) if blocks else np.zeros((0, 6))
            W = np.concatenate([w.ravel() for w in Ws]) if Ws else np.zeros(0)
            chunk = max(1, 2_000_000 // max(1, W.size))
            for s in range(0, xq.size, chunk):
                sl = slice(s, s + chunk)
                out[sl] = _p22(params[None], xq[sl, None], yq[sl, None]) @ W
        elif method == "hierarchy":
            for (window, _), W in zip(blocks, Ws):
                _traverse_sum((xq, yq), self._flat, (self._flat_params, np.ascontiguousarray(W)), tuple(window), out)
        else:
            for ((x0, x1, y0, y1), _), W in zip(blocks, Ws):
                q, iy, ix = _traverse(self._boxes, (x0, x1, y0, y1), xq, yq)
                if q.size:
                    val = W[iy - y0, ix - x0] * _p22(self._params[iy, ix], xq[q], yq[q])
                    out += np.bincount(q, weights=val, minlength=xq.size)
        return (out * inv4).reshape(shape)

    def slope_pdf(self, slopes, center, cov, **kwargs) -> np.ndarray:
        """The P-NDF in slope space, ``P_P(m~) = D_P(m) cos^4 theta_m`` at slopes ``(..., 2)``.

        Parameters
        ----------
        slopes : array-like, shape (..., 2)
            Slopes ``(x~, y~)``.
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.
        **kwargs
            ``normalize`` and ``method`` of :meth:`pndf`.

        Returns
        -------
        numpy.ndarray, shape (...)
            The slope-space density.
        """
        s = np.asarray(slopes, dtype=np.float64)
        inv = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
        m = np.stack([-s[..., 0] * inv, -s[..., 1] * inv, inv], -1)
        return self.pndf(m, center, cov, **kwargs) * inv**4

    def sample_slopes(self, u, center, cov, *, normalize: bool = True) -> np.ndarray:
        """Slopes ``(..., 2)`` distributed as the P-NDF in slope space (density
        :meth:`slope_pdf`, i.e. ``D_P(m) cos m`` per solid angle): a lobe is chosen with
        probability ``W_i / sum W`` (``u[..., 0]``), then its Gaussian (Eq. 4) is sampled
        (Box-Muller, ``u[..., 1:3]``). ``u (..., 3)`` in ``[0, 1)``. With
        ``normalize=False`` the density is ``slope_pdf / sum W``.

        Parameters
        ----------
        u : array-like, shape (..., 3)
            Uniform random numbers in ``[0, 1)``.
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.
        normalize : bool, optional
            Normalized weights (default ``True``; :meth:`weights`).

        Returns
        -------
        numpy.ndarray, shape (..., 2)
            Sampled slopes.
        """
        u = np.asarray(u, dtype=np.float64)
        if u.shape[-1:] != (3,):
            raise ValueError(f"u must have a last axis of size 3, got shape {u.shape}")
        idx, W = self.weights(center, cov, normalize=normalize)
        if W.size == 0 or W.sum() <= 0:
            raise ValueError("the footprint has no lobe")
        cdf = np.cumsum(W) / W.sum()
        k = idx[np.minimum(np.searchsorted(cdf, u[..., 0], side="right"), W.size - 1)]
        E = self.lobe_moments[k]
        e1, e2 = E[..., 0], E[..., 1]
        vx, vy, cxy = E[..., 2] - e1 * e1, E[..., 3] - e2 * e2, E[..., 4] - e1 * e2
        r = np.sqrt(-2.0 * np.log1p(-np.clip(u[..., 1], 0.0, 1.0 - 1e-16)))
        g1, g2 = r * np.cos(2 * np.pi * u[..., 2]), r * np.sin(2 * np.pi * u[..., 2])
        lxx = np.sqrt(vx)
        lyx = cxy / lxx
        lyy = np.sqrt(np.maximum(vy - lyx * lyx, 0.0))
        return np.stack([e1 + lxx * g1, e2 + lyx * g1 + lyy * g2], -1)

    # ----------------------------------------------------------------- MIP (Sec. 4.2.2)
    def mip_level(self, cov) -> int:
        """MIP level whose lobe spacing matches the footprint's largest std.

        Parameters
        ----------
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.

        Returns
        -------
        int
            The MIP level, 0 (finest) to the coarsest.
        """
        _, cov = _check_footprint((0.0, 0.0), cov)
        sd = np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0))
        spacing = 1.0 / max(self.grid)
        lev = int(np.floor(np.log2(sd / spacing))) if sd > spacing else 0
        return int(np.clip(lev, 0, len(self.mip) - 1))

    def mip_moments(self, center, cov, level: int | None = None) -> np.ndarray:
        """Moments ``(5,)`` of the single filtered lobe of a footprint (Sec. 4.2.2): the
        ``W``-weighted average of the lobes of MIP level ``level`` (default
        :meth:`mip_level`), with kernels sized to that level's texels.

        Parameters
        ----------
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.
        level : int, optional
            MIP level (default: :meth:`mip_level` of ``cov``).

        Returns
        -------
        numpy.ndarray, shape (5,)
            The filtered lobe's moments ``E1..E5``.
        """
        lev = self.mip_level(cov) if level is None else int(level)
        if not 0 <= lev < len(self.mip):
            raise ValueError(f"level must lie in [0, {len(self.mip) - 1}], got {level}")
        grid = self.mip[lev]
        ny, nx = grid.shape[:2]
        blocks, Ws = self._weights_grid(center, cov, nx, ny, self.cutoff, True)
        E = np.zeros(5)
        for ((x0, x1, y0, y1), _), W in zip(blocks, Ws):
            E += np.tensordot(W, grid[y0:y1 + 1, x0:x1 + 1], axes=([0, 1], [0, 1]))
        return E

    def mip_lobe(self, center, cov, level: int | None = None):
        """The filtered lobe of :meth:`mip_moments` as a :class:`microfacet.Beckmann`.

        Parameters
        ----------
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.
        level : int, optional
            MIP level (default: :meth:`mip_level` of ``cov``).

        Returns
        -------
        Beckmann
            The filtered lobe.
        """
        return from_moments(self.mip_moments(center, cov, level), max_rho=MAX_RHO)

    # ----------------------------------------------------------------- files
    def save(self, path) -> Path:
        """Write a versioned ``.npz`` atomically; return its path. Format 2: the lobes as
        float32 *central* moments (means, variances, covariance: no cancellation, unlike
        float32 raw moments ``E3 = var + mean^2``) and float32 slopes, uncompressed (fast);
        loading refloors the lobes (the float32 rounding can sit 1 ulp below the floor).

        Parameters
        ----------
        path : str or path-like
            The ``.npz`` file to write.

        Returns
        -------
        Path
            The path written.
        """
        path = Path(path)
        small = {"magic": np.array(_MAGIC), "version": np.array(FORMAT_VERSION), "slopes": self.slopes,
                 "params": np.array([self.h, self.sigma_eps, self.cutoff, self.slope_cutoff])}
        with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name, a in small.items():
                with zf.open(f"{name}.npy", "w", force_zip64=True) as m:
                    np.lib.format.write_array(m, a)
            # the central moments streamed by blocks of rows (no full float32 copy in memory)
            with zf.open("central.npy", "w", force_zip64=True) as m:
                np.lib.format.write_array_header_1_0(
                    m, {"descr": np.lib.format.dtype_to_descr(np.dtype(np.float32)), "fortran_order": False,
                        "shape": self._grid.shape})
                rows = max(1, (16 << 20) // max(1, self._grid[0].nbytes))
                for r in range(0, self._grid.shape[0], rows):
                    m.write(_central_float32(self._grid[r:r + rows]).tobytes())
        return path

    @classmethod
    def load(cls, path) -> "LobeMixture":
        """Read a file written by :meth:`save` (format 2, or 1: float64 raw moments,
        compressed); errors name the file.

        Parameters
        ----------
        path : str or path-like
            A ``.npz`` file written by :meth:`save`.

        Returns
        -------
        LobeMixture
            The stored lobe mixture.
        """
        path = Path(path)
        z = load_npz(path, "a microfacet glints microsurface (.npz from 'microfacet glints')")
        if "magic" not in z or str(z["magic"]) != _MAGIC:
            raise MicrofacetError(f"{path}: not a microfacet glints microsurface (.npz from 'microfacet glints')")
        try:
            version = int(z["version"])
            if version not in (1, FORMAT_VERSION):
                raise MicrofacetError(f"{path}: unsupported microsurface format version {version} "
                                      f"(this microfacet reads 1 and {FORMAT_VERSION})")
            slopes, params = z["slopes"], z["params"]
            moments = z["moments"] if version == 1 else z["central"]
        except (KeyError, TypeError, ValueError) as e:
            raise MicrofacetError(f"{path}: corrupt microsurface file ({type(e).__name__}: {e})") from None
        if moments.ndim != 3 or moments.shape[2] != 5 or 0 in moments.shape or slopes.ndim != 3 or slopes.shape[2] != 2 \
                or params.shape != (4,) or not all(a.dtype in (np.float32, np.float64) for a in (moments, slopes, params)):
            raise MicrofacetError(f"{path}: corrupt microsurface file (bad array shapes or types)")
        if not (_all_finite(moments) and _all_finite(slopes) and _all_finite(params)):
            raise MicrofacetError(f"{path}: corrupt microsurface file (non-finite values)")
        h, eps, cutoff, scut = (float(v) for v in params)
        try:
            if version == 1:
                return cls(moments, slopes, h=h, sigma_eps=eps, cutoff=cutoff, slope_cutoff=scut, copy=False)
            cls._check_params(eps, cutoff, scut)
            _check_layout(moments.shape, slopes.shape, h)
        except ValueError as e:
            raise MicrofacetError(f"{path}: corrupt microsurface file ({e})") from None
        # format 2: raw moments floored in the same pass (finite: float32 squares in float64;
        # the lobes of the constructor's floor, without its second pass and finiteness scan)
        self = cls.__new__(cls)
        self._set(_raw_from_central(moments, eps), slopes, h, eps, cutoff, scut)
        return self
