"""``mf_fitted``: a fit of :mod:`microfacet.fit` (the ``.npz`` of ``microfacet fit``) as a
Mitsuba 3 BSDF plugin.

``use`` names the fit to render among those the file keeps (:func:`microfacet.fit.fit_names`):
``"best"`` (default: the fit ``microfacet fit`` chose by image error; the tabulated fit in
files that keep only it), ``"tabulated"``, or any analytic fit of the file (``"lobe"``,
``"two_lobes"``, ``"coat"``, ``"ggx"``, ...). An unknown name gives a one-line error listing
the file's names.

* An analytic fit (``microfacet.fit.load(path, model=use)``: a tree of ``MicrofacetBRDF``,
  ``Lambertian``, ``SumBRDF`` and ``LayeredBRDF``) renders through
  :mod:`microfacet.mitsuba.tree` (``mf_microfacet``'s lobe code with the fit's Fresnel term,
  the library's coat tables): ``eval`` and ``pdf`` equal the library's.
* ``use="tabulated"`` renders :class:`microfacet.fit.FittedBRDF` itself:
  ``f_r cos theta_i = F D G / (4 z_o) + k_d z_i / pi`` (Eq. 2.1, 1.9) with the tabulated
  ``D`` and ``Lambda`` of :mod:`microfacet.mitsuba.tabulated`, the fit's Fresnel table
  (piecewise linear in ``cos theta_d``), GAF and shadowing, and the fit's sampling
  (visible normals for isotropic Smith fits, slopes of ``P`` otherwise; with a diffuse
  base, the lobe or the cosine lobe with probability ``luminance(F(1))`` over
  ``luminance(F(1)) + luminance(k_d)``, pdf the mixture's).
* ``use="ggx"|"beckmann"`` in a file that keeps no fit of that name (files of
  :meth:`FittedBRDF.save`) renders :meth:`FittedBRDF.to_ggx` / :meth:`FittedBRDF.to_beckmann`
  (App. C, with the Fresnel table solved for the converted NDF; the diffuse base is not
  carried, as in the library) through ``mf_microfacet``'s analytic lobe.

The lobe code (GAF, eval, pdf, sample) is ``mf_microfacet``'s (:mod:`.bsdf`).
"""
from __future__ import annotations

import functools
import operator
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MicrofacetError
from ..fit import fit_names
from ..fit import load as load_fit
from ..io.exr import EXR_MAGIC
from . import properties
from .bsdf import FresnelParams, LobeModel, MicrofacetBSDF, fresnel_term, glossy_flags, glossy_sample
from .registry import variant_class
from .slopes import BECKMANN, GGX, Lobe
from .tabulated import InterpolatedColor, tabulated_lobe
from .tree import component_of

__all__ = ["PLUGIN", "bsdf_class", "load_fit_parameter", "fit_path_parameter", "choose_fit", "USES", "FittedBSDF",
           "FittedParams", "FitLobe", "read_fitted_params", "fitted_components", "tree_eval_pdf", "tree_sample",
           "diffuse_base"]

PLUGIN = "mf_fitted"
#: ``use`` values every fit file answers (besides the names of its analytic fits).
USES = ("best", "tabulated", GGX, BECKMANN)


def fit_path_parameter(props, name: str, plugin: str) -> str:
    """The path of the fit file named by a string parameter, resolved by Mitsuba's file resolver.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter (``filename``, or ``mf_leadr``'s ``fit``).
    plugin : str
        The plugin named in errors.

    Returns
    -------
    str

    Raises
    ------
    PluginParameterError
        Naming the parameter when it is missing or not a string.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> props = mi.Properties("mf_fitted")
    >>> props["filename"] = "fit.npz"
    >>> from microfacet.mitsuba.fitted import fit_path_parameter
    >>> fit_path_parameter(props, "filename", "mf_fitted").endswith("fit.npz")
    True
    >>> fit_path_parameter(props, "fit", "mf_leadr")
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_leadr: parameter 'fit' is required: the .npz written by `microfacet fit`
    """
    if name not in props or props.type(name) != mi.Properties.Type.String:
        raise properties.parameter_error(name, "is required: the .npz written by `microfacet fit`", plugin)
    return str(mi.file_resolver().resolve(props[name]))


