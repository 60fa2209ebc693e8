"""LEADR shading of filtered displacement maps (LEADR supplemental, Dupuy et al. 2013).

Every function takes the five linear slope moments ``E = (E[x~], E[y~], E[x~^2],
E[y~^2], E[x~ y~])`` of a pixel, shape ``(..., 5)`` (one surface per pixel, e.g. from
``mf.leadr.lookup``), and directions ``(..., 3)`` in the local frame of the macrosurface
(z = macro normal ``w_g``; directions point away from the surface). The slope
statistics are the mean ``(x0, y0) = (E1, E2)`` and the covariance
``var_x = E3 - E1^2``, ``var_y = E4 - E2^2``, ``c_xy = E5 - E1 E2`` (Sec. 3.1); a
Beckmann surface of roughness ``alpha`` has ``var = alpha^2 / 2``.

* :func:`point_light` — rough specular microfacets under a point/directional light,
  analytic: ``I = E F D(h) / (4 c_o (1 + Lambda_o [+ Lambda_i]))`` with the inverse
  projected area of the mesonormal ``1 / c_o`` (Sec. 1.4, 3.3) and Smith masking (and
  shadowing) of the noncentral anisotropic Gaussian (Sec. 1.5, 3.2).
* :func:`env_specular` — rough specular microfacets under a MIP-mapped lat-long
  environment, by the ``N x N`` filtered sample grid (Simplified Algorithm 1, Sec. 3.4-3.5).
* :func:`diffuse_sh` and :func:`diffuse_directional` — rough diffuse microfacets with a
  9-coefficient spherical-harmonic irradiance (Simplified Algorithms 2-3, Sec. 3.6).
* :func:`artificial_micronormal` — the fallback normal of Sec. 3.7 that keeps the sample
  grids defined when the mesonormal faces away from the view (low tessellation).

The grid algorithms account for masking only (no self-shadowing of the displacement):
by Eq. 10 of the supplemental the masking ``1 / (1 + Lambda_o)`` and the inverse
projected area are replaced by the grid's own normalization ``1 / S``.

Examples
--------
>>> GRID_SPACING, ARTIFICIAL_WEIGHT, ARTIFICIAL_EPSILON, MIN_VARIANCE
(0.9, 1e-05, 1.01, 5e-11)
"""
from __future__ import annotations

import numpy as np
from scipy.special import erfcx

from ..fresnel import Ideal
from ..geometry import dot, normalize, reflect, to_world
from ..render.lights import Environment

__all__ = ["GRID_SPACING", "ARTIFICIAL_WEIGHT", "ARTIFICIAL_EPSILON", "MIN_VARIANCE",
           "slope_statistics", "sample_grid", "grid_spacing", "grid_slopes", "lod_bias",
           "ndf", "lambda_", "projected_area", "mesonormal", "point_light", "artificial_micronormal",
           "MipEnvironment", "env_specular",
           "sh_basis", "sh_project", "sh_add_directional", "sh_irradiance",
           "diffuse_sh", "diffuse_directional"]

#: Spacing of the 5 x 5 grid in units of the slope standard deviation (Sec. 3.4).
GRID_SPACING = 0.9
#: Weight ``W~`` and bias ``epsilon`` of the artificial micronormal (Sec. 3.7).
ARTIFICIAL_WEIGHT = 1e-5
ARTIFICIAL_EPSILON = 1.01
#: Smallest slope variance kept (``alpha = 1e-5``, as the thesis's Listing 3.5 clamps).
MIN_VARIANCE = 0.5e-10
_MAX_CORRELATION = 0.99
_SQRT_PI = np.sqrt(np.pi)


# ------------------------------------------------------------------ statistics
def slope_statistics(moments) -> tuple[np.ndarray, ...]:
    """``(x0, y0, var_x, var_y, c_xy)`` of moments ``(..., 5)`` (Sec. 3.1), with the
    variances clamped to :data:`MIN_VARIANCE` and the correlation to ``[-0.99, 0.99]``
    (the clamping of Listing 3.5).

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments ``E1..E5``.

    Returns
    -------
    tuple of numpy.ndarray, each shape (...)
        ``(x0, y0, var_x, var_y, c_xy)``: mean slopes, clamped variances and covariance.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.1; Dupuy 2015, thesis, Listing 3.5 (the clamping).

    Examples
    --------
    >>> from microfacet.leadr import to_moments
    >>> [round(float(v), 4) for v in slope_statistics(to_moments(0.2, 0.4, rho=0.5, mean_slope=(0.1, 0.0)))]
    [0.1, 0.0, 0.02, 0.08, 0.02]
    """
    e = np.asarray(moments, dtype=np.float64)
    if e.shape[-1:] != (5,):
        raise ValueError(f"moments must have a last axis of size 5, got shape {e.shape}")
    x0, y0 = e[..., 0], e[..., 1]
    vx = np.maximum(e[..., 2] - x0 * x0, MIN_VARIANCE)
    vy = np.maximum(e[..., 3] - y0 * y0, MIN_VARIANCE)
    lim = _MAX_CORRELATION * np.sqrt(vx * vy)
    cxy = np.clip(e[..., 4] - x0 * y0, -lim, lim)
    return x0, y0, vx, vy, cxy


