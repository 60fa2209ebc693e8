"""Glint images: a procedural scratched normal map, a plane under a point light rendered
with the P-BRDF (Chermain et al. 2019, Fig. 1 and 11 style) and by naive per-pixel
sampling of the normal-mapped near-mirror surface, and the demo's glints section.

Scene (:class:`PlaneScene`): the unit uv square of the (wrapped) normal map covers the
plane ``[-1, 1]^2`` (``u = (x + 1) / 2``, ``v = (y + 1) / 2``, local frame = world frame,
z up), seen by an orthographic camera of elevation ``view_deg`` from the plane (azimuth
-y) and lit by an isotropic point light of intensity ``intensity`` at ``light``. Pixel
``p`` sees the Gaussian footprint ``k_P`` of its pixel filter (a Gaussian of standard
deviation :data:`PIXEL_SIGMA` pixels on the image plane), mapped to uv.

- P-BRDF: ``L_p = I / r^2 eval_cos_P(wi, wo)`` with the footprint's P-BRDF (noise free).
- Naive reference: ``L_p = 1/n sum_k I / r^2 eval_cos_k(wi, wo)`` over ``n`` positions
  ``u_k ~ k_P`` of the bilinearly interpolated normal map, each a near-mirror Beckmann
  lobe (``sigma_eps`` slope deviation, mean slope of the map at ``u_k``) with the library's
  :class:`~microfacet.MicrofacetBRDF` (the paper's "classic normal map" reference,
  Sec. 5.2.2). Its expectation is the image the P-BRDF approximates.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import backend as backend_
from ..brdf import MicrofacetBRDF
from ..distributions import Beckmann
from ..geometry import dot, half_vector
from .pbrdf import Microsurface, eval_cos_footprints

__all__ = ["scratched_normal_map", "PlaneScene", "render_pbrdf", "render_naive", "relative_error",
           "glints_section", "render_cli", "PIXEL_SIGMA"]

#: Standard deviation of the Gaussian pixel filter, in pixels.
PIXEL_SIGMA = 0.5


# ------------------------------------------------------------------------ normal map
def scratched_normal_map(size: int = 512, scratches: int = 160, depth: float = 1.5,
                         width: float = 0.9, roughness: float = 0.04, seed: int = 0) -> np.ndarray:
    """A procedural scratched-metal normal map ``(size, size, 3)`` (unit normals, signed).

    Height field (texel units): ``scratches`` straight grooves of Gaussian profile (width
    ``width`` texels, depth up to ``depth`` texels, random orientation, position and length)
    over a smooth low-amplitude bump field of slope deviation ``roughness``; normals from
    the periodic central-difference gradient. Deterministic for a ``seed``; wraps.

    Parameters
    ----------
    size : int
        Width and height in texels (at least 8).
    scratches : int
        Number of grooves.
    depth, width : float
        Largest groove depth and the grooves' Gaussian width, in texels.
    roughness : float
        Slope deviation of the bump field.
    seed : int
        Random seed.

    Returns
    -------
    (size, size, 3) ndarray
        Unit normals (z up), signed.

    Examples
    --------
    >>> n = scratched_normal_map(16, scratches=4, seed=1)
    >>> n.shape, bool(np.allclose(np.linalg.norm(n, axis=-1), 1.0)), bool((n[..., 2] > 0).all())
    ((16, 16, 3), True, True)
    """
    if int(size) != size or size < 8:
        raise ValueError(f"size must be an integer >= 8, got {size!r}")
    rng = np.random.default_rng(seed)
    n = int(size)
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    hgt = np.zeros((n, n))
    for _ in range(int(scratches)):
        cx, cy = rng.uniform(0, n, 2)
        ang = rng.uniform(0, np.pi)
        half = rng.uniform(0.1, 0.45) * n
        d = rng.uniform(0.3, 1.0) * depth
        dx, dy = np.cos(ang), np.sin(ang)
        px = (x - cx + n / 2) % n - n / 2                   # wrapped offsets
        py = (y - cy + n / 2) % n - n / 2
        t = np.clip(px * dx + py * dy, -half, half)
        dist2 = (px - t * dx) ** 2 + (py - t * dy) ** 2
        taper = np.clip(1.0 - (np.abs(t) / half) ** 4, 0.0, 1.0)
        hgt -= d * taper * np.exp(-0.5 * dist2 / width**2)
    # smooth bumps: band-limited noise, scaled to the requested slope deviation
    k = np.fft.fftfreq(n)
    kk = np.sqrt(k[:, None] ** 2 + k[None, :] ** 2)
    spec = np.exp(-(kk / 0.03) ** 2) * (rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n)))
    bumps = np.real(np.fft.ifft2(spec))
    g = np.gradient(bumps)
    bumps *= roughness / max(np.std(np.concatenate([g[0].ravel(), g[1].ravel()])), 1e-12)
    hgt += bumps
    sx = (np.roll(hgt, -1, 1) - np.roll(hgt, 1, 1)) / 2.0        # slope x~ = dH/dx
    sy = (np.roll(hgt, -1, 0) - np.roll(hgt, 1, 0)) / 2.0
    inv = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
    return np.stack([-sx * inv, -sy * inv, inv], -1)


# ------------------------------------------------------------------------------ scene
@dataclass
class PlaneScene:
    """A normal-mapped plane, an orthographic camera and a point light (module notes).

    Parameters
    ----------
    width : int
        Image width in pixels; the height is ``round(width sin(view_deg))``.
    view_deg : float
        Camera elevation from the plane, degrees, in ``(0, 90]``.
    light : (3,) tuple
        Position of the point light (``z > 0``).
    intensity : float
        The light's intensity ``I`` (radiance ``I / r^2`` times ``eval_cos``).

    Examples
    --------
    Each pixel's footprint is a Gaussian of :data:`PIXEL_SIGMA` pixels, mapped to uv:

    >>> scene = PlaneScene(width=8)
    >>> uv, cov, points = scene.pixels()
    >>> scene.height, uv.shape, bool(np.isclose(cov[0, 0], (PIXEL_SIGMA / 8) ** 2))
    (6, (48, 2), True)
    """

    width: int = 64
    view_deg: float = 50.0
    light: tuple = (0.0, 0.3, 1.0)
    intensity: float = 1.0

    def __post_init__(self):
        if int(self.width) != self.width or self.width < 1:
            raise ValueError(f"width must be a positive integer, got {self.width!r}")
        if not 0 < self.view_deg <= 90:
            raise ValueError(f"view_deg must lie in (0, 90], got {self.view_deg!r}")
        lt = np.asarray(self.light, dtype=np.float64)
        if lt.shape != (3,) or not np.all(np.isfinite(lt)) or lt[2] <= 0:
            raise ValueError(f"light must be a finite position (x, y, z) with z > 0, got {self.light!r}")
        self.width = int(self.width)

    @property
    def height(self) -> int:
        return max(1, int(round(self.width * np.sin(np.radians(self.view_deg)))))

    @property
    def wo(self) -> np.ndarray:
        e = np.radians(self.view_deg)
        return np.array([0.0, -np.cos(e), np.sin(e)])

    def pixels(self):
        """Per pixel: ``(uv centre (P, 2), uv covariance (2, 2), plane point (P, 3))``.

        Image row ``r`` runs from far (top) to near; a pixel is ``2 / width`` wide on the
        plane along x and ``2 / width`` along y (the orthographic foreshortening of the
        image's ``2 sin(e) / height`` pixel height).

        Returns
        -------
        uv : numpy.ndarray, shape (P, 2)
            Footprint centre of each pixel in uv, rows far to near.
        cov : numpy.ndarray, shape (2, 2)
            The footprint covariance in uv^2 (the same for every pixel).
        p : numpy.ndarray, shape (P, 3)
            The plane point seen by each pixel.
        """
        w, h = self.width, self.height
        x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
        y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
        X, Y = np.meshgrid(x, y)
        p = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], -1)
        uv = (p[:, :2] + 1.0) / 2.0
        su = PIXEL_SIGMA * (1.0 / w)                   # pixel (2/w on the plane) in uv (1/2 per unit)
        sv = PIXEL_SIGMA * (1.0 / h)
        return uv, np.diag([su * su, sv * sv]), p

    def lighting(self, p):
        """Local light directions ``(P, 3)`` and ``I / r^2`` ``(P,)`` at plane points.

        Parameters
        ----------
        p : array-like, shape (P, 3)
            Points on the plane (z = 0).

        Returns
        -------
        wi : numpy.ndarray, shape (P, 3)
            Unit directions toward the light.
        E : numpy.ndarray, shape (P,)
            ``intensity / r^2``.
        """
        d = np.asarray(self.light, dtype=np.float64) - p
        r2 = np.sum(d * d, -1)
        return d / np.sqrt(r2)[:, None], self.intensity / r2


def render_pbrdf(ms, scene: PlaneScene, exact: bool = True, fresnel=None, g2: str = "correlated") -> np.ndarray:
    """Image ``(height, width, 3)`` of ``scene`` with the P-BRDF of each pixel's footprint
    (:func:`~microfacet.glints.pbrdf.eval_cos_footprints`, Chermain et al. 2019, Eq. 7).

    Parameters
    ----------
    ms : Microsurface
        The normal map's lobe mixture.
    scene : PlaneScene
        Camera, plane and light.
    exact : bool
        Exact patch masking or the MIP approximation.
    fresnel : Fresnel, optional
        Microfacet Fresnel term (default ideal mirrors).
    g2 : str
        Masking-shadowing form (:data:`~microfacet.glints.pbrdf.G2_MODELS`).

    Returns
    -------
    (height, width, 3) ndarray
        Linear radiance, row 0 the far edge.

    Examples
    --------
    >>> ms = Microsurface.from_normal_map(scratched_normal_map(16, scratches=4, seed=1))
    >>> image = render_pbrdf(ms, PlaneScene(width=8))
    >>> image.shape, bool(image.max() > 0)
    ((6, 8, 3), True)
    """
    uv, cov, p = scene.pixels()
    wi, e = scene.lighting(p)
    f = eval_cos_footprints(ms, uv, cov, wi, scene.wo, fresnel=fresnel, exact=exact, g2=g2)
    return (e[:, None] * f).reshape(scene.height, scene.width, 3)


_GOLDEN, _MIX1, _MIX2 = 0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finalizer of ``uint64`` counters (Steele, Lea and Flood 2014)."""
    with np.errstate(over="ignore"):
        z = x + np.uint64(_GOLDEN)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(_MIX1)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(_MIX2)
        return z ^ (z >> np.uint64(31))


def _seed_key(seed: int) -> np.uint64:
    return _splitmix64(np.array([seed], np.uint64))[0]


def _footprint_normals(pixels: np.ndarray, spp: int, seed: int) -> np.ndarray:
    """Standard normal pairs ``(len(pixels), spp, 2)`` of samples ``s`` of pixels ``p``:
    Box-Muller of two SplitMix64 uniforms, of the counter ``(p << 32 | s) ^ mix(seed)`` and
    of its hash (counter based, so the compiled renderer draws the same numbers in any
    order)."""
    c = (pixels.astype(np.uint64)[:, None] << np.uint64(32)) | np.arange(spp, dtype=np.uint64)[None, :]
    key = _seed_key(seed)
    a = _splitmix64(c ^ key)
    b = _splitmix64(a)
    u1 = (a >> np.uint64(11)).astype(np.float64) * 2.0**-53
    u2 = (b >> np.uint64(11)).astype(np.float64) * 2.0**-53
    r = np.sqrt(-2.0 * np.log1p(-u1))
    return np.stack([r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2)], -1)