def load_fit_parameter(props, name: str, plugin: str):
    """The :class:`~microfacet.fit.FittedBRDF` of the file named by a string parameter.

    The path is resolved by Mitsuba's file resolver (:func:`fit_path_parameter`).

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter.
    plugin : str
        The plugin named in errors.

    Returns
    -------
    microfacet.fit.FittedBRDF

    Raises
    ------
    PluginParameterError
        Naming the parameter and the file when it is missing, not a fit (e.g. a LEADR pyramid
        EXR) or corrupt.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")                       # a tabulated fit, as `microfacet fit` writes
    >>> props = mi.Properties("mf_fitted")
    >>> props["filename"] = "fit.npz"
    >>> from microfacet.mitsuba.fitted import load_fit_parameter
    >>> load_fit_parameter(props, "filename", "mf_fitted")          # doctest: +ELLIPSIS
    FittedBRDF(TabulatedIsotropic(n=31, ...), gaf='smith', f0=0.5003)
    """
    path = fit_path_parameter(props, name, plugin)
    try:
        with open(path, "rb") as f:
            head = f.read(len(EXR_MAGIC))
    except OSError as e:
        raise properties.parameter_error(name, f"cannot read {path!r} ({e.strerror or e})", plugin) from None
    if head == EXR_MAGIC:
        raise properties.parameter_error(name, f"{path!r} is an OpenEXR file (a LEADR pyramid? use mf_leadr), "
                                 "not a fit .npz of `microfacet fit`", plugin)
    try:
        return load_fit(path)
    except MicrofacetError as e:
        raise properties.parameter_error(name, f"is not usable: {e}", plugin) from None


def choose_fit(path: str, use: str, plugin: str = PLUGIN):
    """The fit ``use`` of a fit file (module docstring).

    Parameters
    ----------
    path : str
        The fit file.
    use : str
        ``"best"``, ``"tabulated"``, the name of an analytic fit of the file, or
        ``"ggx"``/``"beckmann"`` (:data:`USES`).
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    name : str
        The fit chosen (``best`` resolved).
    brdf : object or None
        The analytic BRDF tree of ``microfacet.fit.load(path, model=name)``, or ``None`` for
        the tabulated fit and the legacy ``ggx``/``beckmann`` conversions.

    Raises
    ------
    PluginParameterError
        Naming ``use`` and listing the file's fits for an unknown name.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")                       # a tabulated fit, as `microfacet fit` writes
    >>> from microfacet.mitsuba.fitted import USES, choose_fit
    >>> USES
    ('best', 'tabulated', 'ggx', 'beckmann')
    >>> choose_fit("fit.npz", "best"), choose_fit("fit.npz", "ggx")
    (('tabulated', None), ('ggx', None))
    >>> choose_fit("fit.npz", "coat")
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_fitted: parameter 'use' must name a fit of 'fit.npz': one of best, tabulated, got 'coat'
    """
    try:
        names, best = fit_names(path)
    except MicrofacetError as e:
        raise properties.parameter_error("filename", f"is not usable: {e}", plugin) from None
    name = best if use == "best" else use
    if name == "tabulated" or (name in (GGX, BECKMANN) and name not in names):
        return name, None
    if name not in names:
        raise properties.parameter_error("use", f"must name a fit of {path!r}: one of {', '.join(['best', *names])}, "
                                  f"got {use!r}", plugin)
    try:
        return name, load_fit(path, model=name)
    except MicrofacetError as e:
        raise properties.parameter_error("use", f"cannot load the fit {name!r}: {e}", plugin) from None