def mesonormal(moments) -> np.ndarray:
    """Mesonormal ``w_n- = (-E[x~], -E[y~], 1) / |.|`` of the pixel (Eq. 5).

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Unit mesonormals in the local frame.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Eq. 5.

    Examples
    --------
    >>> from microfacet.leadr import to_moments
    >>> mesonormal(to_moments(0.3, 0.3, mean_slope=(0.75, 0.0))).round(4)
    array([-0.6, -0. ,  0.8])
    """
    e = np.asarray(moments, dtype=np.float64)
    return normalize(np.stack([-e[..., 0], -e[..., 1], np.ones_like(e[..., 0])], axis=-1))


def ndf(moments, h) -> np.ndarray:
    """Beckmann NDF ``D(h) = P22(h~) / z_h^4`` of the Gaussian slope PDF ``P22`` of the
    moments (Eq. 2 and Sec. 3.1); 0 for ``z_h <= 0``.

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments.
    h : array-like, shape (..., 3)
        Unit microfacet normals in the local frame.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``D(h)`` in 1/sr.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Eq. 2, Sec. 3.1.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.leadr import to_moments
    >>> h = np.array([0.6, 0.0, 0.8])
    >>> round(float(ndf(to_moments(0.3, 0.3), h)), 4), round(float(mf.Beckmann(alpha=0.3).ndf(h)), 4)
    (0.0167, 0.0167)
    """
    x0, y0, vx, vy, cxy = slope_statistics(moments)
    h = np.asarray(h, dtype=np.float64)
    z = h[..., 2]
    zs = np.where(z > 0, z, 1.0)
    x, y = -h[..., 0] / zs - x0, -h[..., 1] / zs - y0
    det = vx * vy - cxy * cxy
    arg = -0.5 * (x * x * vy + y * y * vx - 2.0 * x * y * cxy) / det
    p22 = np.exp(arg) / (2.0 * np.pi * np.sqrt(det))
    return np.where(z > 0, p22 / zs**4, 0.0)


def lambda_(moments, k) -> np.ndarray:
    """Smith ``Lambda(k)`` of the noncentral anisotropic Gaussian slopes (Sec. 3.2).

    The slopes projected on the azimuth of ``k`` are Gaussian with mean
    ``mu = cos phi x0 + sin phi y0`` and variance ``sigma^2 = cos^2 phi var_x +
    sin^2 phi var_y + 2 cos phi sin phi c_xy``; with ``nu = (cot theta - mu) /
    (sigma sqrt 2)`` the exact Beckmann ``Lambda = (exp(-nu^2) / (nu sqrt pi) - erfc nu) / 2``
    is used (the supplemental uses Walter's rational approximation of it). Evaluated as
    ``nu = (z - x x0 - y y0) / sqrt(2 (x^2 var_x + y^2 var_y + 2 x y c_xy))``, finite at
    normal incidence (``Lambda = 0``); ``inf`` where ``nu <= 0`` (``k`` below the mesosurface).

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments.
    k : array-like, shape (..., 3)
        Unit directions in the local frame.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``Lambda(k)`` (``inf`` below the mesosurface).

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.2.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> round(float(lambda_(to_moments(0.3, 0.3), np.array([0.98, 0.0, 0.198997]))), 4)   # 78.5 degrees
    0.0944
    """
    x0, y0, vx, vy, cxy = slope_statistics(moments)
    k = np.asarray(k, dtype=np.float64)
    x, y, z = k[..., 0], k[..., 1], k[..., 2]
    c = z - x * x0 - y * y0
    s2 = 2.0 * (x * x * vx + y * y * vy + 2.0 * x * y * cxy)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        nu = np.where(s2 > 0, c / np.sqrt(s2), np.where(c > 0, np.inf, -1.0))
        lam = np.maximum(0.5 * np.exp(-nu * nu) * (1.0 / (nu * _SQRT_PI) - erfcx(nu)), 0.0)
        lam = np.where(np.isfinite(lam), lam, 0.0)              # nu = inf: Lambda = 0
    return np.where(nu > 0, lam, np.inf)


