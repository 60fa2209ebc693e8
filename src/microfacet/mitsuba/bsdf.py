"""``mf_microfacet``: the library's noncentral microfacet BRDF as a Mitsuba 3 BSDF plugin.

``f_r cos theta_i = F(o.h) D(h) G(i, o) / (4 z_o)`` (Eq. 2.1, Listing 2.2) with the noncentral
slope distribution of :mod:`microfacet.mitsuba.slopes`, the geometric attenuation of
:meth:`microfacet.MicrofacetBRDF.gaf` (Table 2.IV, :data:`GAFS`; Smith height-correlated
with the sheared projected-area normalization, Eq. 3.3) and the sampling of
:meth:`microfacet.MicrofacetBRDF.sample` (visible normals for Smith, Eq. 2.23; slopes of
``P`` otherwise). Mitsuba's ``si.wi`` is the library's view direction ``o`` and the
``wo`` argument its light direction ``i``; ``eval`` returns ``f_r cos theta_i``.

The plugin's parameters are read once into records (:class:`LobeModel`, :class:`Roughness`,
:class:`FresnelParams`, together :class:`MicrofacetParams`); each step of the math is a
module-level function of those records (:func:`geometric_attenuation`,
:func:`normal_density`, :func:`fresnel_term`, ...). :class:`MicrofacetLobe` is the shading
code shared with ``mf_fitted``, ``mf_leadr`` and the fits' BRDF trees, which supply their
own lobe and Fresnel term; :class:`MicrofacetBSDF` is the plugin :data:`PLUGIN` (a plain
class made a ``mi.BSDF`` per variant by :func:`.registry.variant_class`).

Examples
--------
The plugin's value equals the library's ``f_r`` times ``cos theta_i``:

>>> import numpy as np
>>> import mitsuba as mi
>>> mi.set_variant("scalar_rgb")
>>> import microfacet as mf
>>> import microfacet.mitsuba as mfm
>>> from microfacet.mitsuba.bsdf import GAFS, PLUGIN
>>> _ = mfm.register()
>>> PLUGIN, GAFS
('mf_microfacet', ('smith', 'vgroove', 'normal_map'))
>>> bsdf = mfm.load_dict({"type": PLUGIN, "distribution": "ggx", "alpha": 0.3, "gaf": "vgroove"})
>>> si = mi.SurfaceInteraction3f()
>>> si.wi = mi.Vector3f(0, 0.6, 0.8)
>>> value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.48, -0.36, 0.8))
>>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), gaf="vgroove")
>>> library = brdf.eval(np.array([0.48, -0.36, 0.8]), np.array([0.0, 0.6, 0.8]))[0] * 0.8
>>> bool(np.isclose(value[0], library, rtol=1e-5))
True
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from . import fresnel as fresnel_formulas
from . import properties
from .properties import DEFAULT_PLUGIN as PLUGIN
from .registry import variant_class
from .slopes import BECKMANN, GGX, Lobe, ratio
from .tabulated import luminance

__all__ = ["PLUGIN", "bsdf_class", "GAFS", "MicrofacetBSDF", "MicrofacetLobe", "LobeModel", "Roughness",
           "FresnelParams", "MicrofacetParams", "read_model", "read_roughness", "read_fresnel",
           "read_microfacet_params", "roughness_lobe", "fresnel_term", "geometric_attenuation",
           "normal_density", "reflecting", "half_vector", "mirror", "Reflection", "lobe_value", "lobe_pdf", "sample_normal",
           "sample_weight", "glossy_sample", "glossy_flags"]

GAFS = ("smith", "vgroove", "normal_map")
_ALPHA_MIN = 1e-4           # textured alpha is clamped here (as Mitsuba's roughconductor)
_RHO_MAX = 1.0 - 1e-4       # textured rho is clamped into [-_RHO_MAX, _RHO_MAX]
#: Default of ``int_ior`` / ``ext_ior`` (Mitsuba's ``bk7`` and ``air``).
_INT_IOR, _EXT_IOR = 1.5046, 1.000277


# ------------------------------------------------------------------ records
@dataclass(frozen=True)
class LobeModel:
    """What a microfacet lobe computes, fixed at load.

    The slope distribution ``kind`` (``beckmann``, ``ggx``, ``tabulated``), the GAF (Table
    2.IV: ``smith``, ``vgroove``, ``normal_map``), shadowing (``False``: masking only),
    ``separable`` Smith ``G1 G1``, and whether sampling draws visible normals (Eq. 2.23) or
    slopes of ``P``.

    Attributes
    ----------
    kind : str
        Slope distribution: ``beckmann`` (default), ``ggx`` or ``tabulated``.
    gaf : str
        ``smith`` (default), ``vgroove`` or ``normal_map``.
    shadowing : bool
        Shadowing and masking (default); ``False``: masking only.
    separable : bool
        Smith ``G1(i) G1(o)`` (default ``False``: the library's Smith ``G``).
    samples_visible : bool
        Sample visible normals (default) or slopes of ``P``.

    Examples
    --------

    >>> from microfacet.mitsuba.bsdf import LobeModel
    >>> LobeModel("ggx")
    LobeModel(kind='ggx', gaf='smith', shadowing=True, separable=False, samples_visible=True)
    >>> LobeModel("beckmann", gaf="vgroove", samples_visible=False).gaf
    'vgroove'
    """
    kind: str = BECKMANN
    gaf: str = "smith"
    shadowing: bool = True
    separable: bool = False
    samples_visible: bool = True


@dataclass(frozen=True)
class Roughness:
    """The lobe's textures.

    ``alpha_u``, ``alpha_v`` (one texture when ``isotropic``), the slope correlation ``rho``
    and the mean slope ``(mean_slope_u, mean_slope_v)`` (Eq. 3.4).

    Attributes
    ----------
    alpha_u, alpha_v : texture
        Roughness along u and v (the same texture when ``isotropic``).
    rho : texture
        Slope correlation.
    mean_slope_u, mean_slope_v : texture
        The mean slope (Eq. 3.4).
    isotropic : bool
        Whether one texture gives both roughnesses.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, read_roughness
    >>> props = mi.Properties("mf_microfacet")
    >>> props["alpha_u"], props["alpha_v"], props["rho"] = 0.2, 0.4, 0.5
    >>> r = read_roughness(props, LobeModel("ggx"))
    >>> r.isotropic, r.alpha_v.mean(), r.rho.mean(), r.mean_slope_u.mean()
    (False, 0.4000000059604645, 0.5, 0.0)
    """
    alpha_u: object
    alpha_v: object
    rho: object
    mean_slope_u: object
    mean_slope_v: object
    isotropic: bool


@dataclass(frozen=True)
class FresnelParams:
    """``F(o.h)`` (Table 2.I) times ``specular_reflectance``.

    ``kind`` ``none`` (F = 1), ``conductor`` (textures ``eta``, ``k``), ``dielectric``
    (``eta``: a ``Float`` ``int_ior / ext_ior``), ``schlick`` (textures ``f0``, ``f90``) or
    ``table`` (``table``: an :class:`~.tabulated.InterpolatedColor` of ``cos theta_d``, a
    fit's).

    Attributes
    ----------
    kind : str
        ``none``, ``conductor``, ``dielectric``, ``schlick`` or ``table``.
    specular_reflectance : texture
        Factor of ``F``.
    eta, k : texture or Float, optional
        Conductor indices (``eta`` alone: a dielectric's relative IOR).
    f0, f90 : texture, optional
        Schlick's reflectances at normal and grazing incidence.
    table : InterpolatedColor, optional
        A fit's Fresnel table of ``cos theta_d``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import FresnelParams, fresnel_term
    >>> fresnel = FresnelParams("dielectric", mi.load_dict({"type": "uniform", "value": 1.0}), eta=1.5)
    >>> si = mi.SurfaceInteraction3f()
    >>> fresnel_term(fresnel, si, 1.0, True)                  # ((1.5 - 1) / (1.5 + 1))^2
    [0.04, 0.04, 0.04]
    """
    kind: str
    specular_reflectance: object
    eta: object = None
    k: object = None
    f0: object = None
    f90: object = None
    table: object = None


class Reflection(NamedTuple):
    """The directions of one reflection (Dr.Jit arrays per lane).

    ``light`` (the library's ``i``), ``view`` (``o``, Mitsuba's ``si.wi``), the half vector
    ``h``, ``oh = o.h`` and the lanes where it is ``active``.

    Attributes
    ----------
    light : Vector3f
        Direction toward the light (``i``), local frame.
    view : Vector3f
        Direction toward the viewer (``o``, ``si.wi``).
    h : Vector3f
        Unit half vector.
    oh : Float
        ``o.h``.
    active : Bool
        The lanes where the reflection is valid.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import Reflection, mirror
    >>> r = mirror(mi.Vector3f(0, 0.6, 0.8), mi.Vector3f(0, 0, 1), True)
    >>> isinstance(r, Reflection), r.light, r.active
    (True, [0, -0.6, 0.8], True)
    """
    light: object
    view: object
    h: object
    oh: object
    active: object


@dataclass(frozen=True)
class MicrofacetParams:
    """All parameters of ``mf_microfacet`` (:func:`read_microfacet_params`).

    The lobe's :class:`LobeModel`, its :class:`Roughness`, its :class:`FresnelParams` and
    whether the lobe is ``anisotropic`` (``alpha_u``/``alpha_v``, ``rho`` or a mean slope given).

    Attributes
    ----------
    model : LobeModel
        What the lobe computes.
    roughness : Roughness
        The lobe's textures.
    fresnel : FresnelParams
        The Fresnel term.
    anisotropic : bool
        Whether the lobe is anisotropic.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import read_microfacet_params
    >>> props = mi.Properties("mf_microfacet")
    >>> props["alpha"], props["mean_slope_u"] = 0.3, 0.1
    >>> p = read_microfacet_params(props)
    >>> p.model.kind, p.roughness.isotropic, p.fresnel.kind, p.anisotropic
    ('beckmann', True, 'none', True)
    """
    model: LobeModel
    roughness: Roughness
    fresnel: FresnelParams
    anisotropic: bool


# ------------------------------------------------------------------ reading parameters
def read_model(props, plugin: str = PLUGIN) -> LobeModel:
    """The :class:`LobeModel` of ``distribution``, ``gaf``, ``shadowing`` and ``separable``.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    LobeModel

    Raises
    ------
    PluginParameterError
        For an unknown name, or ``separable`` with a GAF other than ``smith``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import read_model
    >>> props = mi.Properties("mf_microfacet")
    >>> props["distribution"], props["gaf"], props["shadowing"] = "ggx", "vgroove", False
    >>> read_model(props)
    LobeModel(kind='ggx', gaf='vgroove', shadowing=False, separable=False, samples_visible=False)
    """
    kind = properties.choice(props, "distribution", BECKMANN, (BECKMANN, GGX), plugin)
    gaf = properties.choice(props, "gaf", "smith", GAFS, plugin)
    separable = properties.flag(props, "separable", False, plugin)
    if separable and gaf != "smith":
        raise properties.parameter_error("separable", f"applies to gaf=smith only, got gaf={gaf!r}", plugin)
    return LobeModel(kind, gaf, properties.flag(props, "shadowing", True, plugin), separable, gaf == "smith")


def read_roughness(props, model: LobeModel, plugin: str = PLUGIN) -> Roughness:
    """The :class:`Roughness` of ``alpha`` or ``alpha_u``/``alpha_v``, ``rho``,
    ``mean_slope_u``/``mean_slope_v``, checked.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    model : LobeModel
        The lobe's model (V-grooves need a zero mean slope).
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    Roughness

    Raises
    ------
    PluginParameterError
        For ``alpha`` with ``alpha_u``/``alpha_v``, one of ``alpha_u``/``alpha_v`` alone, a
        bad value, or a mean slope with ``gaf=vgroove``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, read_roughness
    >>> props = mi.Properties("mf_microfacet")
    >>> props["alpha"], props["mean_slope_v"] = 0.25, -0.5
    >>> r = read_roughness(props, LobeModel("beckmann"))
    >>> r.isotropic, r.alpha_u.mean(), r.mean_slope_v.mean()
    (True, 0.25, -0.5)
    >>> props["alpha_u"] = 0.1
    >>> read_roughness(props, LobeModel("beckmann"))
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_microfacet: parameter 'alpha' and alpha_u/alpha_v are exclusive: give one or the other
    """
    error = properties.parameter_error
    if "alpha" in props and ("alpha_u" in props or "alpha_v" in props):
        raise error("alpha", "and alpha_u/alpha_v are exclusive: give one or the other", plugin)
    if ("alpha_u" in props) != ("alpha_v" in props):
        raise error("alpha_v" if "alpha_u" in props else "alpha_u",
                    "is missing: give both alpha_u and alpha_v (or alpha)", plugin)
    isotropic = "alpha_u" not in props
    if isotropic:
        alpha_u = alpha_v = properties.texture(props, "alpha", 0.1, properties.positive, plugin=plugin)
    else:
        alpha_u = properties.texture(props, "alpha_u", 0.1, properties.positive, plugin=plugin)
        alpha_v = properties.texture(props, "alpha_v", 0.1, properties.positive, plugin=plugin)
    rho = properties.texture(props, "rho", 0.0, properties.correlation, unbounded=True, plugin=plugin)
    xn, yn = (properties.texture(props, n, 0.0, properties.finite, unbounded=True, plugin=plugin)
              for n in ("mean_slope_u", "mean_slope_v"))
    if model.gaf == "vgroove" and any(n in props and not (properties.is_float(props, n) and props[n] == 0)
                                      for n in ("mean_slope_u", "mean_slope_v")):
        raise error("gaf", "vgroove needs a zero mean slope (V-grooves stand on the macro normal); "
                    "use gaf=smith with mean_slope_u/mean_slope_v", plugin)
    return Roughness(alpha_u, alpha_v, rho, xn, yn, isotropic)


def _ior_textures(material: str, plugin: str = PLUGIN):
    """``(eta, k)`` textures of a named conductor from Mitsuba's IOR database
    (``data/ior/<material>.{eta,k}.spd``), converted as its ``roughconductor`` does."""
    paths = {part: str(mi.file_resolver().resolve(f"data/ior/{material}.{part}.spd")) for part in ("eta", "k")}
    if not all(os.path.isfile(p) for p in paths.values()):
        raise properties.parameter_error("material", f"is not a conductor in Mitsuba's IOR database "
                                                     f"(no data/ior/{material}.eta.spd), got {material!r}", plugin)
    return tuple(_spectrum_texture(*mi.spectrum_from_file(paths[part])) for part in ("eta", "k"))


def _spectrum_texture(wavelengths, values):
    """The texture of a sampled spectrum in the current variant (irregular spectrum,
    luminance or unbounded sRGB colour)."""
    if mi.is_spectral:
        return mi.load_dict({"type": "irregular", "wavelengths": ", ".join(map(str, wavelengths)),
                             "values": ", ".join(map(str, values))})
    rgb = mi.spectrum_list_to_srgb(wavelengths, values, False, False)
    if mi.is_monochromatic:
        return mi.load_dict({"type": "uniform", "value": luminance(rgb)})
    return mi.load_dict({"type": "srgb", "color": rgb, "unbounded": True})


def _fresnel_kind(props, plugin: str) -> tuple[str, list[str]]:
    """The Fresnel term the parameters of :data:`~.properties.FRESNEL_KEYS` name (``none``
    without one) and those parameters, checking that they do not conflict."""
    names = sorted(n for n in props.keys() if n in properties.FRESNEL_KEYS)
    if "material" in names and props.get("material") == "none":
        names.remove("material")                  # Mitsuba's "none": F = 1
    if "material" in names and {"eta", "k"} & set(names):
        raise properties.parameter_error("material", "and eta/k are exclusive: give one or the other", plugin)
    kinds = {properties.FRESNEL_KEYS[n] for n in names}
    if len(kinds) > 1:
        raise properties.parameter_error(names[0], f"conflicts with {', '.join(names[1:])}: give one Fresnel "
                                         "(material or eta/k, int_ior/ext_ior, schlick_f0) or none", plugin)
    return (kinds.pop() if kinds else "none"), names


def _dielectric_eta(props, plugin: str):
    """``int_ior / ext_ior`` (numbers or Mitsuba's names) as a ``Float``."""
    int_ior = mi.lookup_ior(props, "int_ior", _INT_IOR)
    ext_ior = mi.lookup_ior(props, "ext_ior", _EXT_IOR)
    for name, v in (("int_ior", int_ior), ("ext_ior", ext_ior)):
        if not (math.isfinite(v) and v > 0):
            raise properties.parameter_error(name, f"must be a finite number > 0, got {v!r}", plugin)
    return mi.Float(int_ior / ext_ior)


def _unit_interval(v) -> str | None:
    return None if 0 <= v <= 1 else "must lie in [0, 1]"


def read_fresnel(props, plugin: str = PLUGIN) -> FresnelParams:
    """The :class:`FresnelParams` of the Fresnel parameters of Table 2.I and ``specular_reflectance``.

    One of ``material`` (a conductor of Mitsuba's IOR database), ``eta``/``k``,
    ``int_ior``/``ext_ior``, ``schlick_f0``/``schlick_f90``, or none (F = 1).

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    FresnelParams

    Raises
    ------
    PluginParameterError
        For conflicting Fresnel parameters, an unknown material or a bad value.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import read_fresnel
    >>> props = mi.Properties("mf_microfacet")
    >>> props["schlick_f0"] = 0.5
    >>> f = read_fresnel(props)
    >>> f.kind, f.f0.mean(), f.f90.mean()
    ('schlick', 0.5, 1.0)
    >>> props["material"] = "Au"
    >>> read_fresnel(props)
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_microfacet: parameter 'material' conflicts with schlick_f0: give one Fresnel (material or eta/k, int_ior/ext_ior, schlick_f0) or none
    """
    reflectance = properties.texture(props, "specular_reflectance", 1.0, plugin=plugin)
    kind, names = _fresnel_kind(props, plugin)
    if kind == "conductor":
        if "material" in names:
            eta, k = _ior_textures(props.get("material"), plugin)
        else:
            eta = properties.texture(props, "eta", 0.0, properties.finite, unbounded=True, plugin=plugin)
            k = properties.texture(props, "k", 1.0, properties.finite, unbounded=True, plugin=plugin)
        return FresnelParams(kind, reflectance, eta=eta, k=k)
    if kind == "dielectric":
        return FresnelParams(kind, reflectance, eta=_dielectric_eta(props, plugin))
    if kind == "schlick":
        f0 = properties.texture(props, "schlick_f0", 0.04, _unit_interval, plugin=plugin)
        f90 = properties.texture(props, "schlick_f90", 1.0, _unit_interval, plugin=plugin)
        return FresnelParams(kind, reflectance, f0=f0, f90=f90)
    return FresnelParams(kind, reflectance)


def read_microfacet_params(props, plugin: str = PLUGIN) -> MicrofacetParams:
    """All parameters of ``mf_microfacet`` (class docstring of :class:`MicrofacetBSDF`).

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    MicrofacetParams

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import read_microfacet_params
    >>> props = mi.Properties("mf_microfacet")
    >>> props["distribution"], props["alpha"], props["material"] = "ggx", 0.3, "Au"
    >>> p = read_microfacet_params(props)
    >>> p.model.kind, p.fresnel.kind, p.anisotropic
    ('ggx', 'conductor', False)
    """
    model = read_model(props, plugin)
    roughness = read_roughness(props, model, plugin)
    anisotropic = not roughness.isotropic or any(n in props for n in ("rho", "mean_slope_u", "mean_slope_v"))
    return MicrofacetParams(model, roughness, read_fresnel(props, plugin), anisotropic)


# ------------------------------------------------------------------ terms
def roughness_lobe(kind: str, roughness: Roughness, si, active) -> Lobe:
    """The :class:`~.slopes.Lobe` of the roughness textures at ``si``.

    Alpha is clamped to ``>= 1e-4`` and rho into ``+-0.9999``, as Mitsuba's
    ``roughconductor`` clamps textured roughness.

    Parameters
    ----------
    kind : str
        ``"beckmann"`` or ``"ggx"``.
    roughness : Roughness
        The textures.
    si : mi.SurfaceInteraction3f
        Where they are evaluated.
    active : Bool
        The active lanes.

    Returns
    -------
    Lobe

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, read_roughness, roughness_lobe
    >>> props = mi.Properties("mf_microfacet")
    >>> props["alpha_u"], props["alpha_v"], props["rho"] = 0.5, 0.25, 0.5
    >>> lobe = roughness_lobe("ggx", read_roughness(props, LobeModel("ggx")), mi.SurfaceInteraction3f(), True)
    >>> lobe.kind, lobe.alpha_x, lobe.alpha_y, lobe.rho
    ('ggx', 0.5, 0.25, 0.5)
    """
    r = roughness
    ax = dr.maximum(r.alpha_u.eval_1(si, active), _ALPHA_MIN)
    ay = ax if r.isotropic else dr.maximum(r.alpha_v.eval_1(si, active), _ALPHA_MIN)
    rho = dr.clip(r.rho.eval_1(si, active), -_RHO_MAX, _RHO_MAX)
    return Lobe(kind, ax, ay, rho, r.mean_slope_u.eval_1(si, active), r.mean_slope_v.eval_1(si, active))


def fresnel_term(fresnel: FresnelParams, si, oh, active):
    """``F(o.h)`` (Table 2.I; a fit's table, Eq. 4.11) times ``specular_reflectance``.

    Parameters
    ----------
    fresnel : FresnelParams
        The Fresnel parameters.
    si : mi.SurfaceInteraction3f
        Where the textures are evaluated.
    oh : Float
        ``o.h``, the cosine of the difference angle.
    active : Bool
        The active lanes.

    Returns
    -------
    Spectrum

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import fresnel_term, read_fresnel
    >>> props = mi.Properties("mf_microfacet")
    >>> props["int_ior"], props["ext_ior"], props["specular_reflectance"] = 1.5, 1.0, 0.5
    >>> f = read_fresnel(props)
    >>> f.kind, fresnel_term(f, mi.SurfaceInteraction3f(), 1.0, True)   # 0.5 ((1.5 - 1) / (1.5 + 1))^2
    ('dielectric', [0.02, 0.02, 0.02])
    """
    r = fresnel.specular_reflectance.eval(si, active)
    if fresnel.kind == "conductor":
        return r * fresnel_formulas.conductor(oh, fresnel.eta.eval(si, active), fresnel.k.eval(si, active))
    if fresnel.kind == "dielectric":
        return r * fresnel_formulas.dielectric(oh, fresnel.eta)
    if fresnel.kind == "schlick":
        return r * fresnel_formulas.schlick(oh, fresnel.f0.eval(si, active), fresnel.f90.eval(si, active))
    if fresnel.kind == "table":
        return r * fresnel.table(dr.clip(oh, 0.0, 1.0), si.wavelengths)
    return r


def _smith_attenuation(model: LobeModel, lobe, r: Reflection, ok):
    """Smith ``(z_o / c_o) / (1 + Lambda_i + Lambda_o)`` (Eq. 3.3), or separable
    ``G1(i) G1(o)``; ``(G, ok)``."""
    light, view = r.light, r.view
    if model.separable:
        return lobe.g1(view) * (lobe.g1(light) if model.shadowing else 1.0), ok
    lam_o, co = lobe.lambda_c(view)
    ok &= co > 0
    lam_i = lobe.lambda_c(light)[0] if model.shadowing else 0.0
    return ratio(view.z, co * (1.0 + lam_i + lam_o), ok), ok


def _facet_attenuation(model: LobeModel, r: Reflection, ok):
    """V-groove ``min(1, 2 z_i z_h / ih, 2 z_o z_h / oh)`` or normal map ``z_o z_h / oh``."""
    go = ratio(r.view.z * r.h.z, r.oh, ok)
    if model.gaf != "vgroove":
        return go
    go = 2.0 * go
    gi = ratio(2.0 * r.light.z * r.h.z, r.oh, ok)
    return dr.minimum(1.0, dr.minimum(go, gi) if model.shadowing else go)


def geometric_attenuation(model: LobeModel, lobe, r: Reflection):
    """``G(i, o)`` of :meth:`microfacet.MicrofacetBRDF.gaf` at ``i.h = o.h`` (Table 2.IV).

    Without shadowing only the ``o`` factors remain; 0 below the horizons.

    Parameters
    ----------
    model : LobeModel
        The GAF, shadowing and separability.
    lobe : Lobe
        The slope distribution (its ``Lambda`` for Smith).
    r : Reflection
        The directions (:func:`half_vector` or :func:`mirror`).

    Returns
    -------
    Float

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, geometric_attenuation, half_vector
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)                     # the view o
    >>> r = half_vector(ctx, si, mi.Vector3f(0, -0.6, 0.8), True)   # lit from the mirror direction
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> lobe = Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0)
    >>> g = geometric_attenuation(LobeModel("ggx"), lobe, r)
    >>> import numpy as np, microfacet as mf
    >>> library = mf.MicrofacetBRDF(mf.GGX(alpha=0.3)).gaf(np.array([0, -0.6, 0.8]), np.array([0, 0.6, 0.8]))
    >>> round(g, 6), round(float(library), 6)
    (0.97561, 0.97561)
    """
    ok = (r.light.z > 0) & (r.view.z > 0) & (r.oh > 0) & (r.h.z > 0)
    if model.gaf == "smith":
        g, ok = _smith_attenuation(model, lobe, r, ok)
    else:
        g = _facet_attenuation(model, r, ok)
    return dr.select(ok, g, 0.0)


def normal_density(model: LobeModel, lobe, h, view):
    """Density of the sampled normals: ``D_o(h)`` (Smith, Eq. 2.17) or ``D(h) z_h``.

    Parameters
    ----------
    model : LobeModel
        Whether sampling draws visible normals.
    lobe : Lobe
        The slope distribution.
    h : Vector3f
        The normal.
    view : Vector3f
        The view ``o``.

    Returns
    -------
    Float
        The density of ``h`` over the sphere.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, normal_density
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> lobe = Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0)
    >>> n = mi.Vector3f(0, 0, 1)
    >>> p = normal_density(LobeModel("ggx", samples_visible=False), lobe, n, n)
    >>> round(p, 4), round(1 / (3.14159265 * 0.3**2), 4)            # D(n) z_n = 1 / (pi alpha^2)
    (3.5368, 3.5368)
    """
    if model.samples_visible:
        return lobe.vndf(h, view)
    return lobe.ndf(h) * h.z


def reflecting(ctx, si, active):
    """``active`` where the view is above the surface and glossy reflection is asked.

    Parameters
    ----------
    ctx : mi.BSDFContext
        The context (its enabled components).
    si : mi.SurfaceInteraction3f
        The view is ``si.wi``.
    active : Bool
        The active lanes.

    Returns
    -------
    Bool

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import reflecting
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)
    >>> reflecting(mi.BSDFContext(), si, True)
    True
    >>> si.wi = mi.Vector3f(0, 0.6, -0.8)                          # from below
    >>> reflecting(mi.BSDFContext(), si, True)
    False
    """
    active = active & (si.wi.z > 0)
    if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection):
        active = active & False
    return active


def half_vector(ctx, si, light, active) -> Reflection:
    """The :class:`Reflection` of ``light`` and the view ``si.wi``.

    Active where both are above the surface, ``o.h > 0`` and glossy reflection is asked.

    Parameters
    ----------
    ctx : mi.BSDFContext
        The context.
    si : mi.SurfaceInteraction3f
        The view is ``si.wi``.
    light : Vector3f
        The light direction ``i`` (Mitsuba's ``wo``).
    active : Bool
        The active lanes.

    Returns
    -------
    Reflection

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import half_vector
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)
    >>> r = half_vector(mi.BSDFContext(), si, mi.Vector3f(0, -0.6, 0.8), True)
    >>> r.h, round(r.oh, 6), r.active
    ([0, 0, 1], 0.8, True)
    """
    active = reflecting(ctx, si, active & (light.z > 0))
    h = dr.normalize(light + si.wi)
    oh = dr.dot(si.wi, h)
    return Reflection(light, si.wi, h, oh, active & (oh > 0))


def mirror(view, h, active) -> Reflection:
    """The :class:`Reflection` of ``view`` about the normal ``h``: ``i = 2 (o.h) h - o``.

    Active where ``active``, the light is above the surface and ``o.h > 0``.

    Parameters
    ----------
    view : Vector3f
        The view ``o``.
    h : Vector3f
        The (unit) normal.
    active : Bool
        The active lanes.

    Returns
    -------
    Reflection

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import mirror
    >>> r = mirror(mi.Vector3f(0, 0.6, 0.8), mi.Vector3f(0, 0.6, 0.8), True)   # back to the view
    >>> r.light, round(r.oh, 6)
    ([0, 0.6, 0.8], 1.0)
    """
    oh = dr.dot(view, h)
    light = 2.0 * oh * h - view
    return Reflection(light, view, h, oh, active & (light.z > 0) & (oh > 0))


def lobe_value(model: LobeModel, lobe, r: Reflection):
    """``(D G / (4 z_o), ok)``: Listing 2.2 without Fresnel, ``ok`` where ``G > 0``.

    Parameters
    ----------
    model : LobeModel
        The GAF and shadowing.
    lobe : Lobe
        The slope distribution.
    r : Reflection
        The directions.

    Returns
    -------
    value : Float
        ``f_r cos theta_i`` with ``F = 1``.
    ok : Bool
        Where the value is positive.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, half_vector, lobe_value
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)                     # the view o
    >>> r = half_vector(ctx, si, mi.Vector3f(0, -0.6, 0.8), True)   # lit from the mirror direction
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> value, ok = lobe_value(LobeModel("ggx"), Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0), r)
    >>> import numpy as np, microfacet as mf
    >>> f = mf.MicrofacetBRDF(mf.GGX(alpha=0.3)).eval(np.array([0, -0.6, 0.8]), np.array([0, 0.6, 0.8]))
    >>> round(value, 5), round(float(f[0]) * 0.8, 5), ok                  # the library's f_r cos theta_i
    (1.07829, 1.07829, True)
    """
    g = geometric_attenuation(model, lobe, r)
    return ratio(lobe.ndf(r.h) * g, 4.0 * r.view.z, r.active), r.active & (g > 0)


def lobe_pdf(model: LobeModel, lobe, r: Reflection):
    """Solid-angle density of the reflected direction: the normal density over ``4 o.h``.

    Parameters
    ----------
    model : LobeModel
        Whether sampling draws visible normals.
    lobe : Lobe
        The slope distribution.
    r : Reflection
        The directions.

    Returns
    -------
    Float

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, half_vector, lobe_pdf
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)                     # the view o
    >>> r = half_vector(ctx, si, mi.Vector3f(0, -0.6, 0.8), True)   # lit from the mirror direction
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> pdf = lobe_pdf(LobeModel("ggx"), Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0), r)
    >>> import numpy as np, microfacet as mf
    >>> library = mf.MicrofacetBRDF(mf.GGX(alpha=0.3)).pdf(np.array([0, -0.6, 0.8]), np.array([0, 0.6, 0.8]))
    >>> round(pdf, 5), round(float(library), 5)
    (1.0916, 1.0916)
    """
    return ratio(normal_density(model, lobe, r.h, r.view), 4.0 * r.oh, r.active)


def sample_normal(model: LobeModel, lobe, sample2, view):
    """A normal of the visible normals (Smith, Eq. 2.23) or of the slopes of ``P``.

    Parameters
    ----------
    model : LobeModel
        Whether sampling draws visible normals.
    lobe : Lobe
        The slope distribution.
    sample2 : Point2f
        Two uniform numbers.
    view : Vector3f
        The view ``o``.

    Returns
    -------
    Vector3f
        A unit normal.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, sample_normal
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> lobe = Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0)
    >>> view = mi.Vector3f(0, 0.6, 0.8)
    >>> sample_normal(LobeModel("ggx"), lobe, mi.Point2f(0.5, 0.5), view)   # the median: tilted toward o
    [0, 0.0635378, 0.997979]
    """
    return lobe.sample_visible(sample2, view) if model.samples_visible else lobe.sample_p22(sample2)


def sample_weight(model: LobeModel, lobe, r: Reflection):
    """``eval / pdf`` without Fresnel.

    ``G / G1(o)`` for visible normals (Eq. 2.23), else ``G o.h / (z_o z_h)``.

    Parameters
    ----------
    model : LobeModel
        The GAF and the sampling.
    lobe : Lobe
        The slope distribution.
    r : Reflection
        The sampled reflection (:func:`mirror`).

    Returns
    -------
    Float

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, lobe_pdf, lobe_value, mirror, sample_normal, sample_weight
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> model, lobe, view = LobeModel("ggx"), Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0), mi.Vector3f(0, 0.6, 0.8)
    >>> r = mirror(view, sample_normal(model, lobe, mi.Point2f(0.3, 0.7), view), True)
    >>> w = sample_weight(model, lobe, r)
    >>> bool(abs(w - lobe_value(model, lobe, r)[0] / lobe_pdf(model, lobe, r)) < 1e-5 * w)
    True
    """
    g = geometric_attenuation(model, lobe, r)
    if model.samples_visible:
        g1_o = lobe.g1(r.view)
        return ratio(g, g1_o, g1_o > 0)
    return ratio(g * r.oh, r.view.z * r.h.z, r.active & (r.h.z > 0))


def glossy_sample(wo, pdf, active):
    """The ``mi.BSDFSample3f`` of a glossy reflection toward ``wo`` with density ``pdf``.

    Parameters
    ----------
    wo : Vector3f
        The sampled direction.
    pdf : Float
        Its density (0 where not ``active``).
    active : Bool
        The lanes with a sample.

    Returns
    -------
    mi.BSDFSample3f
        Component 0, ``GlossyReflection``, ``eta = 1``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import glossy_sample
    >>> bs = glossy_sample(mi.Vector3f(0, -0.6, 0.8), 1.5, True)
    >>> bs.pdf, bs.sampled_type == int(mi.BSDFFlags.GlossyReflection), bs.sampled_component
    (1.5, True, 0)
    """
    bs = dr.zeros(mi.BSDFSample3f)
    bs.wo = wo
    bs.pdf = dr.select(active, pdf, 0.0)
    bs.eta = 1.0
    bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
    bs.sampled_component = mi.UInt32(0)
    return bs


def glossy_flags(anisotropic: bool, spatially_varying: bool = False):
    """The BSDF flags of a glossy lobe: ``GlossyReflection | FrontSide``.

    Parameters
    ----------
    anisotropic : bool
        Add ``Anisotropic``.
    spatially_varying : bool, optional
        Add ``SpatiallyVarying`` (and ``NeedsDifferentials`` where Mitsuba has it), for the
        footprint plugins.

    Returns
    -------
    mi.BSDFFlags

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import glossy_flags
    >>> F = mi.BSDFFlags
    >>> glossy_flags(False) == F.GlossyReflection | F.FrontSide
    True
    >>> bool(glossy_flags(True) & F.Anisotropic), bool(glossy_flags(True, True) & F.SpatiallyVarying)
    (True, True)
    """
    flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
    if anisotropic:
        flags = flags | mi.BSDFFlags.Anisotropic
    if spatially_varying:
        flags = flags | mi.BSDFFlags.SpatiallyVarying
        if hasattr(mi.BSDFFlags, "NeedsDifferentials"):      # Mitsuba 0.6; 3.x has no such flag
            flags = flags | mi.BSDFFlags.NeedsDifferentials
    return flags


# ------------------------------------------------------------------ the shared lobe
class MicrofacetLobe:
    """``f_r cos theta_i = F D G / (4 z_o)`` and its sampler (Listing 2.2, Sec. 2.2, 3.2).

    For a plugin that supplies ``self.model`` (a :class:`LobeModel`), :meth:`lobe` (the slope
    distribution at ``si``) and :meth:`fresnel` (``F(o.h)`` at ``si``).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import LobeModel, MicrofacetLobe
    >>> from microfacet.mitsuba.slopes import Lobe
    >>> class Gold(MicrofacetLobe):                       # a constant GGX lobe, F = 1
    ...     model = LobeModel("ggx")
    ...     def lobe(self, si, active):
    ...         return Lobe("ggx", 0.3, 0.3, 0.0, 0.0, 0.0)
    ...     def fresnel(self, si, oh, active):
    ...         return mi.Color3f(1.0)
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> value, pdf = Gold().lobe_eval_pdf(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1), True)
    >>> round(value[0], 4), round(pdf, 4)                  # D(n) / 4 = 1 / (4 pi alpha^2)
    (0.8842, 0.8842)
    """

    model: LobeModel

    def lobe(self, si, active):
        """The slope distribution at the shading point (implemented by each plugin).

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            The shading point (its uv, differentials and ``wi``).
        active : Bool
            The lanes to compute.

        Returns
        -------
        Lobe
            A :class:`microfacet.mitsuba.slopes.Lobe` (per lane).
        """
        raise NotImplementedError

    def fresnel(self, si, oh, active):
        """The Fresnel term times the specular reflectance (implemented by each plugin).

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            The shading point (for textured parameters).
        oh : Float
            ``cos theta_d = o.h`` per lane.
        active : Bool
            The lanes to compute.

        Returns
        -------
        Spectrum
            ``F(o.h)`` per lane.
        """
        raise NotImplementedError

    def lobe_eval_pdf(self, ctx, si, light, active, want_value=True, want_pdf=True):
        """``(f_r cos theta_i, pdf)`` toward ``light`` (either ``None`` when not wanted).

        Parameters
        ----------
        ctx : mi.BSDFContext
            The context.
        si : mi.SurfaceInteraction3f
            The view is ``si.wi``.
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
        """
        r = half_vector(ctx, si, light, active)
        lobe = self.lobe(si, r.active)
        value = pdf = None
        if want_value:
            s, ok = lobe_value(self.model, lobe, r)
            value = dr.select(ok, self.fresnel(si, r.oh, r.active) * s, 0.0)
        if want_pdf:
            pdf = lobe_pdf(self.model, lobe, r)
        return value, pdf

    def lobe_sample(self, ctx, si, sample2, active):
        """``(BSDFSample3f, weight)``: the view reflected about a sampled normal (Sec. 2.2, 3.2).

        The weight is ``F`` times :func:`sample_weight`.

        Parameters
        ----------
        ctx : mi.BSDFContext
            The context.
        si : mi.SurfaceInteraction3f
            The view is ``si.wi``.
        sample2 : Point2f
            Two uniform numbers.
        active : Bool
            The active lanes.

        Returns
        -------
        bs : mi.BSDFSample3f
        weight : Spectrum
        """
        active = reflecting(ctx, si, active)
        lobe = self.lobe(si, active)
        r = mirror(si.wi, sample_normal(self.model, lobe, sample2, si.wi), active)
        weight = sample_weight(self.model, lobe, r)
        pdf = lobe_pdf(self.model, lobe, r)
        ok = r.active & (pdf > 0)
        return glossy_sample(r.light, pdf, ok), dr.select(ok, self.fresnel(si, r.oh, ok) * weight, 0.0)


# ------------------------------------------------------------------ the plugin
class MicrofacetBSDF(MicrofacetLobe):
    """The noncentral microfacet BRDF of :class:`microfacet.MicrofacetBRDF`:
    ``f_r cos theta_i = F(o.h) D(h) G(i, o) / (4 z_o)`` with a Beckmann or GGX slope
    distribution under the slope map of Eq. 3.4 (anisotropic, correlated, sheared), the
    library's GAF and its sampler (visible normals for Smith). Parameters of type texture
    may be textures; without a Fresnel parameter F = 1. ``mi.traverse``
    exposes ``alpha`` (or ``alpha_u``, ``alpha_v``), ``rho``, ``mean_slope_u``,
    ``mean_slope_v``, ``specular_reflectance`` and the Fresnel textures.

    | name | type | default | meaning |
    |---|---|---|---|
    | `distribution` | string | `beckmann` | standard slope distribution: `beckmann` or `ggx` |
    | `alpha` | float or texture | 0.1 | isotropic roughness (> 0; textured values clamped to >= 1e-4) |
    | `alpha_u` | float or texture | 0.1 | roughness along u, with `alpha_v` (instead of `alpha`) |
    | `alpha_v` | float or texture | 0.1 | roughness along v, with `alpha_u` |
    | `rho` | float or texture | 0 | slope correlation in (-1, 1) (textured values clamped to +-0.9999) |
    | `mean_slope_u` | float or texture | 0 | mean slope along u of the sheared (noncentral) lobe |
    | `mean_slope_v` | float or texture | 0 | mean slope along v |
    | `gaf` | string | `smith` | `smith` (height-correlated, sheared normalization), `vgroove` or `normal_map` |
    | `shadowing` | boolean | `true` | `false`: masking only |
    | `separable` | boolean | `false` | `true`: Smith `G1(i) G1(o)` as `roughconductor` (gaf=smith only) |
    | `material` | string | `none` | conductor of Mitsuba's IOR database (`Au`, `Cu`, ...); `none`: F = 1 |
    | `eta` | float or texture | 0 | real part of a conductor's index (with `k`) |
    | `k` | float or texture | 1 | imaginary part of a conductor's index (with `eta`) |
    | `int_ior` | float or string | 1.5046 | interior index of a dielectric Fresnel term (or a name, e.g. `bk7`) |
    | `ext_ior` | float or string | 1.000277 | exterior index of a dielectric Fresnel term (or a name, e.g. `air`) |
    | `schlick_f0` | float or texture | 0.04 | reflectance at normal incidence of Schlick's approximation |
    | `schlick_f90` | float or texture | 1 | reflectance at grazing incidence of Schlick's approximation |
    | `specular_reflectance` | float or texture | 1 | factor on the whole BRDF |

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters (table above).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> bsdf = mfm.load_dict({"type": "mf_microfacet", "distribution": "ggx", "alpha_u": 0.2,
    ...                       "alpha_v": 0.4, "rho": 0.3, "mean_slope_u": 0.1, "material": "Cu"})
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)
    >>> ctx = mi.BSDFContext()
    >>> bs, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.3, 0.6))
    >>> value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    >>> bool(abs(pdf - bs.pdf) < 1e-5 * pdf and abs(weight[0] - value[0] / pdf) < 1e-4 * weight[0])
    True
    >>> sorted(mi.traverse(bsdf).keys())[:3]
    ['alpha_u.value', 'alpha_v.value', 'eta.value']
    """

    PLUGIN_NAME = PLUGIN

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.params = read_microfacet_params(props, PLUGIN)
        self.model = self.params.model
        flags = glossy_flags(self.params.anisotropic)
        self.m_components = [flags]
        self.m_flags = flags

    def lobe(self, si, active):
        return roughness_lobe(self.model.kind, self.params.roughness, si, active)

    def fresnel(self, si, oh, active):
        return fresnel_term(self.params.fresnel, si, oh, active)

    # ------------------------------------------------------ Mitsuba API
    def eval(self, ctx, si, wo, active=True):
        """``f_r cos theta_i = F D G / (4 z_o)`` (Listing 2.2); ``wo`` is the light."""
        return self.lobe_eval_pdf(ctx, si, wo, active, want_pdf=False)[0]

    def pdf(self, ctx, si, wo, active=True):
        """Solid-angle density of :meth:`sample`: normal density over ``4 o.h``."""
        return self.lobe_eval_pdf(ctx, si, wo, active, want_value=False)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.lobe_eval_pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        """Reflect the view about a sampled normal (Sec. 2.2, 3.2); the Smith weight is
        ``F G / G1(o)`` (Eq. 2.23), the others' ``F G o.h / (z_o z_h)``."""
        return self.lobe_sample(ctx, si, sample2, active)

    def traverse(self, callback):
        r, f = self.params.roughness, self.params.fresnel
        lobe = mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous
        if r.isotropic:
            callback.put("alpha", r.alpha_u, lobe)
        else:
            callback.put("alpha_u", r.alpha_u, lobe)
            callback.put("alpha_v", r.alpha_v, lobe)
        callback.put("rho", r.rho, lobe)
        callback.put("mean_slope_u", r.mean_slope_u, lobe)
        callback.put("mean_slope_v", r.mean_slope_v, lobe)
        callback.put("specular_reflectance", f.specular_reflectance, mi.ParamFlags.Differentiable)
        if f.kind == "conductor":
            callback.put("eta", f.eta, mi.ParamFlags.Differentiable)
            callback.put("k", f.k, mi.ParamFlags.Differentiable)
        elif f.kind == "schlick":
            callback.put("schlick_f0", f.f0, mi.ParamFlags.Differentiable)
            callback.put("schlick_f90", f.f90, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        m = self.model
        return (f"MicrofacetBSDF[{PLUGIN}, distribution={m.kind}, gaf={m.gaf}, shadowing={m.shadowing}, "
                f"separable={m.separable}, fresnel={self.params.fresnel.kind}]")


def bsdf_class() -> type:
    """The ``mf_microfacet`` class of the current Mitsuba variant (:func:`.registry.variant_class`).

    Returns
    -------
    type
        A subclass of the variant's ``mi.BSDF``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.bsdf import bsdf_class
    >>> cls = bsdf_class()
    >>> issubclass(cls, mi.BSDF), cls.__name__
    (True, 'MicrofacetBSDF')
    >>> cls(mi.Properties("mf_microfacet"))           # doctest: +ELLIPSIS
    MicrofacetBSDF[mf_microfacet, distribution=beckmann, ...]
    """
    return variant_class(MicrofacetBSDF)