@dataclass(frozen=True)
class FitLobe:
    """A fit rendered by the shared lobe code: the tabulated fit or a ``ggx``/``beckmann``
    conversion (module docstring).

    Its :class:`~.bsdf.LobeModel`, Fresnel table, lobe factory (``make_lobe() -> Lobe``),
    Lambertian base texture (or ``None``) with the probability ``p_lobe`` of sampling the lobe,
    and whether the lobe is anisotropic.

    Attributes
    ----------
    model : LobeModel
        What the lobe computes.
    fresnel : FresnelParams
        The fit's Fresnel table.
    make_lobe : callable
        ``make_lobe() -> Lobe``: the lobe factory.
    diffuse : texture or None
        The Lambertian base's reflectance, or ``None``.
    p_lobe : float
        Probability of sampling the lobe (else the base).
    anisotropic : bool
        Whether the lobe is anisotropic.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")                       # a tabulated fit, as `microfacet fit` writes
    >>> props = mi.Properties("mf_fitted")
    >>> props["filename"] = "fit.npz"
    >>> from microfacet.mitsuba.fitted import FitLobe, read_fitted_params
    >>> lobe = read_fitted_params(props).lobe
    >>> isinstance(lobe, FitLobe), lobe.model.kind, lobe.fresnel.kind, lobe.diffuse, lobe.p_lobe
    (True, 'tabulated', 'table', None, 1.0)
    """
    model: LobeModel
    fresnel: FresnelParams
    make_lobe: object
    diffuse: object
    p_lobe: float
    anisotropic: bool


@dataclass(frozen=True)
class FittedParams:
    """All parameters of ``mf_fitted`` (:func:`read_fitted_params`).

    The file, the fit it renders (``use``), ``specular_reflectance`` and either the analytic
    fit's BRDF ``tree`` with its :mod:`.tree` component ``root``, or a :class:`FitLobe`.

    Attributes
    ----------
    filename : str
        The fit's ``.npz``.
    use : str
        The fit rendered.
    specular_reflectance : texture
        Factor on the BRDF.
    tree : BRDF, optional
        The analytic fit's BRDF tree (``None`` for a lobe).
    root : optional
        Its :mod:`.tree` component.
    lobe : FitLobe, optional
        The tabulated fit or conversion (``None`` for a tree).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")                       # a tabulated fit, as `microfacet fit` writes
    >>> props = mi.Properties("mf_fitted")
    >>> props["filename"] = "fit.npz"
    >>> from microfacet.mitsuba.fitted import read_fitted_params
    >>> props["use"] = "beckmann"                  # the moment conversion (App. C)
    >>> p = read_fitted_params(props)
    >>> p.use, p.tree, p.lobe.model.kind
    ('beckmann', None, 'beckmann')
    """
    filename: str
    use: str
    specular_reflectance: object
    tree: object = None
    root: object = None
    lobe: FitLobe | None = None


def _is_anisotropic(fit, dist) -> bool:
    return bool(fit.anisotropic or float(dist.alpha_x) != float(dist.alpha_y)
                or np.any(np.asarray(dist.rho) != 0) or np.any(np.asarray(dist.mean_slope) != 0))


def _fit_lobe(fit, use: str, reflectance) -> FitLobe:
    """The :class:`FitLobe` of ``use="tabulated"`` (the fit's tables, sampling and diffuse
    base) or of the moment conversion ``use="ggx"|"beckmann"`` (App. C, no diffuse base)."""
    diffuse, p_lobe = None, 1.0
    if use == "tabulated":
        dist, fresnel = fit.distribution, fit.fresnel
        model = LobeModel("tabulated", fit.gaf_model, fit.shadowing, False,
                          fit.gaf_model == "smith" and dist.supports_visible_sampling)
        make_lobe = tabulated_lobe(dist)
        if fit.has_diffuse:
            diffuse = mi.load_dict({"type": "srgb", "color": [float(v) for v in fit.diffuse], "unbounded": True})
            p_lobe = float(fit.lobe_probability)
    else:
        converted = fit.to_ggx() if use == GGX else fit.to_beckmann()
        dist, fresnel = converted.distribution, converted.fresnel
        model = LobeModel(use, fit.gaf_model, fit.shadowing, False, fit.gaf_model == "smith")
        params = [mi.Float(float(v)) for v in (dist.alpha_x, dist.alpha_y, dist.rho, dist.xn, dist.yn)]
        make_lobe = functools.partial(Lobe, use, *params)
    table = FresnelParams("table", reflectance, table=InterpolatedColor(fresnel.cos_theta_d, fresnel.values))
    return FitLobe(model, table, make_lobe, diffuse, p_lobe, _is_anisotropic(fit, dist))


