"""``mf_glints``: the patch BRDF of a glint microsurface (``microfacet glints``) as a
Mitsuba 3 BSDF plugin (Chermain, Claux, Mérillou 2019, Eq. 7-17; Sec. 5 sampling).

Per shading point the footprint ``k_P`` (a Gaussian over uv) gathers the lobes of
:func:`microfacet.glints.pbrdf.footprint_lobes` (the seeds within ``cutoff`` standard
deviations of ``Sigma_P + sigma_k^2 I`` per axis, weights ``W_i = exp(-q_i / 2)``,
normalized) in one Dr.Jit loop over that window, summing the terms of the library's
compiled ``_footprint_sums``: ``D_P(h)`` (Eq. 9), ``A_P`` and ``V_P`` of both directions
(Eq. 13-17, ``E[s+]`` of each lobe). ``exact=false`` replaces ``A_P`` by the merged lobe of
the MIP level matching the footprint (Sec. 4.2.2, :func:`microfacet.glints.pbrdf._merged_area`).
``eval = F(o.h) D_P G2 / (4 A_P(o))`` (:meth:`PatchBRDF.eval_cos`), ``pdf = D_P z_h / (4 o.h)``;
``sample`` picks a lobe with probability ``W_i / sum W`` (``sample1``), then a normal of its
slope distribution (``sample2``, the Beckmann ``erfinv`` map of ``mf_microfacet``).
The sums run in double precision (footprint weights of far lobes and sharp lobes'
exponents lose digits in float32).

Footprint: ``Sigma_P = PIXEL_SIGMA^2 (a a^T + b b^T)`` with ``a, b`` the ray differentials
``si.duv_dx``, ``si.duv_dy`` (times ``uv_scale``) where set, else the ``footprint``
parameter (a pixel width in texels of the normal map, along u and v): the Gaussian pixel
filter of ``microfacet glints render`` (:data:`microfacet.glints.figures.PIXEL_SIGMA`).
A footprint whose window would hold more than ``max_lobes`` lobes is shrunk (its
covariance scaled) until it fits: the plugin then renders the P-BRDF of that smaller
footprint (documented limit; the library has none).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MicrofacetError
from ..glints import Microsurface
from ..glints.figures import PIXEL_SIGMA
from ..glints.microsurface import FWHM_PER_SIGMA
from ..glints.pbrdf import G2_MODELS
from . import properties
from .bsdf import FresnelParams, fresnel_term, glossy_flags, glossy_sample, half_vector, read_fresnel, reflecting
from .registry import variant_class
from .slopes import BECKMANN, Lobe, ratio
from .tabulated import Table

__all__ = ["PLUGIN", "bsdf_class", "GlintTables", "GlintsBSDF", "GlintParams", "read_glint_params",
           "footprint_covariance", "Footprint", "SeedGrid", "footprint_sums", "merged_lobe", "merged_area", "g2_over_ao", "glint_eval_pdf",
           "pick_lobe", "lobe_of"]

PLUGIN = "mf_glints"
_ZIP_MAGIC = b"PK\x03\x04"
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_INV_SQRT2 = 1.0 / math.sqrt(2.0)
_FWHM = float(FWHM_PER_SIGMA)


def _load(props, name: str):
    """The :class:`~microfacet.glints.Microsurface` of the ``.npz`` named by ``name``, or a
    one-line error naming the parameter and file (an EXR, e.g. a LEADR pyramid, is named)."""
    if name not in props or props.type(name) != mi.Properties.Type.String:
        raise properties.parameter_error(name, "is required: the .npz written by `microfacet glints`", PLUGIN)
    path = str(mi.file_resolver().resolve(props[name]))
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise properties.parameter_error(name, f"cannot read {path!r} ({e.strerror or e})", PLUGIN) from None
    if head == b"v/1\x01":
        raise properties.parameter_error(name, f"{path!r} is an OpenEXR image (a LEADR pyramid of `microfacet bake`? "
                                 "use mf_leadr), not a glint microsurface .npz", PLUGIN)
    try:
        return Microsurface.load(path)
    except MicrofacetError as e:
        raise properties.parameter_error(name, f"is not usable: {e}", PLUGIN) from None


class GlintTables:
    """A microsurface's lobes as Dr.Jit tables.

    Central moments ``(mx, my, sxx, syy, sxy)`` of level 0 (float64, from the library's raw
    moments) and, for ``exact=false``, the raw moments of every MIP level (one flat table with
    per-level sizes and offsets).

    Parameters
    ----------
    ms : microfacet.glints.Microsurface
        The microsurface.
    mip : bool
        Upload the MIP levels too.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.glints import GlintTables
    >>> ms = mf.glints.Microsurface.from_slopes(0.3 * np.random.default_rng(2).normal(size=(8, 8, 2)), sigma_eps=0.1)
    >>> tables = GlintTables(ms, mip=True)
    >>> tables.grid, tables.levels > 1
    (SeedGrid(nx=8, ny=8, cutoff=3.0), True)
    """

    def __init__(self, ms, mip: bool):
        self.ny, self.nx = ms.grid
        self.height, self.width = ms.resolution
        self.cutoff = float(ms.cutoff)
        self.grid = SeedGrid(self.nx, self.ny, self.cutoff)
        E = np.asarray(ms.lobe_moments, np.float64)
        mx, my = E[:, 0], E[:, 1]
        central = np.stack([mx, my, E[:, 2] - mx * mx, E[:, 3] - my * my, E[:, 4] - mx * my], -1)
        self.central = Table(central, "float64")
        self.levels = len(ms.mip) if mip else 0
        if mip:
            levels = [np.asarray(ms.mip[k], np.float64) for k in range(self.levels)]
            offsets = np.cumsum([0] + [lv.shape[0] * lv.shape[1] for lv in levels])[:-1]
            self.mip = Table(np.concatenate([lv.ravel() for lv in levels]), "float64")
            self.mip_nx = Table([lv.shape[1] for lv in levels], "float64")
            self.mip_ny = Table([lv.shape[0] for lv in levels], "float64")
            self.mip_offset = Table(offsets, "float64")


class Footprint(NamedTuple):
    """A pixel footprint in uv (double precision per lane).

    Centre ``(cu, cv)`` wrapped into the unit square and covariance ``(uu, vv, uv)``.

    Attributes
    ----------
    cu, cv : Float64
        Footprint centre in uv, wrapped into the unit square.
    cov : (Float64, Float64, Float64)
        Covariance ``(uu, vv, uv)`` in uv^2.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import Footprint, footprint_covariance
    >>> fp = footprint_covariance(params, si)
    >>> isinstance(fp, Footprint), fp.cu, fp.cov               # PIXEL_SIGMA^2 (2 / 8)^2 on the diagonal
    (True, 0.5, (0.015625, 0.015625, 0.0))
    """
    cu: object
    cv: object
    cov: tuple


class SeedGrid(NamedTuple):
    """The ``nx x ny`` lobe seeds of a level and the window ``cutoff`` in standard deviations.

    Per lane where a MIP level is chosen per lane.

    Attributes
    ----------
    nx, ny : Int or int
        Lobe seeds along u and v of the level (per lane).
    cutoff : float
        The window's half-width in standard deviations.

    Examples
    --------
    >>> from microfacet.mitsuba.glints import SeedGrid
    >>> SeedGrid(8, 8, 3.0).cutoff
    3.0
    """
    nx: object
    ny: object
    cutoff: float


def _window(fp: Footprint, grid: SeedGrid):
    """Seed window (first index and count per axis) and inverse covariance ``(iuu, ivv,
    iuv)`` of the footprint plus the kernel of the seeds (the window and weights of
    :func:`microfacet.glints.pbrdf.footprint_lobes`)."""
    cu, cv, (sxx, syy, sxy) = fp
    nx, ny, cutoff = grid
    kx, ky = (1.0 / nx / _FWHM) ** 2, (1.0 / ny / _FWHM) ** 2
    sxx, syy = sxx + kx, syy + ky
    det = sxx * syy - sxy * sxy
    rx, ry = cutoff * dr.sqrt(sxx), cutoff * dr.sqrt(syy)
    x0, y0 = dr.ceil((cu - rx) * nx - 0.5), dr.ceil((cv - ry) * ny - 0.5)
    cx = dr.maximum(dr.floor((cu + rx) * nx - 0.5) - x0 + 1.0, 0.0)
    cy = dr.maximum(dr.floor((cv + ry) * ny - 0.5) - y0 + 1.0, 0.0)
    return x0, y0, cx, cy, syy / det, sxx / det, -sxy / det


def _walk(fp: Footprint, grid: SeedGrid, state, body):
    """``state = body(index, W, state)`` over the window's seeds (row-major, index wrapped
    into ``nx x ny``; ``W = exp(-q / 2)`` unnormalized), one ``dr.while_loop``."""
    cu, cv, _ = fp
    nx, ny, _ = grid
    x0, y0, cx, cy, iuu, ivv, iuv = _window(fp, grid)
    n = cx * cy

    def step(j, s):
        r = dr.floor(j / cx)
        ix, iy = x0 + (j - r * cx), y0 + r
        du, dv = (ix + 0.5) / nx - cu, (iy + 0.5) / ny - cv
        w = dr.exp(-0.5 * (iuu * du * du + ivv * dv * dv + 2.0 * iuv * du * dv))
        index = (iy - ny * dr.floor(iy / ny)) * nx + (ix - nx * dr.floor(ix / nx))
        return j + 1.0, body(index, w, s)

    j = 0.0 * n
    _, state = dr.while_loop(state=(j, state), cond=lambda j, s: j < n, body=lambda j, s: step(j, s))
    return state


def _area(c, var):
    """``E[s+]`` of ``s ~ N(c, var)`` (:func:`microfacet.glints.pbrdf.lobe_projected_area`):
    ``c Phi(c / sigma) + sigma phi(c / sigma)``, ``max(c, 0)`` at ``sigma = 0``."""
    sg = dr.sqrt(dr.maximum(var, 0.0))
    t = ratio(c, sg, sg > 0)
    area = c * 0.5 * (1.0 + dr.erf(t * _INV_SQRT2)) + sg * _INV_SQRT_2PI * dr.exp(-0.5 * t * t)
    return dr.select(sg > 0, area, dr.maximum(c, 0.0))


def _lobe_areas(k, mx, my, sxx, syy, sxy):
    """``(max(c, 0), E[s+])`` of one lobe toward ``k`` (Eq. 13, 17), ``c = z - x mx - y my``."""
    x, y, z = k
    c = z - x * mx - y * my
    return dr.maximum(c, 0.0), _area(c, x * x * sxx + 2.0 * x * y * sxy + y * y * syy)


@dataclass(frozen=True)
class GlintParams:
    """All parameters of ``mf_glints`` (:func:`read_glint_params`).

    The microsurface's :class:`GlintTables`, the area model (``exact``), the ``g2`` model, the
    map's repetition ``uv_scale``, the fallback ``footprint`` (texels), the ``max_lobes``
    bound and the Fresnel term (:func:`.bsdf.read_fresnel`).

    Attributes
    ----------
    filename : str
        The microsurface ``.npz``.
    tables : GlintTables
        The microsurface's lobes and levels.
    exact : bool
        Exact patch areas (else the merged lobe).
    g2 : str
        ``correlated`` or ``separable``.
    uv_scale : float
        Repetitions of the map over the uv square.
    footprint : float
        Fallback pixel width in texels (without ray differentials).
    max_lobes : int
        Most lobes gathered per shading point.
    fresnel : FresnelParams
        The Fresnel term.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import GlintParams
    >>> isinstance(params, GlintParams), params.exact, params.g2, params.footprint, params.max_lobes
    (True, True, 'correlated', 2.0, 1024)
    """
    filename: str
    tables: GlintTables
    exact: bool
    g2: str
    uv_scale: float
    footprint: float
    max_lobes: int
    fresnel: FresnelParams


def read_glint_params(props) -> GlintParams:
    """All parameters of ``mf_glints`` (class docstring of :class:`GlintsBSDF`), checked.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.

    Returns
    -------
    GlintParams

    Raises
    ------
    PluginParameterError
        Naming the parameter (and the file) that is unusable.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> read_glint_params(props).tables.grid.nx
    8
    >>> props["max_lobes"] = 4
    >>> read_glint_params(props)
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_glints: parameter 'max_lobes' must be a finite number >= 16, got 4
    """
    ms = _load(props, "filename")
    exact = properties.flag(props, "exact", True, PLUGIN)
    g2 = properties.choice(props, "g2", "correlated", G2_MODELS, PLUGIN)
    uv_scale = float(props.get("uv_scale", 1.0))
    footprint = float(props.get("footprint", 1.0))
    max_lobes = int(props.get("max_lobes", 1024))
    for name, v, ok, what in (("uv_scale", uv_scale, uv_scale > 0, "> 0"),
                              ("footprint", footprint, footprint >= 0, ">= 0"),
                              ("max_lobes", max_lobes, max_lobes >= 16, ">= 16")):
        if not (math.isfinite(v) and ok):
            raise properties.parameter_error(name, f"must be a finite number {what}, got {v!r}", PLUGIN)
    return GlintParams(props["filename"], GlintTables(ms, mip=not exact), exact, g2, uv_scale, footprint,
                       max_lobes, read_fresnel(props, PLUGIN))


def _footprint_scale(params: GlintParams, suu, svv):
    """The factor on the footprint covariance that keeps at most ``L = floor(sqrt(max_lobes))``
    seeds per axis in its window: ``sd_total <= (L - 1) / (2 cutoff n)``."""
    t = params.tables
    side = float(math.floor(math.sqrt(params.max_lobes)) - 1) / (2.0 * t.cutoff)
    scale = 1.0
    for s, n in ((suu, t.nx), (svv, t.ny)):
        cap = (side / n) ** 2 - (1.0 / n / _FWHM) ** 2
        scale = dr.minimum(scale, dr.select(s > cap, cap / dr.maximum(s, 1e-300), 1.0))
    return scale


def footprint_covariance(params: GlintParams, si):
    """The :class:`Footprint` at ``si`` (module docstring), shrunk to fit ``max_lobes``.

    ``Sigma_P = PIXEL_SIGMA^2 (a a^T + b b^T)`` with ``a, b`` the ray differentials times
    ``uv_scale``, else ``footprint`` texels along u and v.

    Parameters
    ----------
    params : GlintParams
        The plugin's parameters.
    si : mi.SurfaceInteraction3f
        The shading point.

    Returns
    -------
    Footprint

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.glints.figures import PIXEL_SIGMA
    >>> from microfacet.mitsuba.glints import footprint_covariance
    >>> fp = footprint_covariance(params, si)
    >>> fp.cov[0] == PIXEL_SIGMA**2 * (2.0 / 8) ** 2
    True
    """
    F64, t = mi.Float64, params.tables
    a, b = si.duv_dx * params.uv_scale, si.duv_dy * params.uv_scale
    has = (dr.squared_norm(a) + dr.squared_norm(b)) > 0
    ax, ay = F64(dr.select(has, a.x, params.footprint / t.width)), F64(dr.select(has, a.y, 0.0))
    bx, by = F64(dr.select(has, b.x, 0.0)), F64(dr.select(has, b.y, params.footprint / t.height))
    s2 = PIXEL_SIGMA * PIXEL_SIGMA
    suu, svv, suv = s2 * (ax * ax + bx * bx), s2 * (ay * ay + by * by), s2 * (ax * ay + bx * by)
    scale = _footprint_scale(params, suu, svv)
    u, v = F64(si.uv.x) * params.uv_scale, F64(si.uv.y) * params.uv_scale
    return Footprint(u - dr.floor(u), v - dr.floor(v), (suu * scale, svv * scale, suv * scale))


def _lobe_terms(tables: GlintTables, index, xh, yh, ki, ko):
    """``(P_i(h~), A_i(i), V_i(i), A_i(o), V_i(o))`` of lobe ``index``: its Gaussian slope
    density at ``h~ = (xh, yh)`` and its areas toward both directions (Eq. 9, 13, 17)."""
    mx, my, sxx, syy, sxy = (tables.central[5 * index + c] for c in range(5))
    det = sxx * syy - sxy * sxy
    gx, gy = xh - mx, yh - my
    q = (syy * gx * gx + sxx * gy * gy - 2.0 * sxy * gx * gy) / det
    d = dr.exp(-0.5 * q) / (2.0 * math.pi * dr.sqrt(det))
    ai, vi = _lobe_areas(ki, mx, my, sxx, syy, sxy)
    ao, vo = _lobe_areas(ko, mx, my, sxx, syy, sxy)
    return d, ai, vi, ao, vo


def _f64(k):
    return mi.Float64(k.x), mi.Float64(k.y), mi.Float64(k.z)


def footprint_sums(params: GlintParams, si, h, light, view):
    """``(D_P(h), A_P(i), V_P(i), A_P(o), V_P(o))`` of the footprint (Eq. 9, 13-17).

    As the library's ``_footprint_sums``; with ``exact=false`` ``A_P`` from the merged lobe.

    Parameters
    ----------
    params : GlintParams
        The plugin's parameters.
    si : mi.SurfaceInteraction3f
        The shading point.
    h : Vector3f
        The half vector.
    light, view : Vector3f
        The directions ``i`` and ``o``.

    Returns
    -------
    tuple of Float64

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import footprint_sums
    >>> d, ai, vi, ao, vo = footprint_sums(params, si, mi.Vector3f(0, 0, 1), mi.Vector3f(0, -0.6, 0.8), si.wi)
    >>> bool(d > 0 and ai > 0 and ao > 0)
    True
    """
    t = params.tables
    fp = footprint_covariance(params, si)
    hz = mi.Float64(h.z)
    xh, yh = -mi.Float64(h.x) / hz, -mi.Float64(h.y) / hz
    ki, ko = _f64(light), _f64(view)

    def body(index, w, s):
        terms = _lobe_terms(t, index, xh, yh, ki, ko)
        return [acc + w * x for acc, x in zip(s, (1.0, *terms))]

    ws, d, ai, vi, ao, vo = _walk(fp, t.grid, [0.0 * fp.cu] * 6, body)
    d, ai, vi, ao, vo = (ratio(x, ws, ws > 0) for x in (d, ai, vi, ao, vo))
    if not params.exact:
        m = merged_lobe(t, fp)
        ai, vi = merged_area(vi, m, ki)
        ao, vo = merged_area(vo, m, ko)
    return d / (hz * hz * hz * hz), ai, vi, ao, vo      # D_P(h) = P_P(h~) / z_h^4 (Eq. 9)


def merged_lobe(tables: GlintTables, fp: Footprint):
    """Raw moments of the footprint's merged lobe.

    Sec. 4.2.2: the ``W``-weighted average over the MIP level of :meth:`LobeMixture.mip_level`.

    Parameters
    ----------
    tables : GlintTables
        With the MIP levels (``exact=false``).
    fp : Footprint
        The footprint.

    Returns
    -------
    list of Float64
        ``E1..E5``.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import footprint_covariance, merged_lobe, read_glint_params
    >>> props["exact"] = False
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv = mi.Point2f(0.5, 0.5)
    >>> e1, e2, e3, e4, e5 = merged_lobe(params.tables, footprint_covariance(params, si))
    >>> bool(e3 >= e1 * e1 and e4 >= e2 * e2)                   # variances >= 0
    True
    """
    t = tables
    suu, svv, suv = fp.cov
    half = 0.5 * (suu + svv)
    sd = dr.sqrt(half + dr.sqrt(dr.maximum(0.25 * (suu - svv) ** 2 + suv * suv, 0.0)))
    spacing = 1.0 / max(t.nx, t.ny)
    lev = dr.select(sd > spacing, dr.floor(dr.log2(dr.maximum(sd, 1e-300) / spacing)), 0.0)
    lev = dr.clip(lev, 0.0, float(t.levels - 1))
    nx, ny, off = t.mip_nx[lev], t.mip_ny[lev], t.mip_offset[lev]

    def body(index, w, s):
        base = 5.0 * (off + index)
        return [s[0] + w] + [acc + w * t.mip[base + c] for c, acc in enumerate(s[1:])]

    s = _walk(fp, SeedGrid(nx, ny, t.cutoff), [0.0 * fp.cu] * 6, body)
    return [ratio(x, s[0], s[0] > 0) for x in s[1:]]


def merged_area(v, m, k):
    """``(A_P, V_P)`` with ``A_P = V_P c_m+ / V_m`` (:func:`..glints.pbrdf._merged_area`).

    Parameters
    ----------
    v : Float64
        ``V_P`` of the footprint.
    m : sequence of Float64
        The merged lobe's raw moments (:func:`merged_lobe`).
    k : tuple of Float64
        The direction ``(x, y, z)``.

    Returns
    -------
    tuple of Float64

    Examples
    --------
    A merged lobe without slope variance facing ``k``: ``A_P = V_P``.

    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.glints import merged_area
    >>> merged_area(0.8, [0.0, 0.0, 0.0, 0.0, 0.0], (0.0, 0.0, 1.0))
    (0.8, 0.8)
    """
    e1, e2, e3, e4, e5 = m
    c, vm = _lobe_areas(k, e1, e2, e3 - e1 * e1, e4 - e2 * e2, e5 - e1 * e2)
    return dr.select((vm > 0) & (c > 0), v * ratio(c, vm, vm > 0), 0.0), v


def g2_over_ao(g2: str, ai, vi, ao, vo):
    """``G2 / A_P(o)`` (:func:`microfacet.glints.pbrdf._g2_over_ao`).

    Parameters
    ----------
    g2 : str
        ``"correlated"`` or ``"separable"``.
    ai, vi, ao, vo : Float64
        ``A_P`` and ``V_P`` of ``i`` and of ``o``.

    Returns
    -------
    Float64

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.glints import g2_over_ao
    >>> g2_over_ao("separable", 0.5, 0.5, 0.5, 0.5), g2_over_ao("correlated", 0.0, 0.5, 0.5, 0.5)
    (2.0, 0.0)
    """
    den = vo * vi if g2 == "separable" else vo * ai + ao * (vi - ai)
    return dr.select((den > 0) & (ai > 0), ratio(ai, den, den > 0), 0.0)


def glint_eval_pdf(params: GlintParams, ctx, si, light, active, want_value=True, want_pdf=True):
    """``(F D_P G2 / (4 A_P(o)), D_P z_h / (4 o.h))`` toward ``light``.

    Either is ``None`` when not wanted (:meth:`PatchBRDF.eval_cos`).

    Parameters
    ----------
    params : GlintParams
        The plugin's parameters.
    ctx : mi.BSDFContext
        The context.
    si : mi.SurfaceInteraction3f
        The shading point; the view is ``si.wi``.
    light : Vector3f
        The light ``i``.
    active : Bool
        The active lanes.
    want_value, want_pdf : bool, optional
        Compute the value, the pdf.

    Returns
    -------
    value : Spectrum or None
    pdf : Float or None

    Examples
    --------
    The library's patch BRDF of the same footprint gives the same value:

    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import footprint_covariance, glint_eval_pdf
    >>> value, pdf = glint_eval_pdf(params, mi.BSDFContext(), si, mi.Vector3f(0, -0.6, 0.8), True)
    >>> uu, vv, uv = footprint_covariance(params, si).cov
    >>> patch = mf.glints.PatchBRDF(mf.glints.Microsurface.load(path), (0.5, 0.5), [[uu, uv], [uv, vv]])
    >>> library = patch.eval_cos(np.array([0, -0.6, 0.8]), np.array([0, 0.6, 0.8]))
    >>> bool(np.allclose(np.array(value), library, rtol=1e-4))
    True
    """
    r = half_vector(ctx, si, light, active)
    h, oh, active = r.h, r.oh, r.active & (r.h.z > 0)
    d, ai, vi, ao, vo = footprint_sums(params, si, h, light, si.wi)
    value = pdf = None
    if want_value:
        s = mi.Float(d * g2_over_ao(params.g2, ai, vi, ao, vo) * 0.25)
        value = dr.select(active, fresnel_term(params.fresnel, si, oh, active) * s, 0.0)
    if want_pdf:
        pdf = dr.select(active, mi.Float(d * mi.Float64(h.z) / (4.0 * mi.Float64(oh))), 0.0)
    return value, pdf


def pick_lobe(tables: GlintTables, fp: Footprint, sample1):
    """The index of the lobe ``i`` of the footprint's window with
    ``sum_{j<i} W_j <= sample1 sum W < sum_{j<=i} W_j`` (two walks: the total, then the pick).

    Parameters
    ----------
    tables : GlintTables
        The lobes.
    fp : Footprint
        The footprint.
    sample1 : Float
        A uniform number.

    Returns
    -------
    Float64
        The lobe's index.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import footprint_covariance, pick_lobe
    >>> fp = footprint_covariance(params, si)
    >>> picks = [int(pick_lobe(params.tables, fp, u)) for u in (0.0, 0.5, 0.999)]
    >>> picks == sorted(picks) and all(0 <= i < 64 for i in picks)
    True
    """
    grid, zero = tables.grid, 0.0 * fp.cu
    ws = _walk(fp, grid, [zero], lambda i, w, s: [s[0] + w])[0]
    target = mi.Float64(sample1) * ws

    def pick(index, w, s):
        acc, chosen, last = s
        take = (acc <= target) & (acc + w > target)
        return [acc + w, dr.select(take, index, chosen), index]

    _, chosen, last = _walk(fp, grid, [zero, zero - 1.0, zero], pick)
    return dr.select(chosen < 0, last, chosen)    # sample1 * ws rounded up to ws


def lobe_of(tables: GlintTables, index) -> Lobe:
    """Lobe ``index`` as a Beckmann :class:`~.slopes.Lobe` (``alpha = sqrt(2 sigma^2)``).

    Parameters
    ----------
    tables : GlintTables
        The lobes.
    index : Float64
        The lobe's index.

    Returns
    -------
    Lobe

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> props = mi.Properties("mf_glints")
    >>> props["filename"], props["footprint"] = "glints.npz", 2.0       # 2 texels wide
    >>> from microfacet.mitsuba.glints import read_glint_params
    >>> params = read_glint_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> from microfacet.mitsuba.glints import lobe_of
    >>> lobe = lobe_of(params.tables, 0)
    >>> lobe.kind, bool(lobe.alpha_x > 0)
    ('beckmann', True)
    """
    mx, my, sxx, syy, sxy = (tables.central[5 * index + c] for c in range(5))
    ax, ay = dr.sqrt(2.0 * sxx), dr.sqrt(2.0 * syy)
    return Lobe(BECKMANN, *(mi.Float(p) for p in (ax, ay, 2.0 * sxy / (ax * ay), mx, my)))


class GlintsBSDF:
    """The patch BRDF (:class:`microfacet.glints.PatchBRDF`) of a glint microsurface of
    ``microfacet glints``: per shading point the lobes of the footprint (a Gaussian pixel
    filter from the ray differentials, else ``footprint`` texels), summed in double
    precision; a footprint whose window would exceed ``max_lobes`` lobes is shrunk. ``mi.traverse`` exposes ``specular_reflectance``.

    | name | type | default | meaning |
    |---|---|---|---|
    | `filename` | string | required | the `.npz` of `microfacet glints` |
    | `exact` | boolean | `true` | exact patch areas `A_P` (Eq. 17); `false`: the merged lobe of the MIP level matching the footprint (Sec. 4.2.2) |
    | `g2` | string | `correlated` | `correlated` or `separable`, as `PatchBRDF` |
    | `footprint` | float | 1 | pixel width in texels of the normal map without ray differentials (>= 0) |
    | `uv_scale` | float | 1 | the map repeats `uv_scale` times over the uv square (> 0) |
    | `max_lobes` | integer | 1024 | bound on the lobes gathered per shading point (>= 16; larger footprints are shrunk) |
    | `material` | string | `none` | Fresnel of a conductor of Mitsuba's IOR database, as `mf_microfacet` |
    | `eta` | float or texture | 0 | conductor Fresnel (with `k`), as `mf_microfacet` |
    | `k` | float or texture | 1 | conductor Fresnel (with `eta`), as `mf_microfacet` |
    | `int_ior` | float or string | 1.5046 | dielectric Fresnel, as `mf_microfacet` |
    | `ext_ior` | float or string | 1.000277 | dielectric Fresnel, as `mf_microfacet` |
    | `schlick_f0` | float or texture | 0.04 | Schlick Fresnel, as `mf_microfacet` |
    | `schlick_f90` | float or texture | 1 | Schlick Fresnel's grazing value, as `mf_microfacet` |
    | `specular_reflectance` | float or texture | 1 | factor on the BRDF |

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters (table above).

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    >>> path = mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save("glints.npz")
    >>> bsdf = mfm.load_dict({"type": "mf_glints", "filename": "glints.npz", "material": "Ag"})
    >>> bsdf                                          # doctest: +ELLIPSIS
    GlintsBSDF[mf_glints, filename='glints.npz', lobes=8x8, exact=True, g2=correlated, ...]
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> bs, weight = bsdf.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.3, 0.6))
    >>> value, pdf = bsdf.eval_pdf(mi.BSDFContext(), si, bs.wo)
    >>> bool(abs(weight[0] - value[0] / pdf) < 1e-4 * weight[0])        # weight = eval / pdf
    True
    """

    PLUGIN_NAME = PLUGIN

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.params = read_glint_params(props)
        flags = glossy_flags(anisotropic=True, spatially_varying=True)
        self.m_components = [flags]
        self.m_flags = flags

    def eval(self, ctx, si, wo, active=True):
        return glint_eval_pdf(self.params, ctx, si, wo, active, want_pdf=False)[0]

    def pdf(self, ctx, si, wo, active=True):
        return glint_eval_pdf(self.params, ctx, si, wo, active, want_value=False)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        return glint_eval_pdf(self.params, ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        """Lobe ``i`` with probability ``W_i / sum W`` (``sample1``), a normal of its slope
        density (``sample2``), the view reflected about it (Sec. 5); weight ``eval / pdf``."""
        view = si.wi
        active = reflecting(ctx, si, active)
        fp = footprint_covariance(self.params, si)
        h = lobe_of(self.params.tables, pick_lobe(self.params.tables, fp, sample1)).sample_p22(sample2)
        light = 2.0 * dr.dot(view, h) * h - view
        value, pdf = glint_eval_pdf(self.params, ctx, si, light, active & (light.z > 0))
        active &= (pdf > 0) & (light.z > 0)
        return glossy_sample(light, pdf, active), dr.select(active, value / dr.select(active, pdf, 1.0), 0.0)

    def traverse(self, callback):
        callback.put("specular_reflectance", self.params.fresnel.specular_reflectance, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        p = self.params
        return (f"GlintsBSDF[{PLUGIN}, filename={p.filename!r}, lobes={p.tables.nx}x{p.tables.ny}, "
                f"exact={p.exact}, g2={p.g2}, uv_scale={p.uv_scale}, "
                f"footprint={p.footprint}, max_lobes={p.max_lobes}]")


def bsdf_class() -> type:
    """The ``mf_glints`` class of the current Mitsuba variant (:func:`.registry.variant_class`).

    Returns
    -------
    type
        A subclass of the variant's ``mi.BSDF``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.glints import PLUGIN, bsdf_class
    >>> PLUGIN, issubclass(bsdf_class(), mi.BSDF)
    ('mf_glints', True)
    """
    return variant_class(GlintsBSDF)