def render_naive(ms, scene: PlaneScene, spp: int, seed: int = 0, fresnel=None,
                 batch: int = 1 << 19, backend: str = "auto") -> np.ndarray:
    """Image of ``scene`` by naive sampling: ``spp`` positions of each pixel's footprint on
    the interpolated normal map (``u = c + L z``, ``L L^T`` the footprint covariance, ``z``
    of :func:`_footprint_normals`), each shaded as a ``sigma_eps`` Beckmann near-mirror
    with the map's slope there as mean slope (:class:`~microfacet.MicrofacetBRDF`,
    height-correlated Smith ``G`` of the sheared lobe, Eq. 3.3).

    ``backend``: ``"numpy"`` (the reference: ``MicrofacetBRDF.eval_cos`` of a Beckmann with
    array mean slopes, ``batch`` samples at a time), ``"numba"`` (one compiled pass,
    :func:`_naive_sums`, the same positions and formulas; tested against the reference)
    or ``"auto"`` (numba when available). The Fresnel term depends on the pixel's half
    vector only (one light direction per pixel) and is applied per pixel.

    Parameters
    ----------
    ms : Microsurface
        The normal map (its ``slopes`` and ``sigma_eps``).
    scene : PlaneScene
        Camera, plane and light.
    spp : int
        Samples per pixel.
    seed : int
        Seed of the counter-based samples.
    fresnel : Fresnel, optional
        Microfacet Fresnel term (default ideal mirrors).
    batch : int
        Samples per NumPy batch.
    backend : str
        ``"auto"``, ``"numpy"`` or ``"numba"``.

    Returns
    -------
    (height, width, 3) ndarray
        Linear radiance, an unbiased estimate of the image :func:`render_pbrdf` approximates.

    Examples
    --------
    The backends draw the same samples:

    >>> ms = Microsurface.from_normal_map(scratched_normal_map(16, scratches=4, seed=1))
    >>> a = render_naive(ms, PlaneScene(width=8), spp=4, backend="numpy")
    >>> b = render_naive(ms, PlaneScene(width=8), spp=4, backend="auto")
    >>> a.shape, bool(np.allclose(a, b))
    ((6, 8, 3), True)
    """
    compiled = backend_.choose(backend, _naive_sums is not None) == backend_.NUMBA
    if int(spp) != spp or spp < 1:
        raise ValueError(f"spp must be a positive integer, got {spp!r}")
    spp = int(spp)
    uv, cov, p = scene.pixels()
    wi, e = scene.lighting(p)
    L = np.linalg.cholesky(cov)
    alpha = np.sqrt(2.0) * ms.sigma_eps
    wo = scene.wo
    P = uv.shape[0]
    if compiled:
        s = _naive_sums(np.ascontiguousarray(ms.slopes), uv, L, wi, wo, alpha, spp, _seed_key(seed))
        F = MicrofacetBRDF(Beckmann(alpha=alpha), fresnel=fresnel).fresnel
        acc = F(dot(wo, half_vector(wi, wo))) * s[:, None]
    else:
        acc = np.zeros((P, 3))
        rows = max(1, batch // spp)
        for s0 in range(0, P, rows):
            sl = slice(s0, min(P, s0 + rows))
            z = _footprint_normals(np.arange(sl.start, sl.stop), spp, seed)
            slopes = ms.slopes_at(uv[sl, None, :] + z @ L.T)
            lobe = MicrofacetBRDF(Beckmann(alpha=alpha, mean_slope=slopes), fresnel=fresnel)
            f = lobe.eval_cos(np.broadcast_to(wi[sl, None, :], slopes.shape[:-1] + (3,)), wo)
            acc[sl] = f.mean(1)
    return (e[:, None] * acc).reshape(scene.height, scene.width, 3)


# --------------------------------------------------------- compiled naive renderer
from .. import kernels as _kernels  # noqa: E402

if _kernels.AVAILABLE:
    import math

    import numba

    from .microsurface import bilinear_slopes

    _U53 = 2.0**-53
    _SQRT_PI = math.sqrt(math.pi)

    @numba.njit(cache=True, inline="always")
    def _mix(x):  # pragma: no cover - compiled
        """:func:`_splitmix64` of one ``uint64``."""
        z = x + numba.uint64(_GOLDEN)
        z = (z ^ (z >> numba.uint64(30))) * numba.uint64(_MIX1)
        z = (z ^ (z >> numba.uint64(27))) * numba.uint64(_MIX2)
        return z ^ (z >> numba.uint64(31))

    @numba.njit(cache=True, inline="always")
    def _beckmann_lambda(v):  # pragma: no cover - compiled
        """Beckmann ``Lambda(v) = (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2`` (Table 2.III,
        ``v = cot theta``; ``inf`` for ``v <= 0``, 0 where ``exp(-v^2)`` underflows)."""
        if v <= 0.0:
            return np.inf
        if v > 27.0:
            return 0.0
        return max(0.5 * (math.exp(-v * v) / (v * _SQRT_PI) - math.erfc(v)), 0.0)

    @numba.njit(cache=True, parallel=True, nogil=True)
    def _naive_sums(slopes, uv, L, wi, wo, alpha, spp, key):  # pragma: no cover - compiled
        """Per pixel: the mean over ``spp`` footprint positions (:func:`_footprint_normals`)
        of the sheared Beckmann near-mirror's ``D G / (4 z_o)`` (Eq. 2.11, 3.2-3.3:
        ``D = exp(-|h~ - m|^2 / alpha^2) / (pi alpha^2 z_h^4)``, ``G = (z_o / c_o) /
        (1 + Lambda_i + Lambda_o)``, ``Lambda(v)`` at ``v = c / (alpha |k_xy|)``), ``m`` the
        bilinearly interpolated slope of ``slopes (H, W, 2)`` at the position; what
        :class:`~microfacet.MicrofacetBRDF` gives, one pass, no temporaries."""
        P = uv.shape[0]
        hgt, wid = slopes.shape[0], slopes.shape[1]
        out = np.zeros(P)
        a2 = alpha * alpha
        for p in numba.prange(P):
            hx, hy, hz = wi[p, 0] + wo[0], wi[p, 1] + wo[1], wi[p, 2] + wo[2]
            n = math.sqrt(hx * hx + hy * hy + hz * hz)
            if n <= 0.0:
                continue
            hx, hy, hz = hx / n, hy / n, hz / n
            oh = wo[0] * hx + wo[1] * hy + wo[2] * hz
            if not (wi[p, 2] > 0.0 and wo[2] > 0.0 and oh > 0.0 and hz > 0.0):
                continue
            xh, yh = -hx / hz, -hy / hz
            inv4 = 1.0 / (math.pi * a2 * hz * hz * hz * hz)
            ri = alpha * math.sqrt(wi[p, 0] * wi[p, 0] + wi[p, 1] * wi[p, 1])
            ro = alpha * math.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
            acc = 0.0
            for s in range(spp):
                a = _mix((numba.uint64(p) << numba.uint64(32) | numba.uint64(s)) ^ key)
                b = _mix(a)
                u1 = numba.float64(a >> numba.uint64(11)) * _U53
                u2 = numba.float64(b >> numba.uint64(11)) * _U53
                r = math.sqrt(-2.0 * math.log1p(-u1))
                z1, z2 = r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)
                mx, my = bilinear_slopes(slopes, (uv[p, 0] + L[0, 0] * z1 + L[0, 1] * z2) * wid - 0.5,
                                          (uv[p, 1] + L[1, 0] * z1 + L[1, 1] * z2) * hgt - 0.5)
                co = wo[2] - wo[0] * mx - wo[1] * my
                ci = wi[p, 2] - wi[p, 0] * mx - wi[p, 1] * my
                if co <= 0.0 or ci <= 0.0:
                    continue            # Lambda_i or Lambda_o infinite: G = 0
                gx, gy = xh - mx, yh - my
                d = math.exp(-(gx * gx + gy * gy) / a2) * inv4
                lam_i = _beckmann_lambda(ci / ri) if ri > 0.0 else 0.0
                lam_o = _beckmann_lambda(co / ro) if ro > 0.0 else 0.0
                acc += d / (4.0 * co * (1.0 + lam_i + lam_o))
            out[p] = acc / spp
        return out