def read_fitted_params(props) -> FittedParams:
    """All parameters of ``mf_fitted`` (class docstring of :class:`FittedBSDF`), checked.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.

    Returns
    -------
    FittedParams

    Raises
    ------
    PluginParameterError
        Naming the parameter (and the file) that is unusable.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")                       # a tabulated fit, as `microfacet fit` writes
    >>> props = mi.Properties("mf_fitted")
    >>> props["filename"] = "fit.npz"
    >>> from microfacet.mitsuba.fitted import read_fitted_params
    >>> p = read_fitted_params(props)
    >>> p.filename, p.use, p.lobe.model.gaf
    ('fit.npz', 'tabulated', 'smith')
    """
    fit = load_fit_parameter(props, "filename", PLUGIN)
    use = props.get("use", "best") if "use" in props else "best"
    if not isinstance(use, str):
        raise properties.parameter_error("use", f"must be the name of a fit, got {use!r}", PLUGIN)
    use, tree = choose_fit(fit_path_parameter(props, "filename", PLUGIN), use)
    reflectance = properties.texture(props, "specular_reflectance", 1.0, plugin=PLUGIN)
    if tree is not None:
        return FittedParams(props["filename"], use, reflectance, tree=tree, root=component_of(tree))
    return FittedParams(props["filename"], use, reflectance, lobe=_fit_lobe(fit, use, reflectance))


def fitted_components(params: FittedParams) -> list:
    """Mitsuba's component flags of ``mf_fitted``.

    One glossy component (``| DiffuseReflection`` for an analytic fit with a diffuse part),
    plus a diffuse one for a tabulated fit's base.

    Parameters
    ----------
    params : FittedParams
        The plugin's parameters.

    Returns
    -------
    list of mi.BSDFFlags

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.fit import SumBRDF
    >>> from microfacet.mitsuba.tree import component_of
    >>> from microfacet.mitsuba.fitted import FittedParams
    >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), mf.Lambertian(0.5))
    >>> one = mi.load_dict({"type": "uniform", "value": 1.0})
    >>> params = FittedParams("fit.npz", "two_lobes", one, tree=brdf, root=component_of(brdf))
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> from microfacet.mitsuba.fitted import fitted_components
    >>> [bool(c & mi.BSDFFlags.DiffuseReflection) for c in fitted_components(params)]
    [True]
    """
    if params.lobe is None:
        flags = glossy_flags(anisotropic=False)
        return [flags | mi.BSDFFlags.DiffuseReflection if params.root.diffuse else flags]
    glossy = glossy_flags(params.lobe.anisotropic)
    if params.lobe.diffuse is None:
        return [glossy]
    return [glossy, mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide]


def tree_eval_pdf(params: FittedParams, ctx, si, light, active):
    """``(f cos theta_i, pdf)`` of an analytic fit, times ``specular_reflectance``.

    Parameters
    ----------
    params : FittedParams
        With the fit's ``root`` component.
    ctx : mi.BSDFContext
        The context.
    si : mi.SurfaceInteraction3f
        The view is ``si.wi``.
    light : Vector3f
        The light ``i``.
    active : Bool
        The active lanes.

    Returns
    -------
    value : Spectrum
    pdf : Float

    Examples
    --------
    A GGX lobe plus a Lambertian base (equal sampling weights), seen and lit from the normal:
    ``1 / (4 pi alpha^2) + 0.5 / pi``.

    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.fit import SumBRDF
    >>> from microfacet.mitsuba.tree import component_of
    >>> from microfacet.mitsuba.fitted import FittedParams
    >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), mf.Lambertian(0.5))
    >>> one = mi.load_dict({"type": "uniform", "value": 1.0})
    >>> params = FittedParams("fit.npz", "two_lobes", one, tree=brdf, root=component_of(brdf))
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> from microfacet.mitsuba.fitted import tree_eval_pdf
    >>> value, pdf = tree_eval_pdf(params, ctx, si, mi.Vector3f(0, 0, 1), True)
    >>> round(value[0], 3), round(1 / (4 * 3.14159265 * 0.09) + 0.5 / 3.14159265, 3)
    (1.043, 1.043)
    """
    active = active & (si.wi.z > 0) & (light.z > 0)
    value, pdf = params.root.eval_pdf(ctx, si, light, active)
    value = value * params.specular_reflectance.eval(si, active)
    return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)


