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

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import MicrofacetError
from ..fit import fit_names
from ..fit import load as load_fit
from ..io.exr import EXR_MAGIC
from . import bsdf as _bsdf
from . import properties
from .slopes import BECKMANN, GGX, Lobe
from .tabulated import InterpolatedColor, tabulated_lobe

__all__ = ["PLUGIN", "bsdf_class", "load_fit_parameter", "fit_path_parameter", "choose_fit", "USES"]

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


def _make_class() -> type:
    Base = _bsdf.bsdf_class()
    from .tree import component_of

    class FittedBSDF(Base):
        """Mitsuba BSDF of a :class:`microfacet.fit.FittedBRDF` (see the module docstring)."""

        PLUGIN_NAME = PLUGIN

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            fit = load_fit_parameter(props, "filename", PLUGIN)
            self.filename = props["filename"]
            use = props.get("use", "best") if "use" in props else "best"
            if not isinstance(use, str):
                raise properties.parameter_error("use", f"must be the name of a fit, got {use!r}", PLUGIN)
            self.use, tree = choose_fit(fit_path_parameter(props, "filename", PLUGIN), use)
            self.root = None
            self.specular_reflectance = properties.texture(props, "specular_reflectance", 1.0, plugin=PLUGIN)
            if tree is not None:
                self._init_tree(tree)
                return
            self.gaf = fit.gaf_model
            self.shadowing = fit.shadowing
            self.separable = False
            fresnel = fit.fresnel
            if self.use == "tabulated":
                self.kind = "tabulated"
                self.make_lobe = tabulated_lobe(fit.distribution)
                self.samples_visible = self.gaf == "smith" and fit.distribution.supports_visible_sampling
                self.diffuse = (mi.load_dict({"type": "srgb", "color": [float(v) for v in fit.diffuse],
                                              "unbounded": True}) if fit.has_diffuse else None)
                self.p_lobe = float(fit._lobe_probability())
                dist = fit.distribution
            else:
                self.kind = self.use
                converted = fit.to_ggx() if self.use == GGX else fit.to_beckmann()
                dist, fresnel = converted.distribution, converted.fresnel
                params = [mi.Float(float(v)) for v in (dist.alpha_x, dist.alpha_y, dist.rho, dist.xn, dist.yn)]
                self.make_lobe = lambda: Lobe(self.kind, *params)
                self.samples_visible = self.gaf == "smith"
                self.diffuse = None
            self.fresnel_table = InterpolatedColor(fresnel.cos_theta_d, fresnel.values)
            anisotropic = (fit.anisotropic or float(dist.alpha_x) != float(dist.alpha_y)
                           or np.any(np.asarray(dist.rho) != 0) or np.any(np.asarray(dist.mean_slope) != 0))
            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            if anisotropic:
                glossy = glossy | mi.BSDFFlags.Anisotropic
            self.m_components = [glossy]
            flags = glossy
            if self.diffuse is not None:
                diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
                self.m_components = [glossy, diffuse]
                flags = flags | diffuse
            self.m_flags = flags

        def _init_tree(self, tree):
            """An analytic fit: rendered by its :mod:`.tree` component."""
            self.tree = tree
            self.root = component_of(tree)
            self.diffuse = None
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            if self.root.diffuse:
                flags = flags | mi.BSDFFlags.DiffuseReflection
            self.m_components = [flags]
            self.m_flags = flags

        def _tree_eval_pdf(self, ctx, si, light, active):
            """``(f cos theta_i, pdf)`` of the analytic fit, times ``specular_reflectance``."""
            active = active & (si.wi.z > 0) & (light.z > 0)
            value, pdf = self.root.eval_pdf(ctx, si, light, active)
            value = value * self.specular_reflectance.eval(si, active)
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

        def _tree_sample(self, ctx, si, sample1, sample2, active):
            active = active & (si.wi.z > 0)
            light, ok = self.root.sample(ctx, si, sample1, sample2, active)
            value, pdf = self._tree_eval_pdf(ctx, si, light, active & ok)
            ok = active & ok & (pdf > 0) & (light.z > 0)
            bs = _bsdf.glossy_sample(light, pdf, ok)
            return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

        # ------------------------------------------------------------- terms
        def _lobe(self, si, active):
            return self.make_lobe()

        def _fresnel(self, si, oh, active):
            """The fit's Fresnel table ``F(o.h)`` (Eq. 4.11), times ``specular_reflectance``."""
            return self.specular_reflectance.eval(si, active) * self.fresnel_table(dr.clip(oh, 0.0, 1.0),
                                                                                   si.wavelengths)

        # ------------------------------------------------------ diffuse base
        def _base(self, ctx, si, light, active):
            """``(k_d z_i / pi, z_i / pi)`` of the Lambertian base (Eq. 1.9), 0 below the horizons."""
            ok = active & (si.wi.z > 0) & (light.z > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1)
            cos_pdf = dr.select(ok, light.z * (1.0 / dr.pi), 0.0)
            return self.diffuse.eval(si, ok) * cos_pdf, cos_pdf

        def eval_pdf(self, ctx, si, wo, active=True):
            """The lobe (Listing 2.2) plus the base; pdf ``p pdf_lobe + (1 - p) z_i / pi``; an
            analytic fit's own ``eval_pdf``."""
            if self.root is not None:
                return self._tree_eval_pdf(ctx, si, wo, active)
            value, pdf = Base._eval_pdf(self, ctx, si, wo, active)
            if self.diffuse is None:
                return value, pdf
            value_d, pdf_d = self._base(ctx, si, wo, active)
            return value + value_d, self.p_lobe * pdf + (1.0 - self.p_lobe) * pdf_d

        def eval(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[1]

        def sample(self, ctx, si, sample1, sample2, active=True):
            """The lobe's sample (``mf_microfacet``), or, with a base, the lobe or the cosine
            lobe chosen by ``sample1 < p``; the weight is then the mixture's ``eval / pdf``. An
            analytic fit: its tree's mixture sampler, weight ``eval / pdf``."""
            if self.root is not None:
                return self._tree_sample(ctx, si, sample1, sample2, active)
            if self.diffuse is None:
                return Base.sample(self, ctx, si, sample1, sample2, active)
            bs, _ = Base.sample(self, ctx, si, sample1, sample2, active)
            lobe = sample1 < self.p_lobe
            light = dr.select(lobe, bs.wo, mi.warp.square_to_cosine_hemisphere(sample2))
            value, pdf = self.eval_pdf(ctx, si, light, active)
            ok = active & (pdf > 0) & (si.wi.z > 0) & (light.z > 0)
            bs.wo = light
            bs.pdf = dr.select(ok, pdf, 0.0)
            bs.sampled_type = dr.select(lobe, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                        mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
            bs.sampled_component = dr.select(lobe, mi.UInt32(0), mi.UInt32(1))
            return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

        def traverse(self, callback):
            callback.put("specular_reflectance", self.specular_reflectance, mi.ParamFlags.Differentiable)

        def to_string(self):
            if self.root is not None:
                return f"FittedBSDF[{PLUGIN}, filename={self.filename!r}, use={self.use}, fit={self.tree!r}]"
            return (f"FittedBSDF[{PLUGIN}, filename={self.filename!r}, use={self.use}, gaf={self.gaf}, "
                    f"shadowing={self.shadowing}, diffuse={self.diffuse is not None}]")

    FittedBSDF.__name__ = FittedBSDF.__qualname__ = "FittedBSDF"
    return FittedBSDF


bsdf_class = _bsdf.per_variant(_make_class)
