"""``mf_leadr``: a LEADR moment pyramid (``microfacet bake``) over a base material as a
Mitsuba 3 BSDF plugin (thesis Sec. 3.3-3.4, Ch. 5).

Per shading point: the five filtered moments ``E1..E5`` of the pyramid merged with the
base lobe (:func:`microfacet.leadr.downsample_operator`: moment addition, Listing 5.1)
are looked up as :func:`microfacet.leadr.lookup` does (trilinear, GPU-style anisotropic
probes along the footprint's major axis, wrapping), converted to a noncentral Beckmann
lobe as :func:`microfacet.leadr.from_moments` (Listing 3.5, same clamps) and shaded by
``mf_microfacet``'s Beckmann path (Smith, height-correlated with the sheared
normalization; :mod:`.bsdf`). The footprint is the ray differentials' ``si.duv_dx``,
``si.duv_dy`` (times ``uv_scale``) where Mitsuba provides them (camera rays; the path
integrator scales them by ``1/sqrt(spp)``), else the ``footprint`` parameter (a width
in uv units of the map; 0, the default, is a bilinear lookup of the finest level).
Slopes are taken along the shading frame's ``s`` (``dp/du``) and ``t`` axes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MicrofacetError
from ..leadr import downsample_operator, read_pyramid
from ..leadr.mip import MAX_ANISOTROPY
from ..leadr.moments import MAX_RHO, MIN_ALPHA
from . import properties
from .bsdf import FresnelParams, LobeModel, MicrofacetBSDF, fresnel_term, glossy_flags, read_fresnel
from .fitted import load_fit_parameter
from .registry import variant_class
from .slopes import BECKMANN, Lobe
from .tabulated import InterpolatedColor, Table, index_of

__all__ = ["PLUGIN", "bsdf_class", "Pyramid", "LeadrBSDF", "LeadrParams", "read_leadr_params", "footprint_axes",
           "filtered_moments", "lobe_from_moments"]

PLUGIN = "mf_leadr"
_ZIP_MAGIC = b"PK\x03\x04"


def _read(props, name: str):
    """The pyramid of the EXR named by ``name`` (:func:`microfacet.leadr.read_pyramid`), or a
    one-line error naming the parameter and file (a ``.npz``, e.g. a fit or glint file,
    is recognized and named as such)."""
    if name not in props or props.type(name) != mi.Properties.Type.String:
        raise properties.parameter_error(name, "is required: the pyramid EXR written by `microfacet bake`", PLUGIN)
    path = str(mi.file_resolver().resolve(props[name]))
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise properties.parameter_error(name, f"cannot read {path!r} ({e.strerror or e})", PLUGIN) from None
    if head == _ZIP_MAGIC:
        raise properties.parameter_error(name, f"{path!r} is a .npz archive (a fit or glint file?), not a LEADR "
                                 "pyramid EXR of `microfacet bake`", PLUGIN)
    try:
        return read_pyramid(path)
    except MicrofacetError as e:
        raise properties.parameter_error(name, f"is not usable: {e}", PLUGIN) from None


class Pyramid:
    """A moment pyramid in one flat table, looked up as :func:`microfacet.leadr.lookup`.

    Level after level, row-major texels, 5 moments each (the file's float32 values, widened),
    with per-level sizes and offsets; :meth:`lookup` is :func:`microfacet.leadr.lookup`
    (``wrap=True``) in Dr.Jit. Lookups and the moment-to-lobe conversion run in double
    precision, as the library's: the variances ``E3 - E1^2`` of sharp lobes with large mean
    slopes cancel digits in float32.

    Parameters
    ----------
    levels : list of ndarray
        The levels ``(H, W, 5)``, finest first (:func:`microfacet.leadr.bake`).
    max_anisotropy : int, optional
        The most probes along the footprint's major axis.

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1))
    >>> from microfacet.mitsuba.leadr import Pyramid
    >>> table = Pyramid(pyramid)
    >>> e = table.lookup(mi.Point2f(0.5, 0.5), mi.Vector2f(0.25, 0), mi.Vector2f(0, 0.25))
    >>> library = mf.leadr.lookup(pyramid, np.array([0.5, 0.5]), 0.25)
    >>> table.levels, bool(np.allclose(e, library, rtol=1e-5, atol=1e-9))
    (4, True)
    """

    def __init__(self, levels, max_anisotropy: int = MAX_ANISOTROPY):
        self.levels = len(levels)
        self.h0, self.w0 = levels[0].shape[:2]
        offsets = np.cumsum([0] + [lv.shape[0] * lv.shape[1] for lv in levels])[:-1]
        self.data = Table(np.concatenate([np.asarray(lv, np.float32).ravel() for lv in levels]), "float64")
        self.width = Table([lv.shape[1] for lv in levels], "float64")
        self.height = Table([lv.shape[0] for lv in levels], "float64")
        self.offset = Table(offsets, dtype="uint32")
        self.max_anisotropy = int(max_anisotropy)

    def _bilinear(self, k, u, v):
        """Bilinear sample (texel centres at ``(i + 1/2) / W``, wrapping) of level ``k``."""
        w, h, off = self.width[k], self.height[k], self.offset[k]
        x, y = u * w - 0.5, v * h - 0.5
        x0, y0 = dr.floor(x), dr.floor(y)
        fx, fy = x - x0, y - y0
        xa = x0 - w * dr.floor(x0 / w)
        ya = y0 - h * dr.floor(y0 / h)
        xb = dr.select(xa + 1.0 >= w, 0.0, xa + 1.0)
        yb = dr.select(ya + 1.0 >= h, 0.0, ya + 1.0)
        wu = mi.UInt32(w)

        def texel(row, col):
            i = (off + mi.UInt32(row) * wu + mi.UInt32(col)) * 5
            return [self.data[i + c] for c in range(5)]

        t00, t01, t10, t11 = texel(ya, xa), texel(ya, xb), texel(yb, xa), texel(yb, xb)
        return [((t00[c] * (1 - fx) + t01[c] * fx) * (1 - fy) + (t10[c] * (1 - fx) + t11[c] * fx) * fy)
                for c in range(5)]

    def _trilinear(self, u, v, lod):
        """Blend of levels ``floor(lod)`` and the next (the top level alone at the top)."""
        top = self.levels - 1
        lod = dr.clip(lod, 0.0, float(top))
        k0 = index_of(lod, self.levels)
        t = lod - mi.Float64(k0)
        s0 = self._bilinear(k0, u, v)
        s1 = self._bilinear(dr.minimum(k0 + 1, top), u, v)
        return [a * (1.0 - t) + b * t for a, b in zip(s0, s1)]

    def lookup(self, uv, a, b):
        """Filtered moments ``[E1..E5]`` (double precision) at ``uv`` over the footprint axes.

        ``N = min(ceil(major / minor), max_anisotropy)`` trilinear probes (1 when the major axis is
        below a texel) spread over the major axis at ``lod = log2(max(major / N, 1))``, averaged
        (:func:`microfacet.leadr.lookup`).

        Parameters
        ----------
        uv : Point2f
            Where (wrapping).
        a, b : Vector2f
            The footprint's axes, in uv units.

        Returns
        -------
        list of Float64
        """
        F = mi.Float64
        u, v = F(uv.x), F(uv.y)
        ax, ay, bx, by = F(a.x) * self.w0, F(a.y) * self.h0, F(b.x) * self.w0, F(b.y) * self.h0
        la, lb = dr.sqrt(ax * ax + ay * ay), dr.sqrt(bx * bx + by * by)
        major_is_a = la >= lb
        major = dr.select(major_is_a, la, lb)
        minor = dr.select(major_is_a, lb, la)
        axis_u = dr.select(major_is_a, F(a.x), F(b.x))
        axis_v = dr.select(major_is_a, F(a.y), F(b.y))
        n = dr.clip(dr.ceil(major / dr.maximum(minor, 1e-12)), 1.0, float(self.max_anisotropy))
        n = dr.select(major > 1.0, n, 1.0)
        lod = dr.log2(dr.maximum(major / n, 1.0))

        def body(j, e):
            s = (j + 0.5) / n - 0.5
            p = self._trilinear(u + s * axis_u, v + s * axis_v, lod)
            return j + 1.0, [acc + q for acc, q in zip(e, p)]

        zero = 0.0 * n
        j, e = dr.while_loop(state=(zero, [zero] * 5), cond=lambda j, e: j < n, body=body)
        return [c / n for c in e]


def lobe_from_moments(e):
    """The Beckmann lobe of moments ``[E1..E5]`` (Listing 3.5).

    As :func:`microfacet.leadr.from_moments`: ``alpha^2 = 2 max(Var, MIN_ALPHA^2 / 2)``,
    ``rho = clip(2 Cov / (alpha_x alpha_y), +-MAX_RHO)``, mean slope ``(E1, E2)``.

    Parameters
    ----------
    e : sequence of Float
        The moments ``E1..E5`` (``E[x~]``, ``E[y~]``, ``E[x~^2]``, ``E[y~^2]``, ``E[x~ y~]``).

    Returns
    -------
    Lobe
        A Beckmann :class:`~.slopes.Lobe`.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.leadr import lobe_from_moments
    >>> lobe = lobe_from_moments([0.1, 0.0, 0.03, 0.02, 0.0])     # Var x = 0.02, Var y = 0.02
    >>> round(lobe.alpha_x, 6), round(lobe.alpha_y, 6), lobe.rho, round(lobe.xn, 6)
    (0.2, 0.2, 0.0, 0.1)
    """
    e1, e2, e3, e4, e5 = e
    floor = 0.5 * MIN_ALPHA * MIN_ALPHA
    ax = dr.sqrt(2.0 * dr.maximum(e3 - e1 * e1, floor))
    ay = dr.sqrt(2.0 * dr.maximum(e4 - e2 * e2, floor))
    rho = dr.clip(2.0 * (e5 - e1 * e2) / (ax * ay), -MAX_RHO, MAX_RHO)
    return Lobe(BECKMANN, *(mi.Float(p) for p in (ax, ay, rho, e1, e2)))


@dataclass(frozen=True)
class LeadrParams:
    """All parameters of ``mf_leadr`` (:func:`read_leadr_params`).

    The pyramid merged with the base lobe, the Fresnel term (the base fit's table, or
    :func:`.bsdf.read_fresnel`'s), the map's repetition ``uv_scale`` and the fallback
    ``footprint`` width (uv units).

    Attributes
    ----------
    filename : str
        The pyramid EXR.
    pyramid : Pyramid
        The pyramid merged with the base lobe.
    model : LobeModel
        The lobe's computation (Beckmann, Smith).
    fresnel : FresnelParams
        The Fresnel term.
    uv_scale : float
        Repetitions of the map over the uv square.
    footprint : float
        Fallback footprint width in uv units (without ray differentials).

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1))
    >>> path = mf.leadr.write_pyramid("pyramid.exr", pyramid)        # as `microfacet bake` writes
    >>> props = mi.Properties("mf_leadr")
    >>> props["filename"], props["alpha"], props["footprint"] = "pyramid.exr", 0.1, 0.25
    >>> from microfacet.mitsuba.leadr import LeadrParams, read_leadr_params
    >>> p = read_leadr_params(props)
    >>> isinstance(p, LeadrParams), p.pyramid.levels, p.uv_scale, p.footprint, p.fresnel.kind
    (True, 4, 1.0, 0.25, 'none')
    """
    filename: str
    pyramid: Pyramid
    model: LobeModel
    fresnel: FresnelParams
    uv_scale: float
    footprint: float


def _read_base(props):
    """``(base, fresnel)``: the base lobe merged into the pyramid (an alpha, a Beckmann fit
    of the ``fit`` file, or ``None`` for a mirror) and its Fresnel term."""
    error = properties.parameter_error
    if "alpha" in props and "fit" in props:
        raise error("alpha", "and fit are exclusive: the base is one material", PLUGIN)
    if "fit" in props:
        fit = load_fit_parameter(props, "fit", PLUGIN)
        if any(k in props for k in properties.FRESNEL_KEYS):
            raise error("fit", "brings its own Fresnel table: drop the Fresnel parameters", PLUGIN)
        base = fit.to_beckmann()
        table = InterpolatedColor(base.fresnel.cos_theta_d, base.fresnel.values)
        reflectance = properties.texture(props, "specular_reflectance", 1.0, plugin=PLUGIN)
        return base, FresnelParams("table", reflectance, table=table)
    if "alpha" in props and not properties.is_float(props, "alpha"):
        raise error("alpha", f"must be a number, got {props.as_string('alpha')!r}", PLUGIN)
    alpha = float(props.get("alpha", 0.0))
    if not (math.isfinite(alpha) and alpha >= 0):
        raise error("alpha", f"must be a finite number >= 0, got {alpha!r}", PLUGIN)
    return (alpha if alpha > 0 else None), read_fresnel(props, PLUGIN)


def _read_scale(props, name: str, default: float, zero_ok: bool) -> float:
    """A finite number ``> 0`` (``>= 0`` where ``zero_ok``) of ``props``."""
    v = float(props.get(name, default))
    if not (math.isfinite(v) and (v > 0 or (zero_ok and v == 0))):
        raise properties.parameter_error(name, f"must be a finite number {'>=' if zero_ok else '>'} 0, got {v!r}",
                                         PLUGIN)
    return v


def read_leadr_params(props) -> LeadrParams:
    """All parameters of ``mf_leadr`` (class docstring of :class:`LeadrBSDF`), checked.

    The pyramid is merged with the base lobe (``alpha``, or the Beckmann moments of the
    ``fit`` file) by :func:`microfacet.leadr.downsample_operator`.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.

    Returns
    -------
    LeadrParams

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
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1))
    >>> path = mf.leadr.write_pyramid("pyramid.exr", pyramid)        # as `microfacet bake` writes
    >>> props = mi.Properties("mf_leadr")
    >>> props["filename"], props["alpha"], props["footprint"] = "pyramid.exr", 0.1, 0.25
    >>> from microfacet.mitsuba.leadr import read_leadr_params
    >>> read_leadr_params(props).model
    LobeModel(kind='beckmann', gaf='smith', shadowing=True, separable=False, samples_visible=True)
    >>> props["fit"] = "pyramid.exr"
    >>> read_leadr_params(props)
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_leadr: parameter 'alpha' and fit are exclusive: the base is one material
    """
    pyramid = _read(props, "filename")
    base, fresnel = _read_base(props)
    pyramid = Pyramid(downsample_operator(pyramid, base))
    uv_scale = _read_scale(props, "uv_scale", 1.0, zero_ok=False)
    footprint = _read_scale(props, "footprint", 0.0, zero_ok=True)
    model = LobeModel(BECKMANN, "smith", properties.flag(props, "shadowing", True, PLUGIN), False, True)
    return LeadrParams(props["filename"], pyramid, model, fresnel, uv_scale, footprint)


def footprint_axes(params: LeadrParams, si):
    """The footprint's axes ``(a, b)`` at ``si``, in uv units of the map.

    ``uv_scale`` times the ray differentials ``duv_dx``, ``duv_dy`` where they are set, else
    ``footprint`` along u and v.

    Parameters
    ----------
    params : LeadrParams
        The plugin's parameters.
    si : mi.SurfaceInteraction3f
        The shading point.

    Returns
    -------
    a, b : Vector2f

    Examples
    --------
    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1))
    >>> path = mf.leadr.write_pyramid("pyramid.exr", pyramid)        # as `microfacet bake` writes
    >>> props = mi.Properties("mf_leadr")
    >>> props["filename"], props["alpha"], props["footprint"] = "pyramid.exr", 0.1, 0.25
    >>> from microfacet.mitsuba.leadr import footprint_axes, read_leadr_params
    >>> p = read_leadr_params(props)
    >>> si = mi.SurfaceInteraction3f()
    >>> footprint_axes(p, si)                          # no ray differentials: `footprint`
    ([0.25, 0], [0, 0.25])
    >>> si.duv_dx, si.duv_dy = mi.Vector2f(0.01, 0), mi.Vector2f(0, 0.02)
    >>> footprint_axes(p, si)
    ([0.01, 0], [0, 0.02])
    """
    a, b = si.duv_dx * params.uv_scale, si.duv_dy * params.uv_scale
    has = (dr.squared_norm(a) + dr.squared_norm(b)) > 0
    f = params.footprint
    return dr.select(has, a, mi.Vector2f(f, 0.0)), dr.select(has, b, mi.Vector2f(0.0, f))


def filtered_moments(params: LeadrParams, si):
    """Filtered moments ``[E1..E5]`` at ``si`` (:meth:`Pyramid.lookup` over :func:`footprint_axes`).

    Parameters
    ----------
    params : LeadrParams
        The plugin's parameters.
    si : mi.SurfaceInteraction3f
        The shading point (``si.uv`` times ``uv_scale``).

    Returns
    -------
    list of Float64

    Examples
    --------
    The base roughness ``alpha = 0.1`` adds ``alpha^2 / 2`` to the second moments:

    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1))
    >>> path = mf.leadr.write_pyramid("pyramid.exr", pyramid)        # as `microfacet bake` writes
    >>> props = mi.Properties("mf_leadr")
    >>> props["filename"], props["alpha"], props["footprint"] = "pyramid.exr", 0.1, 0.25
    >>> from microfacet.mitsuba.leadr import filtered_moments, read_leadr_params
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv = mi.Point2f(0.5, 0.5)
    >>> e = filtered_moments(read_leadr_params(props), si)
    >>> library = mf.leadr.lookup(pyramid, np.array([0.5, 0.5]), 0.25)
    >>> bool(np.allclose(np.array(e) - library, [0, 0, 0.005, 0.005, 0], atol=1e-7))
    True
    """
    a, b = footprint_axes(params, si)
    return params.pyramid.lookup(si.uv * params.uv_scale, a, b)


class LeadrBSDF(MicrofacetBSDF):
    """A LEADR moment pyramid of ``microfacet bake`` over a base material: per shading point
    the pyramid's moments merged with the base lobe, filtered over the footprint (ray
    differentials, else ``footprint``; trilinear, anisotropic probes, wrapping) and
    converted to a Beckmann lobe, shaded as ``mf_microfacet``'s Smith path. ``mi.traverse`` exposes ``specular_reflectance``.

    | name | type | default | meaning |
    |---|---|---|---|
    | `filename` | string | required | the pyramid EXR of `microfacet bake` |
    | `alpha` | float | 0 | base Beckmann roughness merged into every level (0: a mirror base, clamped to 1e-3) |
    | `fit` | string | none | instead of `alpha`: a fit `.npz`, merged by its Beckmann moments, whose Fresnel table is used |
    | `uv_scale` | float | 1 | the map repeats `uv_scale` times over the uv square (> 0) |
    | `footprint` | float | 0 | footprint width in uv units of the map without ray differentials (0: bilinear finest level) |
    | `shadowing` | boolean | `true` | `false`: masking only |
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
    A Beckmann height field baked to a pyramid, over a gold base of roughness 0.1:

    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> heights = mf.leadr.gaussian_heightfield((8, 8), 0.3, correlation=2.0, seed=1)
    >>> path = mf.leadr.write_pyramid("pyramid.exr", mf.leadr.bake(heights))
    >>> bsdf = mfm.load_dict({"type": "mf_leadr", "filename": "pyramid.exr", "alpha": 0.1,
    ...                       "material": "Au", "footprint": 0.5})
    >>> bsdf                                     # doctest: +ELLIPSIS
    LeadrBSDF[mf_leadr, filename='pyramid.exr', levels=4, uv_scale=1.0, footprint=0.5, shadowing=True]
    >>> si = mi.SurfaceInteraction3f()
    >>> si.uv, si.wi = mi.Point2f(0.5, 0.5), mi.Vector3f(0, 0.6, 0.8)
    >>> value, pdf = bsdf.eval_pdf(mi.BSDFContext(), si, mi.Vector3f(0, -0.6, 0.8))
    >>> bool(value[0] > 0 and pdf > 0)
    True
    """

    PLUGIN_NAME = PLUGIN

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.params = read_leadr_params(props)
        self.model = self.params.model
        flags = glossy_flags(anisotropic=True, spatially_varying=True)
        self.m_components = [flags]
        self.m_flags = flags

    def lobe(self, si, active):
        return lobe_from_moments(filtered_moments(self.params, si))

    def fresnel(self, si, oh, active):
        return fresnel_term(self.params.fresnel, si, oh, active)

    def traverse(self, callback):
        callback.put("specular_reflectance", self.params.fresnel.specular_reflectance, mi.ParamFlags.Differentiable)

    def to_string(self):
        p = self.params
        return (f"LeadrBSDF[{PLUGIN}, filename={p.filename!r}, levels={p.pyramid.levels}, "
                f"uv_scale={p.uv_scale}, footprint={p.footprint}, shadowing={p.model.shadowing}]")


def bsdf_class() -> type:
    """The ``mf_leadr`` class of the current Mitsuba variant (:func:`.registry.variant_class`).

    Returns
    -------
    type
        A subclass of the variant's ``mi.BSDF``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.leadr import PLUGIN, bsdf_class
    >>> PLUGIN, issubclass(bsdf_class(), mi.BSDF)
    ('mf_leadr', True)
    """
    return variant_class(LeadrBSDF)