def tree_sample(params: FittedParams, ctx, si, sample1, sample2, active):
    """The analytic fit's mixture sampler; weight ``eval / pdf``.

    Parameters
    ----------
    params : FittedParams
        With the fit's ``root`` component.
    ctx : mi.BSDFContext
        The context.
    si : mi.SurfaceInteraction3f
        The view is ``si.wi``.
    sample1 : Float
        Chooses the part.
    sample2 : Point2f
        Samples the part.
    active : Bool
        The active lanes.

    Returns
    -------
    bs : mi.BSDFSample3f
    weight : Spectrum

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.fit import SumBRDF
    >>> from microfacet.mitsuba.tree import component_of
    >>> from microfacet.mitsuba.fitted import FittedParams
    >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), mf.Lambertian(0.5))
    >>> one = mi.load_dict({"type": "uniform", "value": 1.0})
    >>> params = FittedParams("fit.npz", "two_lobes", one, tree=brdf, root=component_of(brdf))
    >>> ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> from microfacet.mitsuba.fitted import tree_eval_pdf, tree_sample
    >>> bs, weight = tree_sample(params, ctx, si, 0.7, mi.Point2f(0.2, 0.4), True)
    >>> value, pdf = tree_eval_pdf(params, ctx, si, bs.wo, True)
    >>> bool(abs(weight[0] - value[0] / pdf) < 1e-5 * weight[0])
    True
    """
    active = active & (si.wi.z > 0)
    light, ok = params.root.sample(ctx, si, sample1, sample2, active)
    value, pdf = tree_eval_pdf(params, ctx, si, light, active & ok)
    ok = active & ok & (pdf > 0) & (light.z > 0)
    return glossy_sample(light, pdf, ok), dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)


def diffuse_base(diffuse, ctx, si, light, active):
    """``(k_d z_i / pi, z_i / pi)`` of the Lambertian base (Eq. 1.9), 0 below the horizons.

    Parameters
    ----------
    diffuse : mi.Texture
        The base's reflectance ``k_d``.
    ctx : mi.BSDFContext
        The context (component 1 must be enabled).
    si : mi.SurfaceInteraction3f
        The view is ``si.wi``.
    light : Vector3f
        The light ``i``.
    active : Bool
        The active lanes.

    Returns
    -------
    value : Spectrum
    pdf : Float
        The cosine-weighted density.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.fitted import diffuse_base
    >>> kd = mi.load_dict({"type": "srgb", "color": [0.5, 0.25, 0.125]})
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> value, pdf = diffuse_base(kd, mi.BSDFContext(), si, mi.Vector3f(0.6, 0, 0.8), True)
    >>> round(pdf, 6), round(0.8 / 3.14159265, 6)
    (0.254648, 0.254648)
    """
    ok = active & (si.wi.z > 0) & (light.z > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1)
    cos_pdf = dr.select(ok, light.z * (1.0 / dr.pi), 0.0)
    return diffuse.eval(si, ok) * cos_pdf, cos_pdf


def _mixture_sample(bs, lobe: FitLobe, eval_pdf, si, sample1, sample2, active):
    """The lobe's sample ``bs`` or a cosine-lobe direction, chosen by ``sample1 < p_lobe``;
    weight and pdf the mixture's (``eval_pdf(light) -> (value, pdf)``)."""
    chose_lobe = sample1 < lobe.p_lobe
    light = dr.select(chose_lobe, bs.wo, mi.warp.square_to_cosine_hemisphere(sample2))
    value, pdf = eval_pdf(light)
    ok = active & (pdf > 0) & (si.wi.z > 0) & (light.z > 0)
    bs.wo = light
    bs.pdf = dr.select(ok, pdf, 0.0)
    bs.sampled_type = dr.select(chose_lobe, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
    bs.sampled_component = dr.select(chose_lobe, mi.UInt32(0), mi.UInt32(1))
    return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)


