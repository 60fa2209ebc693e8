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
    """The path of the fit file named by string parameter ``name``, resolved by Mitsuba's file
    resolver; a one-line ``ValueError`` naming the parameter when it is missing."""
    if name not in props or props.type(name) != mi.Properties.Type.String:
        raise properties.parameter_error(name, "is required: the .npz written by `microfacet fit`", plugin)
    return str(mi.file_resolver().resolve(props[name]))


def load_fit_parameter(props, name: str, plugin: str):
    """The :class:`~microfacet.fit.FittedBRDF` of the file named by string parameter ``name``
    (resolved by Mitsuba's file resolver); a one-line ``ValueError`` naming the parameter
    and the file when it is missing, not a fit (e.g. a LEADR pyramid EXR) or corrupt."""
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
    """``(name, brdf)``: the fit ``use`` of the fit file ``path`` (module docstring): ``brdf`` the
    analytic BRDF tree of ``microfacet.fit.load(path, model=name)``, or ``None`` for the
    tabulated fit and the legacy ``ggx``/``beckmann`` conversions (``name`` says which). A
    one-line ``ValueError`` naming ``use`` and listing the file's fits for an unknown name."""
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
    conversion (module docstring): its :class:`LobeModel`, Fresnel table, lobe factory
    (``make_lobe() -> Lobe``), Lambertian base texture (or ``None``) with the probability
    ``p_lobe`` of sampling the lobe, and whether the lobe is anisotropic."""
    model: LobeModel
    fresnel: FresnelParams
    make_lobe: object
    diffuse: object
    p_lobe: float
    anisotropic: bool


@dataclass(frozen=True)
class FittedParams:
    """All parameters of ``mf_fitted`` (:func:`read_fitted_params`): the file, the fit it
    renders (``use``), ``specular_reflectance`` and either the analytic fit's BRDF ``tree``
    with its :mod:`.tree` component ``root``, or a :class:`FitLobe`."""
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
    """All parameters of ``mf_fitted`` (class docstring of :class:`FittedBSDF`), checked."""
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
    """Mitsuba's component flags: one glossy component (``| DiffuseReflection`` for an
    analytic fit with a diffuse part), plus a diffuse one for a tabulated fit's base."""
    if params.lobe is None:
        flags = glossy_flags(anisotropic=False)
        return [flags | mi.BSDFFlags.DiffuseReflection if params.root.diffuse else flags]
    glossy = glossy_flags(params.lobe.anisotropic)
    if params.lobe.diffuse is None:
        return [glossy]
    return [glossy, mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide]


def tree_eval_pdf(params: FittedParams, ctx, si, light, active):
    """``(f cos theta_i, pdf)`` of the analytic fit, times ``specular_reflectance``."""
    active = active & (si.wi.z > 0) & (light.z > 0)
    value, pdf = params.root.eval_pdf(ctx, si, light, active)
    value = value * params.specular_reflectance.eval(si, active)
    return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)


def tree_sample(params: FittedParams, ctx, si, sample1, sample2, active):
    """The analytic fit's mixture sampler; weight ``eval / pdf``."""
    active = active & (si.wi.z > 0)
    light, ok = params.root.sample(ctx, si, sample1, sample2, active)
    value, pdf = tree_eval_pdf(params, ctx, si, light, active & ok)
    ok = active & ok & (pdf > 0) & (light.z > 0)
    return glossy_sample(light, pdf, ok), dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)


def diffuse_base(diffuse, ctx, si, light, active):
    """``(k_d z_i / pi, z_i / pi)`` of the Lambertian base (Eq. 1.9), 0 below the horizons."""
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
        """The fit's Fresnel table ``F(o.h)`` (Eq. 4.11), times ``specular_reflectance``."""
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
    """The ``mf_fitted`` class of the current Mitsuba variant (:func:`.registry.variant_class`)."""
    return variant_class(FittedBSDF)