def projected_area(moments, k) -> np.ndarray:
    """Projected area toward ``k`` of the microsurface of ``moments`` per unit macro area,
    ``A(k) = int <k, n>+ D(n) dn = c_k (1 + Lambda(k))`` with ``c_k = (-x0, -y0, 1) . k``
    the mesonormal's (supplemental Eq. 4, 9); 0 where ``c_k <= 0``.

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments.
    k : array-like, shape (..., 3)
        Unit directions in the local frame.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``A(k)`` per unit macro area (0 where the mesonormal faces away).

    References
    ----------
    Dupuy et al. 2013, supplemental material, Eq. 4, 9.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> round(float(projected_area(to_moments(0.3, 0.3), np.array([0.0, 0.0, 1.0]))), 6)   # cos theta = 1
    1.0
    """
    e = np.asarray(moments, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    c = k[..., 2] - k[..., 0] * e[..., 0] - k[..., 1] * e[..., 1]
    with np.errstate(invalid="ignore"):
        return np.where(c > 0, c * (1.0 + lambda_(e, k)), 0.0)


# ------------------------------------------------------------------ point light
def point_light(moments, wi, wo, irradiance=1.0, fresnel=None, shadowing: bool = True) -> np.ndarray:
    """Radiance ``(..., 3)`` of rough specular microfacets lit by a point/directional
    light (Sec. 3.3, with the Fresnel term put back):

        I = E F(o.h) D(h) / (4 c_o (1 + Lambda(o) + Lambda(i))),   c_o = (-x0, -y0, 1) . o,

    ``1 / c_o`` being the inverse projected area of the mesonormal (Eq. 4) and
    ``E`` the irradiance the light delivers to a surface facing it. With
    ``shadowing=False`` the self-shadowing term ``Lambda(i)`` is dropped (masking only,
    Sec. 1.5: use it when shadows of the displacement are not rendered at close range).
    This equals ``MicrofacetBRDF(Beckmann.from_moments(*E), fresnel).eval_cos(wi, wo) * E``.
    0 where either direction is below the macro horizon, ``o.h <= 0`` or ``c_o <= 0``.

    Parameters
    ----------
    moments : ndarray, (..., 5)
        The pixels' slope moments.
    wi, wo : ndarray, (..., 3)
        Light and view directions in the macrosurface's frame.
    irradiance : float or array-like
        ``E``, scalar or RGB.
    fresnel : Fresnel, optional
        Default: ideal (``F = 1``).
    shadowing : bool
        Include ``Lambda(i)``.

    Returns
    -------
    ndarray, (..., 3)
        Radiance.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 1.4, 1.5, 3.2, 3.3, Eq. 4.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.leadr import to_moments
    >>> E = to_moments(0.3, 0.3)
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.6, 0.0, 0.8])
    >>> point_light(E, wi, wo).round(4)
    array([1.1052, 1.1052, 1.1052])
    >>> mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3)).eval_cos(wi, wo).round(4)      # the same
    array([1.1052, 1.1052, 1.1052])
    """
    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    e = np.asarray(moments, dtype=np.float64)
    h = normalize(wi + wo)
    oh = dot(wo, h)
    c_o = wo[..., 2] - wo[..., 0] * e[..., 0] - wo[..., 1] * e[..., 1]
    lam = lambda_(e, wo) + (lambda_(e, wi) if shadowing else 0.0)
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (oh > 0) & (h[..., 2] > 0) & (c_o > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(ok, ndf(e, h) / (4.0 * c_o * (1.0 + lam)), 0.0)
    f = (Ideal() if fresnel is None else fresnel)(np.clip(oh, 0.0, 1.0))
    return np.asarray(irradiance, dtype=np.float64) * f * s[..., None]


# ------------------------------------------------------------------ sample grid
def sample_grid(n: int = 5, spacing: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """1-D positions ``p`` (in standard deviations) and weights ``w`` (summing to 1) of
    the ``n x n`` integration grid (Sec. 3.4).

    ``p`` is uniform with ``spacing`` between samples, centred on 0; ``w`` is the standard
    normal density at ``p``, normalized. The default spacing is 0.9 (the supplemental's
    empirical best for ``n = 5``: ``p = (-1.8, -0.9, 0, 0.9, 1.8)``,
    ``w = (0.0725, 0.2443, 0.3663, 0.2443, 0.0725)``); from ``n = 8`` on the grid spans
    ``[-3, 3]`` ("it is not necessary to place samples beyond"), spacing ``6 / (n - 1)``.

    Parameters
    ----------
    n : int, optional
        Samples per axis (default 5).
    spacing : float, optional
        Distance between samples in standard deviations (default: 0.9 below ``n = 8``,
        ``6 / (n - 1)`` from 8 on).

    Returns
    -------
    p : numpy.ndarray, shape (n,)
        Positions in standard deviations.
    w : numpy.ndarray, shape (n,)
        Weights, summing to 1.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.4.

    Examples
    --------
    >>> p, w = sample_grid(5)
    >>> p.round(2), w.round(4)
    (array([-1.8, -0.9,  0. ,  0.9,  1.8]), array([0.0725, 0.2443, 0.3663, 0.2443, 0.0725]))
    """
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    n = int(n)
    if n == 1:
        return np.zeros(1), np.ones(1)
    if spacing is None:
        spacing = min(GRID_SPACING, 6.0 / (n - 1))
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, got {spacing!r}")
    p = (np.arange(n) - 0.5 * (n - 1)) * spacing
    w = np.exp(-0.5 * p * p)
    return p, w / w.sum()


def grid_spacing(n: int) -> float:
    """Spacing of :func:`sample_grid` for ``n`` samples per axis.

    Parameters
    ----------
    n : int
        Samples per axis.

    Returns
    -------
    float
        Distance between neighbouring samples in standard deviations (0 for ``n = 1``).

    Examples
    --------
    >>> grid_spacing(5), grid_spacing(13)
    (0.9, 0.5)
    """
    p, _ = sample_grid(n)
    return float(p[1] - p[0]) if n > 1 else 0.0


def grid_slopes(moments, n: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slopes ``(x~, y~)`` and weights ``W = w_j w_k`` of the ``n x n`` grid, each
    ``(..., n * n)`` (Algorithm 1): ``x~ = x0 + p_j sigma_x``,
    ``y~ = y0 + (r p_j + sqrt(1 - r^2) p_k) sigma_y`` with ``r = c_xy / (sigma_x sigma_y)``,
    i.e. the grid of the standard normal mapped by the Cholesky factor of the covariance.

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments.
    n : int, optional
        Samples per axis (default 5).

    Returns
    -------
    x, y : numpy.ndarray, shape (..., n * n)
        The grid's slopes.
    W : numpy.ndarray, shape (..., n * n)
        Their weights (summing to 1).

    References
    ----------
    Dupuy et al. 2013, supplemental material, Simplified Algorithm 1.

    Examples
    --------
    >>> from microfacet.leadr import to_moments
    >>> x, y, W = grid_slopes(to_moments(0.2, 0.2), n=3)
    >>> x.shape, round(float(W.sum()), 6)
    ((9,), 1.0)
    """
    x0, y0, vx, vy, cxy = slope_statistics(moments)
    p, w = sample_grid(n)
    pj, pk = np.repeat(p, len(p)), np.tile(p, len(p))
    sx, sy = np.sqrt(vx)[..., None], np.sqrt(vy)[..., None]
    r = (cxy / np.sqrt(vx * vy))[..., None]
    x = x0[..., None] + pj * sx
    y = y0[..., None] + (r * pj + np.sqrt(1.0 - r * r) * pk) * sy
    return x, y, np.broadcast_to(np.outer(w, w).ravel(), x.shape)


#: LOD bias replacing the constant -1.48 of Sec. 3.5 against banding, by grid size.
_LOD_BIAS = ((5, 0.5), (32, -0.5), (128, -1.48))


def lod_bias(n: int) -> float:
    """Constant of the LOD rule for an ``n x n`` grid: 0.5 for ``n <= 5``, -0.5 for 32,
    -1.48 (unbiased) from 128 on (Sec. 3.5), linear in ``log2 n`` in between.

    Parameters
    ----------
    n : int
        Grid samples per axis.

    Returns
    -------
    float
        The constant ``b`` of the LOD rule.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.5.

    Examples
    --------
    >>> lod_bias(5), lod_bias(32)
    (0.5, -0.5)
    """
    ln = np.log2([m for m, _ in _LOD_BIAS])
    return float(np.interp(np.log2(max(n, 1)), ln, [b for _, b in _LOD_BIAS]))


# ------------------------------------------------------------------ micronormals
def _normals(x, y) -> np.ndarray:
    return normalize(np.stack([-x, -y, np.ones_like(x)], axis=-1))


def artificial_micronormal(moments, wo, epsilon: float = ARTIFICIAL_EPSILON) -> np.ndarray:
    """Artificial micronormal ``w~ = (w_n- - (w_n-.o) eps o) / |.|`` (Sec. 3.7).

    The mesonormal biased toward the view: where the mesonormal faces away from ``o``
    (``w_n-.o < 0``, a silhouette of a low-tessellated mesh) it is visible
    (``w~.o = -(eps - 1) w_n-.o |.|^-1 > 0``); elsewhere it is back-facing and contributes
    nothing. Used with weight :data:`ARTIFICIAL_WEIGHT` in the grid sums.

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments of each pixel.
    wo : array-like, shape (..., 3)
        Unit view directions in the local frames.
    epsilon : float, optional
        The bias ``eps`` (> 1; default 1.01).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Unit artificial micronormals.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.7.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> E = to_moments(0.1, 0.1, mean_slope=(-3.0, 0.0))          # mesonormal tilted toward +x
    >>> wo = np.array([-0.8, 0.0, 0.6])                            # seen from the other side
    >>> bool(mesonormal(E) @ wo < 0), bool(artificial_micronormal(E, wo) @ wo > 0)
    (True, True)
    """
    m = mesonormal(moments)
    wo = np.asarray(wo, dtype=np.float64)
    return normalize(m - epsilon * dot(m, wo)[..., None] * wo)


def _grid_normals(moments, wo, n: int, fallback: bool):
    """Micronormals ``(..., M, 3)``, weights ``W (..., M)`` and projected areas
    ``<n,o>+ / n_z`` of the grid, with the artificial micronormal appended last."""
    x, y, w = grid_slopes(moments, n)
    normals = _normals(x, y)
    wo = np.asarray(wo, dtype=np.float64)
    if fallback:
        extra = artificial_micronormal(moments, wo)[..., None, :]
        lead = np.broadcast_shapes(normals.shape[:-2], extra.shape[:-2])
        normals = np.concatenate([np.broadcast_to(normals, lead + normals.shape[-2:]),
                                  np.broadcast_to(extra, lead + (1, 3))], axis=-2)
        w = np.concatenate([np.broadcast_to(w, lead + w.shape[-1:]),
                            np.full(lead + (1,), ARTIFICIAL_WEIGHT)], axis=-1)
    vn = np.maximum(dot(normals, wo[..., None, :]), 0.0)
    zn = np.maximum(normals[..., 2], 1e-12)
    return normals, w, vn, zn


# ------------------------------------------------------------------ environment
class MipEnvironment(Environment):
    """A lat-long environment (:class:`~microfacet.render.Environment` conventions) with
    a MIP pyramid for filtered lookups.

    Level ``l + 1`` is the 2 x 2 box filter of level ``l`` weighted by the texels' solid
    angles, so a constant map stays constant and every level keeps the map's integral
    ``sum L dOmega``; the pyramid stops at the first odd dimension. Lookups are
    trilinear: bilinear in each level (wrapping in ``phi``), linear between levels.

    Parameters
    ----------
    radiance : Environment or array-like, shape (H, W, 3)
        The lat-long radiance map (level 0).

    Examples
    --------
    >>> import numpy as np
    >>> env = MipEnvironment(np.full((16, 32, 3), 0.5))         # a constant 16 x 32 lat-long map
    >>> [level.map.shape[:2] for level in env.levels], env.texture_size
    ([(16, 32), (8, 16), (4, 8), (2, 4), (1, 2)], 8.0)
    >>> env.radiance_lod(np.array([0.0, 0.0, 1.0]), 2.5)          # constant at every level
    array([0.5, 0.5, 0.5])
    """

    def __init__(self, radiance):
        super().__init__(radiance)
        self.levels = [Environment(self.map)]
        while all(s % 2 == 0 and s >= 2 for s in self.levels[-1].map.shape[:2]):
            self.levels.append(Environment(_downsample_latlong(self.levels[-1].map)))

    @property
    def texture_size(self) -> float:
        """Side of the cube map of the same angular resolution, ``T = H / 2``: a cube
        texel spans ``pi / (2 T)``, a lat-long texel ``pi / H`` (Sec. 3.5)."""
        return self.map.shape[0] / 2.0

    def radiance_lod(self, w, lod) -> np.ndarray:
        """Radiance ``(..., 3)`` from world directions ``w`` at level of detail ``lod``
        (broadcast against ``w[..., 0]``, clamped to the pyramid).

        Parameters
        ----------
        w : array-like, shape (..., 3)
            World directions (unit vectors).
        lod : float or array-like
            Level of detail (0: the full-resolution map), broadcast against ``w[..., 0]``.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            Trilinearly filtered radiance.
        """
        w = np.asarray(w, dtype=np.float64)
        top = len(self.levels) - 1
        lod = np.clip(np.broadcast_to(np.asarray(lod, dtype=np.float64), w.shape[:-1]), 0.0, top)
        base = np.minimum(np.floor(lod), max(top - 1, 0)).astype(np.intp)
        frac = (lod - base)[..., None]
        out = np.zeros(w.shape[:-1] + (3,))
        for level in np.unique(base):           # loop over MIP levels, not elements
            sel = base == level
            lo = self.levels[level].radiance(w[sel])
            if top > 0:
                hi = self.levels[level + 1].radiance(w[sel])
                lo = lo + frac[sel] * (hi - lo)
            out[sel] = lo
        return out


def _downsample_latlong(m: np.ndarray) -> np.ndarray:
    """2 x 2 box filter weighted by the texels' exact solid angles (rows of ``cos``
    differences), so that ``sum L dOmega`` is the same at every level."""
    h = m.shape[0]
    edges = np.cos(np.arange(h + 1) / h * np.pi)
    sw = np.broadcast_to((edges[:-1] - edges[1:])[:, None, None], m.shape)
    blocks = (h // 2, 2, m.shape[1] // 2, 2, 3)
    return (m * sw).reshape(blocks).sum(axis=(1, 3)) / sw.reshape(blocks).sum(axis=(1, 3))


def env_specular(moments, wo, env: MipEnvironment, frame=None, n: int = 5, fresnel=None,
                 lod_offset: float | None = None, fallback: bool = True) -> np.ndarray:
    """Radiance ``(..., 3)`` of rough specular microfacets under a filtered environment,
    by the ``n x n`` sample grid (Simplified Algorithm 1, Sec. 3.5):

        I = sum_k W_k F(<n_k, o>) (<n_k, o>+ / n_k,z) L(r_k, LOD_k)  /  sum_k W_k <n_k, o>+ / n_k,z

    with ``r_k = 2 (n_k.o) n_k - o`` and ``LOD_k = 0.72 ln J_k + log2(d max(sigma_x,
    sigma_y) T) + b``, ``J_k = 4 n_k,z^3 <n_k, o>`` the Jacobian from slope area to solid
    angle, ``d`` the grid spacing, ``T`` the environment's :attr:`~MipEnvironment.texture_size`
    and ``b`` :func:`lod_bias` (``lod_offset`` overrides it). Masking only (no
    self-shadowing); reflected directions below the macro horizon still read the map.

    Parameters
    ----------
    moments : (..., 5)
        Slope moments of each pixel.
    wo : (..., 3)
        View directions in the local frames.
    env : MipEnvironment
        World-space lat-long environment.
    frame : (s, t, n) or None
        World tangents and normal of each local frame (``None``: local = world).
    n : int
        Grid samples per axis (5 by default).
    fresnel : Fresnel or None
        Microfacet Fresnel term of ``cos theta_d = <n_k, o>`` (default: ideal mirror).
    lod_offset : float or None
        The constant ``b`` of the LOD rule (``None``: :func:`lod_bias` of ``n``).
    fallback : bool
        Append the artificial micronormal (Sec. 3.7), so the result is defined even when
        every grid normal faces away from ``o``.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Reflected radiance toward ``wo``.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Simplified Algorithm 1, Sec. 3.4-3.5, 3.7.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> env = MipEnvironment(np.full((16, 32, 3), 0.5))
    >>> env_specular(to_moments(0.3, 0.3), np.array([0.0, 0.6, 0.8]), env).round(4)   # ideal Fresnel: L
    array([0.5, 0.5, 0.5])
    """
    wo = np.asarray(wo, dtype=np.float64)
    normals, w, vn, zn = _grid_normals(moments, wo, n, fallback)
    r = reflect(wo[..., None, :], normals)
    if frame is not None:
        s, t, nn = (np.asarray(v, dtype=np.float64)[..., None, :] for v in frame)
        r = to_world(r, s, t, nn)
    _, _, vx, vy, _ = slope_statistics(moments)
    spacing = grid_spacing(n) if n > 1 else 1.0
    offset = lod_bias(n) if lod_offset is None else float(lod_offset)
    with np.errstate(divide="ignore"):
        base = offset + np.log2(spacing * np.sqrt(np.maximum(vx, vy)) * env.texture_size)
        lod = 0.72 * np.log(4.0 * zn**3 * vn) + base[..., None]
    lod = np.where(np.isfinite(lod), lod, 0.0)
    radiance = env.radiance_lod(r, lod)
    f = (Ideal() if fresnel is None else fresnel)(vn)
    a = w * vn / zn
    return (a[..., None] * f * radiance).sum(axis=-2) / _safe(a.sum(axis=-1))[..., None]


def _safe(s):
    return np.where(s > 0, s, np.inf)


# ------------------------------------------------------------------ SH irradiance
#: Normalization constants of the real SH basis up to l = 2 (Algorithm 2: 0.282095,
#: 0.488603, 1.092548, 0.315392, 0.546274), in closed form.
_Y = (0.5 / np.sqrt(np.pi), np.sqrt(3.0 / (4.0 * np.pi)), 0.5 * np.sqrt(15.0 / np.pi),
      0.25 * np.sqrt(5.0 / np.pi), 0.25 * np.sqrt(15.0 / np.pi))
#: Irradiance constants of Ramamoorthi and Hanrahan 2001 (Eq. 13: 0.429043, 0.511664,
#: 0.743125, 0.886227, 0.247708) from the clamped-cosine SH coefficients
#: ``A_0 = pi``, ``A_1 = 2 pi / 3``, ``A_2 = pi / 4``.
_C1, _C2, _C3 = np.pi / 4 * _Y[4], np.pi / 3 * _Y[1], 3.0 * np.pi / 4 * _Y[3]
_C4, _C5 = np.pi * _Y[0], np.pi / 4 * _Y[3]


def sh_basis(w) -> np.ndarray:
    """Real SH ``Y_lm(w)`` ``(..., 9)`` in the order ``L00, L1-1, L10, L11, L2-2, L2-1,
    L20, L21, L22`` (Algorithm 2's constants: ``Y_1 = 0.488603 (y, z, x)``,
    ``Y_2-2,2-1,21 = 1.092548 (xy, yz, xz)``, ``Y_20 = 0.315392 (3z^2 - 1)``,
    ``Y_22 = 0.546274 (x^2 - y^2)``), in the frame of ``w``.

    Parameters
    ----------
    w : array-like, shape (..., 3)
        Unit directions.

    Returns
    -------
    numpy.ndarray, shape (..., 9)
        ``Y_lm(w)``.

    Examples
    --------
    >>> import numpy as np
    >>> sh_basis(np.array([0.0, 0.0, 1.0])).round(4)
    array([0.2821, 0.    , 0.4886, 0.    , 0.    , 0.    , 0.6308, 0.    ,
           0.    ])
    """
    w = np.asarray(w, dtype=np.float64)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([np.full_like(x, _Y[0]), _Y[1] * y, _Y[1] * z, _Y[1] * x,
                     _Y[2] * x * y, _Y[2] * y * z, _Y[3] * (3 * z * z - 1), _Y[2] * x * z,
                     _Y[4] * (x * x - y * y)], axis=-1)


def sh_project(env) -> np.ndarray:
    """SH coefficients ``L_lm`` ``(9, 3)`` of a lat-long environment (an
    :class:`~microfacet.render.Environment` or an ``(H, W, 3)`` map), in world
    coordinates: ``int L(w) Y_lm(w) dw`` with ``L`` constant over each texel and ``Y_lm``
    integrated over the texel by a 3 x 3 Gauss-Legendre rule in ``(cos theta, phi)``
    (exact solid angles; a constant map is projected exactly, smooth ones to ~1e-6).

    Parameters
    ----------
    env : Environment or array-like, shape (H, W, 3)
        A lat-long radiance map.

    Returns
    -------
    numpy.ndarray, shape (9, 3)
        The SH coefficients ``L_lm``.

    Examples
    --------
    >>> import numpy as np
    >>> sh_project(np.ones((8, 16, 3)))[:, 0].round(4)      # a constant map: L00 = 2 sqrt(pi) only
    array([ 3.5449, -0.    ,  0.    ,  0.    , -0.    , -0.    , -0.    ,
           -0.    , -0.    ])
    """
    m = np.asarray(env.map if isinstance(env, Environment) else env, dtype=np.float64)
    h, wd = m.shape[:2]
    t, g = np.polynomial.legendre.leggauss(3)
    t, g = 0.5 * (t + 1.0), 0.5 * g                              # on [0, 1]
    c0 = np.cos(np.arange(h) / h * np.pi)[:, None]                # cos theta at row tops
    c1 = np.cos(np.arange(1, h + 1) / h * np.pi)[:, None]
    u = c0 + (c1 - c0) * t                                        # (h, 3) nodes in cos theta
    phi = -np.pi + (np.arange(wd)[:, None] + t) * (2.0 * np.pi / wd)   # (wd, 3)
    s = np.sqrt(np.maximum(0.0, 1.0 - u * u))
    # w = (sin theta sin phi, cos theta, sin theta cos phi), nodes (h, 3, wd, 3)
    w = np.stack(np.broadcast_arrays(s[:, :, None, None] * np.sin(phi)[None, None],
                                     u[:, :, None, None] + 0.0 * phi[None, None],
                                     s[:, :, None, None] * np.cos(phi)[None, None]), axis=-1)
    weight = ((c0 - c1) * g)[:, :, None, None] * (g * (2.0 * np.pi / wd))[None, None]
    y = np.einsum("iajbk,iajb->ijk", sh_basis(w), weight)           # per-texel integral of Y
    return np.einsum("ijk,ijc->kc", y, m)


def sh_add_directional(coeffs, direction, radiance) -> np.ndarray:
    """``coeffs`` plus a directional light of world ``direction`` and RGB ``radiance``
    (Algorithm 2: ``L_lm += Y_lm(w_i) L``); returns a new ``(9, 3)`` array.

    Parameters
    ----------
    coeffs : array-like, shape (9, 3)
        SH radiance coefficients.
    direction : array-like, shape (3,)
        World direction of the light (normalized here).
    radiance : float or array-like, shape (3,)
        RGB radiance of the light.

    Returns
    -------
    numpy.ndarray, shape (9, 3)
        The new coefficients.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Simplified Algorithm 2.

    Examples
    --------
    >>> import numpy as np
    >>> coeffs = sh_add_directional(np.zeros((9, 3)), np.array([0.0, 0.0, 1.0]), [1.0, 1.0, 1.0])
    >>> sh_irradiance(coeffs, np.array([0.0, 0.0, 1.0])).round(3)       # 1 up to the SH's ringing
    array([1.062, 1.062, 1.062])
    """
    d = normalize(np.asarray(direction, dtype=np.float64))
    rgb = np.broadcast_to(np.asarray(radiance, dtype=np.float64), (3,))
    return np.asarray(coeffs, dtype=np.float64) + sh_basis(d)[:, None] * rgb


def sh_irradiance(coeffs, normals) -> np.ndarray:
    """Irradiance ``E(n) = int L(w) <n, w>+ dw`` ``(..., 3)`` of the 9-coefficient SH
    radiance at world normals ``n`` (Ramamoorthi and Hanrahan 2001, Eq. 13). Exact for
    radiance of degree <= 2 (constant and linear in particular).

    Parameters
    ----------
    coeffs : array-like, shape (9, 3)
        SH radiance coefficients.
    normals : array-like, shape (..., 3)
        Unit world normals.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Irradiance ``E(n)``.

    References
    ----------
    Ramamoorthi & Hanrahan 2001, Eq. 13.

    Examples
    --------
    >>> import numpy as np
    >>> sh_irradiance(sh_project(np.ones((8, 16, 3))), np.array([0.0, 0.0, 1.0])).round(4)    # pi
    array([3.1416, 3.1416, 3.1416])
    """
    L = np.asarray(coeffs, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    x, y, z = (n[..., i, None] for i in range(3))
    l00, l1m1, l10, l11, l2m2, l2m1, l20, l21, l22 = L
    return (_C1 * l22 * (x * x - y * y) + _C3 * l20 * z * z + _C4 * l00 - _C5 * l20
            + 2.0 * _C1 * (l2m2 * x * y + l21 * x * z + l2m1 * y * z)
            + 2.0 * _C2 * (l11 * x + l1m1 * y + l10 * z))


def _diffuse(moments, wo, n, fallback, irradiance_of, albedo):
    wo = np.asarray(wo, dtype=np.float64)
    normals, w, vn, zn = _grid_normals(moments, wo, n, fallback)
    a = w * vn / zn
    e = irradiance_of(normals)
    rgb = np.broadcast_to(np.asarray(albedo, dtype=np.float64), (3,))
    return rgb / np.pi * (a[..., None] * e).sum(axis=-2) / _safe(a.sum(axis=-1))[..., None]


def diffuse_sh(moments, wo, coeffs, frame=None, albedo=1.0, n: int = 5,
               fallback: bool = True) -> np.ndarray:
    """Radiance ``(..., 3)`` of rough diffuse (Lambertian, reflectance ``albedo``)
    microfacets under the SH irradiance ``coeffs`` (:func:`sh_project`,
    :func:`sh_add_directional`), by the ``n x n`` grid (Simplified Algorithm 3):

        I = albedo / pi * sum_k W_k (<n_k, o>+ / n_k,z) E(n_k)  /  sum_k W_k <n_k, o>+ / n_k,z.

    Masking only. ``frame`` as in :func:`env_specular` (``None``: local = world).

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments of each pixel.
    wo : array-like, shape (..., 3)
        Unit view directions in the local frames.
    coeffs : array-like, shape (9, 3)
        World-space SH radiance coefficients.
    frame : (s, t, n) or None, optional
        World tangents and normal of each local frame (``None``: local = world).
    albedo : float or array-like, optional
        Lambertian reflectance (scalar or RGB; default 1).
    n : int, optional
        Grid samples per axis (default 5).
    fallback : bool, optional
        Append the artificial micronormal (Sec. 3.7) (default ``True``).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Reflected radiance toward ``wo``.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Simplified Algorithm 3, Sec. 3.6.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> coeffs = sh_project(np.ones((8, 16, 3)))                  # uniform white sky and ground
    >>> diffuse_sh(to_moments(0.3, 0.3), np.array([0.0, 0.6, 0.8]), coeffs, albedo=0.5).round(4)
    array([0.5, 0.5, 0.5])
    """
    def irradiance(normals):
        if frame is not None:
            s, t, nn = (np.asarray(v, dtype=np.float64)[..., None, :] for v in frame)
            normals = to_world(normals, s, t, nn)
        return sh_irradiance(coeffs, normals)
    return _diffuse(moments, wo, n, fallback, irradiance, albedo)


def diffuse_directional(moments, wo, wi, irradiance=1.0, albedo=1.0, n: int = 5,
                        fallback: bool = True) -> np.ndarray:
    """Rough diffuse microfacets under one directional light of local direction ``wi``:
    :func:`diffuse_sh` with ``E(n_k) = E <n_k, i>+`` (end of Sec. 3.6).

    Parameters
    ----------
    moments : array-like, shape (..., 5)
        Slope moments of each pixel.
    wo : array-like, shape (..., 3)
        Unit view directions in the local frames.
    wi : array-like, shape (..., 3)
        Unit direction toward the light in the local frames.
    irradiance : float or array-like, optional
        The light's irradiance (scalar or RGB; default 1).
    albedo : float or array-like, optional
        Lambertian reflectance (scalar or RGB; default 1).
    n : int, optional
        Grid samples per axis (default 5).
    fallback : bool, optional
        Append the artificial micronormal (Sec. 3.7) (default ``True``).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Reflected radiance toward ``wo``.

    References
    ----------
    Dupuy et al. 2013, supplemental material, Sec. 3.6.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import to_moments
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> diffuse_directional(to_moments(1e-3, 1e-3), n, n, albedo=0.5).round(4)     # flat: albedo / pi
    array([0.1592, 0.1592, 0.1592])
    """
    wi = np.asarray(wi, dtype=np.float64)
    rgb = np.broadcast_to(np.asarray(irradiance, dtype=np.float64), (3,))

    def irr(normals):
        return np.maximum(dot(normals, wi[..., None, :]), 0.0)[..., None] * rgb
    return _diffuse(moments, wo, n, fallback, irr, albedo)