class FittedBSDF(MicrofacetBSDF):
    """A fit of ``microfacet fit`` (its ``.npz``): an analytic fit through its BRDF tree
    (``eval`` and ``pdf`` equal the library's), the tabulated fit with its tables, Fresnel
    table, sampling and Lambertian base, or the ``ggx`` / ``beckmann`` moment conversions of
    files that keep no such fit. ``mi.traverse`` exposes ``specular_reflectance``.

    | name | type | default | meaning |
    |---|---|---|---|
    | `filename` | string | required | the `.npz` of `microfacet fit` (format versions 1 and 2) |
    | `use` | string | `best` | the fit to render: `best` (chosen by image error), `tabulated`, an analytic fit of the file, or the `ggx` / `beckmann` conversions |
    | `specular_reflectance` | float or texture | 1 | factor on the BRDF |

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters (table above).

    Examples
    --------
    The tabulated fit's value equals the library's ``f_r cos theta_i``:

    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)), 16)
    >>> path = fit.save("fit.npz")
    >>> bsdf = mfm.load_dict({"type": "mf_fitted", "filename": "fit.npz", "use": "tabulated"})
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0.6, 0.8)
    >>> value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.48, -0.36, 0.8))
    >>> library = fit.eval(np.array([0.48, -0.36, 0.8]), np.array([0.0, 0.6, 0.8])) * 0.8
    >>> bool(np.allclose(np.array(value), library, rtol=1e-4))
    True
    """

    PLUGIN_NAME = PLUGIN

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.params = read_fitted_params(props)
        self.model = None if self.params.lobe is None else self.params.lobe.model
        self.m_components = fitted_components(self.params)
        self.m_flags = functools.reduce(operator.or_, self.m_components)

    def lobe(self, si, active):
        return self.params.lobe.make_lobe()

    def fresnel(self, si, oh, active):
        """The fit's Fresnel table ``F(o.h)`` (Eq. 4.11), times ``specular_reflectance``.

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            The shading point (for a textured ``specular_reflectance``).
        oh : Float
            ``cos theta_d = o.h`` per lane.
        active : Bool
            The lanes to compute.

        Returns
        -------
        Spectrum
            ``F(o.h)`` per lane.
        """
        return fresnel_term(self.params.lobe.fresnel, si, oh, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        """The lobe (Listing 2.2) plus the base; pdf ``p pdf_lobe + (1 - p) z_i / pi``; an
        analytic fit's own ``eval_pdf``."""
        p = self.params
        if p.root is not None:
            return tree_eval_pdf(p, ctx, si, wo, active)
        value, pdf = self.lobe_eval_pdf(ctx, si, wo, active)
        if p.lobe.diffuse is None:
            return value, pdf
        value_d, pdf_d = diffuse_base(p.lobe.diffuse, ctx, si, wo, active)
        return value + value_d, p.lobe.p_lobe * pdf + (1.0 - p.lobe.p_lobe) * pdf_d

    def eval(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[1]

    def sample(self, ctx, si, sample1, sample2, active=True):
        """The lobe's sample (``mf_microfacet``), or, with a base, the lobe or the cosine
        lobe chosen by ``sample1 < p``; the weight is then the mixture's ``eval / pdf``. An
        analytic fit: its tree's mixture sampler, weight ``eval / pdf``."""
        p = self.params
        if p.root is not None:
            return tree_sample(p, ctx, si, sample1, sample2, active)
        bs, weight = self.lobe_sample(ctx, si, sample2, active)
        if p.lobe.diffuse is None:
            return bs, weight
        return _mixture_sample(bs, p.lobe, lambda light: self.eval_pdf(ctx, si, light, active),
                               si, sample1, sample2, active)

    def traverse(self, callback):
        callback.put("specular_reflectance", self.params.specular_reflectance, mi.ParamFlags.Differentiable)

    def to_string(self):
        p = self.params
        if p.root is not None:
            return f"FittedBSDF[{PLUGIN}, filename={p.filename!r}, use={p.use}, fit={p.tree!r}]"
        return (f"FittedBSDF[{PLUGIN}, filename={p.filename!r}, use={p.use}, gaf={p.lobe.model.gaf}, "
                f"shadowing={p.lobe.model.shadowing}, diffuse={p.lobe.diffuse is not None}]")


def bsdf_class() -> type:
    """The ``mf_fitted`` class of the current Mitsuba variant (:func:`.registry.variant_class`).

    Returns
    -------
    type
        A subclass of the variant's ``mi.BSDF``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.fitted import PLUGIN, bsdf_class
    >>> PLUGIN, issubclass(bsdf_class(), mi.BSDF)
    ('mf_fitted', True)
    """
    return variant_class(FittedBSDF)