else:  # pragma: no cover - without numba
    _naive_sums = None


def relative_error(image, reference) -> float:
    """Relative L2 error ``||image - ref|| / ||ref||`` over pixels (first channel).

    Parameters
    ----------
    image, reference : (H, W, C) array_like
        Images of the same shape.

    Returns
    -------
    float
        The relative error.

    Examples
    --------
    >>> relative_error(np.full((2, 2, 3), 1.1), np.ones((2, 2, 3)))
    0.10000000000000009
    """
    a, b = np.asarray(image)[..., 0], np.asarray(reference)[..., 0]
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def _timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def _normal_preview(normals: np.ndarray) -> np.ndarray:
    """Linear RGB whose sRGB PNG shows the usual ``(n + 1) / 2`` normal-map colours."""
    v = np.clip((normals + 1.0) / 2.0, 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)   # inverse sRGB


def _exposure(reference) -> float:
    top = float(np.percentile(np.asarray(reference)[..., 0], 99.5))
    return float(np.log2(1.0 / top)) if top > 0 else 0.0


def _errors_against_noisy_reference(images, a, b):
    """Relative L2 errors ``||x - truth|| / ||truth||`` (first channel) of ``images``
    against the mean ``R = (a + b) / 2`` of two independent naive renders, with the
    reference's own noise removed: ``E||x - R||^2 = ||x - truth||^2 + ||a - b||^2 / 4``
    for ``x`` independent of ``R``. Returns ``(errors, reference noise)``."""
    ref = 0.5 * (np.asarray(a)[..., 0] + np.asarray(b)[..., 0])
    noise2 = float(np.sum((np.asarray(a)[..., 0] - np.asarray(b)[..., 0]) ** 2)) / 4.0
    norm = max(float(np.linalg.norm(ref)), 1e-300)
    errs = [float(np.sqrt(max(float(np.sum((np.asarray(x)[..., 0] - ref) ** 2)) - noise2, 0.0))) / norm
            for x in images]
    return errs, float(np.sqrt(noise2)) / norm


def glints_section(out, progress=None, map_size: int = 512, width: int = 256,
                   reference_spp: int = 256, naive_spp: int = 16, seed: int = 0) -> str:
    """The demo's glints section (Chermain et al. 2019) under ``out/glints/``; returns HTML.

    A procedural scratched normal map (:func:`scratched_normal_map`) is turned into a
    Beckmann mixture; a plane under a point light (``width`` pixels wide, ``map_size /
    width`` texels per pixel) is rendered with the exact and the approximate P-BRDF and
    by naive per-pixel sampling (``naive_spp``, and a reference of two independent
    ``reference_spp / 2`` renders whose own noise is removed from the errors, see
    :func:`_errors_against_noisy_reference`); the output is deterministic, so timings are
    left to ``benchmarks/bench_glints_render.py``. A white-furnace table shows that both
    P-BRDFs conserve energy and that the approximation darkens. ``progress(n)`` is
    called as steps complete.

    Parameters
    ----------
    out : str or os.PathLike
        The demo's folder (``out/glints/`` is written).
    progress : callable, optional
        Called with the number of steps done.
    map_size : int
        The scratched map's size in texels.
    width : int
        The images' width in pixels.
    reference_spp, naive_spp : int
        Samples per pixel of the naive reference and of the naive image.
    seed : int
        Seed of the map and of the samples.

    Returns
    -------
    str
        The HTML ``<section id="glints">``.

    Examples
    --------
    It takes seconds even for tiny images (the white-furnace integrals):

    >>> html = glints_section("demo", map_size=8, width=4, reference_spp=2, naive_spp=1)   # doctest: +SKIP
    >>> html.startswith('<section id="glints">')                                          # doctest: +SKIP
    True
    """
    from html import escape

    from ..io import html_grid, write_exr, write_png
    tick = progress if progress is not None else (lambda n=1: None)
    folder = Path(out) / "glints"
    folder.mkdir(parents=True, exist_ok=True)
    normals = scratched_normal_map(map_size, scratches=max(4, int(160 * (map_size / 512) ** 2)), seed=seed)
    write_png(folder / "normal_map.png", _normal_preview(normals))
    ms = Microsurface.from_normal_map(normals)
    tick(1)
    scene = PlaneScene(width=width, view_deg=50.0, light=(0.0, 0.35, 0.9))
    half = max(1, reference_spp // 2)
    ref_a = render_naive(ms, scene, half, seed=seed + 1)
    ref_b = render_naive(ms, scene, half, seed=seed + 3)
    ref = 0.5 * (ref_a + ref_b)
    tick(1)
    exact = render_pbrdf(ms, scene, True)
    approx = render_pbrdf(ms, scene, False)
    naive = render_naive(ms, scene, naive_spp, seed=seed + 2)
    (e_exact, e_approx, e_naive), ref_noise = _errors_against_noisy_reference((exact, approx, naive), ref_a, ref_b)
    tick(1)
    ev = _exposure(ref)
    size = f"{scene.width}×{scene.height} px"
    cells = []
    for stem, img, label in (
            ("pbrdf_exact", exact, f"P-BRDF, exact patch masking: rel. L2 error {e_exact:.3f}"),
            ("pbrdf_approx", approx, f"P-BRDF, MIP-lobe masking: rel. L2 error {e_approx:.3f}"),
            ("naive", naive, f"naive, {naive_spp} spp: rel. L2 error {e_naive:.3f}"),
            ("naive_reference", ref, f"naive reference, {2 * half} spp (its own noise {ref_noise:.3f})")):
        write_exr(folder / f"{stem}.exr", img.astype(np.float32))
        write_png(folder / f"{stem}.png", img, ev)
        cells.append((f"glints/{stem}.png", f"{label}; {size}"))
    # white furnace: a small and a large footprint, exact vs approximate
    rows = []
    thetas = (0, 30, 60, 75, 85, 89)
    for sd in (1.0, 3.0):
        cov = np.eye(2) * (sd / map_size) ** 2
        for exact_flag in (True, False):
            p = ms.pbrdf((0.37, 0.61), cov, exact=exact_flag)
            vals = [p.albedo(np.array([np.sin(np.radians(t)), 0.0, np.cos(np.radians(t))]), order=8)
                    for t in thetas]
            rows.append((f"footprint sd {sd:g} texels ({len(p.weights)} lobes), "
                         f"{'exact' if exact_flag else 'MIP-lobe masking'}", vals))
    tick(1)
    head = "".join(f"<th>&theta;<sub>o</sub> = {t}&deg;</th>" for t in thetas)
    body = "".join(f"<tr><th class='row'>{escape(label)}</th>" + "".join(f"<td>{v:.4f}</td>" for v in vals)
                   + "</tr>" for label, vals in rows)
    return ('<section id="glints"><h2>Glints: the P-BRDF of a scratched normal map '
            '(Chermain, Claux, Mérillou 2019)</h2>'
            f'<p>A procedural {map_size}&times;{map_size} scratched normal map, one Beckmann lobe per texel '
            f'({ms.n_lobes} lobes), on a plane seen at 50&deg; under a point light, rendered at {size} '
            f'({map_size / scene.width:g} texels per pixel, shown at native size). Each pixel evaluates the '
            'P-BRDF of its Gaussian footprint (Eq. 7: P-NDF, exact patch masking Eq. 10-16 and projected area '
            'Eq. 17, or the merged MIP lobe&rsquo;s masking of Sec. 4.2.2); naive rendering samples positions '
            'of the interpolated normal map, each a near-mirror Beckmann lobe (&sigma;<sub>&epsilon;</sub> = '
            '0.01). The numbers under the images are relative L2 errors ||image &minus; truth|| / ||truth|| '
            'over the image, estimated against the naive reference (two independent renders; their '
            'difference measures the reference&rsquo;s own noise, which is removed). The P-BRDF errors are '
            'its bias (the lobe mixture&rsquo;s approximation of the map); the naive error is its noise at '
            f'{naive_spp} samples per pixel. Times and matched-error speed-ups: '
            '<code>benchmarks/bench_glints_render.py</code>.</p>'
            + html_grid([("plane, point light", cells)])
            + '<figure><img src="glints/normal_map.png" alt="scratched normal map" width="256">'
              f'<figcaption>The procedural normal map, {map_size}&times;{map_size} texels shown at 256 px '
              '((n + 1) / 2 colours).</figcaption></figure>'
            + '<h3>White furnace, &int; f cos&theta;<sub>i</sub> d&omega;<sub>i</sub></h3>'
              '<p>The reflected fraction of a white furnace (Fresnel 1) for a view at &theta;<sub>o</sub>, '
              'by Gauss-Hermite quadrature of each lobe: &le; 1 means energy is conserved (= 1 at normal '
              'view up to light reflected below the horizon). Both models normalize the P-NDF exactly '
              '(Eq. 11); the single merged lobe of the approximation is rougher than the lobes it '
              'replaces, so its masking darkens at oblique views.</p>'
            + f'<table class="grid"><tr><th></th>{head}</tr>{body}</table></section>')


def render_cli(npz, out_png, light=(0.0, 0.35, 0.9), distance: float = 1.2, width: int = 256,
               view_deg: float = 50.0, exact: bool = True, exposure: float | None = None):
    """``microfacet glints render``: a plane with the microsurface ``npz`` under a point
    light at ``distance`` from the plane's centre in direction ``light``; writes the PNG
    (exposure: the 99.5th percentile maps to 1 unless given). Returns
    ``(png_path, linear image, seconds)``.

    Parameters
    ----------
    npz : str or os.PathLike
        A microsurface file (``microfacet glints build``, :meth:`Microsurface.save`).
    out_png : str or os.PathLike
        The picture to write (its folder is created).
    light : (3,) sequence
        Direction of the light from the plane's centre (``z > 0``).
    distance : float
        The light's distance from the plane's centre.
    width : int
        Image width in pixels.
    view_deg : float
        Camera elevation, degrees.
    exact : bool
        Exact patch masking or the MIP approximation.
    exposure : float, optional
        Exposure (stops) of the PNG.

    Returns
    -------
    png_path : Path
    image : (height, width, 3) ndarray
        Linear radiance.
    seconds : float
        The render's wall time.

    Raises
    ------
    ValueError
        ``light`` or ``distance`` out of range.

    Examples
    --------
    >>> ms = Microsurface.from_normal_map(scratched_normal_map(16, scratches=4, seed=1))
    >>> png, image, seconds = render_cli(ms.save("scratches.npz"), "glints.png", width=8)
    >>> png.name, image.shape
    ('glints.png', (6, 8, 3))
    """
    from ..io import write_png
    lt = np.asarray(light, dtype=np.float64)
    if lt.shape != (3,) or not np.all(np.isfinite(lt)) or lt[2] <= 0:
        raise ValueError(f"--light must be a direction x,y,z with z > 0, got {light!r}")
    if not (np.isfinite(distance) and distance > 0):
        raise ValueError(f"--distance must be > 0, got {distance!r}")
    ms = Microsurface.load(npz)
    scene = PlaneScene(width=int(width), view_deg=float(view_deg),
                       light=tuple(distance * lt / np.linalg.norm(lt)))
    img, seconds = _timed(render_pbrdf, ms, scene, exact)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    ev = _exposure(img) if exposure is None else float(exposure)
    return write_png(out_png, img, ev), img, seconds
