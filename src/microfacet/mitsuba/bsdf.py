"""``mf_microfacet``: the library's noncentral microfacet BRDF as a Mitsuba 3 BSDF plugin.

``f_r cos theta_i = F(o.h) D(h) G(i, o) / (4 z_o)`` (Eq. 2.1, Listing 2.2) with the noncentral
slope distribution of :mod:`microfacet.mitsuba.slopes`, the geometric attenuation of
:meth:`microfacet.MicrofacetBRDF.gaf` (Table 2.IV; Smith height-correlated with the
sheared projected-area normalization, Eq. 3.3) and the sampling of
:meth:`microfacet.MicrofacetBRDF.sample` (visible normals for Smith, Eq. 2.23; slopes of
``P`` otherwise). Mitsuba's ``si.wi`` is the library's view direction ``o`` and the
``wo`` argument its light direction ``i``; ``eval`` returns ``f_r cos theta_i``.
"""
from __future__ import annotations

import math
import os

import drjit as dr
import mitsuba as mi

from . import fresnel as _fresnel
from .properties import DEFAULT_PLUGIN as PLUGIN
from .properties import FRESNEL_KEYS as _FRESNEL_KEYS
from .properties import choice as _choice
from .properties import correlation as _correlation
from .properties import finite as _finite
from .properties import flag as _flag
from .properties import is_float as _is_float
from .properties import parameter_error as _error
from .properties import positive as _positive
from .properties import texture as _texture
from .slopes import BECKMANN, GGX, Lobe, ratio
from .tabulated import luminance

__all__ = ["PLUGIN", "bsdf_class", "GAFS"]

GAFS = ("smith", "vgroove", "normal_map")
_ALPHA_MIN = 1e-4           # textured alpha is clamped here (as Mitsuba's roughconductor)
_RHO_MAX = 1.0 - 1e-4       # textured rho is clamped into [-_RHO_MAX, _RHO_MAX]


def _ior_textures(material: str, plugin: str = PLUGIN):
    """``(eta, k)`` textures of a named conductor from Mitsuba's IOR database
    (``data/ior/<material>.{eta,k}.spd``), converted as its ``roughconductor`` does."""
    paths = {part: str(mi.file_resolver().resolve(f"data/ior/{material}.{part}.spd")) for part in ("eta", "k")}
    if not all(os.path.isfile(p) for p in paths.values()):
        raise _error("material", f"is not a conductor in Mitsuba's IOR database "
                                 f"(no data/ior/{material}.eta.spd), got {material!r}", plugin)
    textures = []
    for part in ("eta", "k"):
        wavelengths, values = mi.spectrum_from_file(paths[part])
        if mi.is_spectral:
            textures.append(mi.load_dict({"type": "irregular",
                                          "wavelengths": ", ".join(map(str, wavelengths)),
                                          "values": ", ".join(map(str, values))}))
        else:
            rgb = mi.spectrum_list_to_srgb(wavelengths, values, False, False)
            if mi.is_monochromatic:
                textures.append(mi.load_dict({"type": "uniform", "value": luminance(rgb)}))
            else:
                textures.append(mi.load_dict({"type": "srgb", "color": rgb, "unbounded": True}))
    return tuple(textures)


def glossy_sample(wo, pdf, active):
    """The ``mi.BSDFSample3f`` of a glossy reflection toward ``wo`` with density ``pdf``
    (0 where not ``active``), component 0."""
    bs = dr.zeros(mi.BSDFSample3f)
    bs.wo = wo
    bs.pdf = dr.select(active, pdf, 0.0)
    bs.eta = 1.0
    bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
    bs.sampled_component = mi.UInt32(0)
    return bs


def per_variant(make):
    """``bsdf_class()``: the plugin class ``make()`` builds for the current Mitsuba variant
    (``mi.BSDF`` differs per variant, so each class is built once per variant); ``make``
    raises ``RuntimeError`` for a variant it does not support."""
    classes: dict[str, type] = {}

    def bsdf_class() -> type:
        variant = mi.variant()
        if variant not in classes:
            classes[variant] = make()
        return classes[variant]
    return bsdf_class


def _make_class() -> type:
    if mi.is_polarized:
        raise RuntimeError(f"polarized variants are not supported ({mi.variant()})")

    class MicrofacetBSDF(mi.BSDF):
        """Mitsuba BSDF of :class:`microfacet.MicrofacetBRDF` (see the module docstring)."""

        PLUGIN_NAME = PLUGIN

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.kind = _choice(props, "distribution", BECKMANN, (BECKMANN, GGX))
            self.gaf = _choice(props, "gaf", "smith", GAFS)
            self.shadowing = _flag(props, "shadowing", True)
            self.separable = _flag(props, "separable", False)
            if self.separable and self.gaf != "smith":
                raise _error("separable", f"applies to gaf=smith only, got gaf={self.gaf!r}")
            if "alpha" in props and ("alpha_u" in props or "alpha_v" in props):
                raise _error("alpha", "and alpha_u/alpha_v are exclusive: give one or the other")
            if ("alpha_u" in props) != ("alpha_v" in props):
                raise _error("alpha_v" if "alpha_u" in props else "alpha_u",
                             "is missing: give both alpha_u and alpha_v (or alpha)")
            if "alpha_u" in props:
                self.alpha_u = _texture(props, "alpha_u", 0.1, _positive)
                self.alpha_v = _texture(props, "alpha_v", 0.1, _positive)
            else:
                self.alpha_u = self.alpha_v = _texture(props, "alpha", 0.1, _positive)
            self.isotropic = "alpha_u" not in props
            self.rho = _texture(props, "rho", 0.0, _correlation, unbounded=True)
            self.xn = _texture(props, "mean_slope_u", 0.0, _finite, unbounded=True)
            self.yn = _texture(props, "mean_slope_v", 0.0, _finite, unbounded=True)
            if self.gaf == "vgroove" and any(n in props and not (_is_float(props, n) and props[n] == 0)
                                             for n in ("mean_slope_u", "mean_slope_v")):
                raise _error("gaf", "vgroove needs a zero mean slope (V-grooves stand on the macro normal); "
                             "use gaf=smith with mean_slope_u/mean_slope_v")
            self.specular_reflectance = _texture(props, "specular_reflectance", 1.0)
            self.samples_visible = self.gaf == "smith"
            self._init_fresnel(props)
            anisotropic = not self.isotropic or any(n in props for n in ("rho", "mean_slope_u", "mean_slope_v"))
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            if anisotropic:
                flags = flags | mi.BSDFFlags.Anisotropic
            self.m_components = [flags]
            self.m_flags = flags

        def _init_fresnel(self, props):
            """Fresnel parameters of Table 2.I (``material``, ``eta``/``k``, ``int_ior``/
            ``ext_ior``, ``schlick_f0``, or none)."""
            plugin = self.PLUGIN_NAME
            names = sorted(n for n in props.keys() if n in _FRESNEL_KEYS)
            if "material" in names and props.get("material") == "none":
                names.remove("material")                  # Mitsuba's "none": F = 1
            if "material" in names and {"eta", "k"} & set(names):
                raise _error("material", "and eta/k are exclusive: give one or the other", plugin)
            kinds = {_FRESNEL_KEYS[n] for n in names}
            if len(kinds) > 1:
                raise _error(names[0], f"conflicts with {', '.join(names[1:])}: give one Fresnel "
                                       "(material or eta/k, int_ior/ext_ior, schlick_f0) or none", plugin)
            self.fresnel = kinds.pop() if kinds else "none"
            if self.fresnel == "conductor":
                if "material" in names:
                    self.eta, self.k = _ior_textures(props.get("material"), plugin)
                else:
                    self.eta = _texture(props, "eta", 0.0, _finite, unbounded=True, plugin=plugin)
                    self.k = _texture(props, "k", 1.0, _finite, unbounded=True, plugin=plugin)
            elif self.fresnel == "dielectric":
                int_ior = mi.lookup_ior(props, "int_ior", 1.5046)
                ext_ior = mi.lookup_ior(props, "ext_ior", 1.000277)
                for name, v in (("int_ior", int_ior), ("ext_ior", ext_ior)):
                    if not (math.isfinite(v) and v > 0):
                        raise _error(name, f"must be a finite number > 0, got {v!r}", plugin)
                self.eta_real = mi.Float(int_ior / ext_ior)
            elif self.fresnel == "schlick":
                self.f0 = _texture(props, "schlick_f0", 0.04,
                                   lambda v: None if 0 <= v <= 1 else "must lie in [0, 1]", plugin=plugin)

        # ------------------------------------------------------------- terms
        def _lobe(self, si, active):
            ax = dr.maximum(self.alpha_u.eval_1(si, active), _ALPHA_MIN)
            ay = ax if self.isotropic else dr.maximum(self.alpha_v.eval_1(si, active), _ALPHA_MIN)
            rho = dr.clip(self.rho.eval_1(si, active), -_RHO_MAX, _RHO_MAX)
            return Lobe(self.kind, ax, ay, rho, self.xn.eval_1(si, active), self.yn.eval_1(si, active))

        def _fresnel(self, si, oh, active):
            """``F(o.h)`` times ``specular_reflectance`` (Table 2.I)."""
            r = self.specular_reflectance.eval(si, active)
            if self.fresnel == "conductor":
                return r * _fresnel.conductor(oh, self.eta.eval(si, active), self.k.eval(si, active))
            if self.fresnel == "dielectric":
                return r * _fresnel.dielectric(oh, self.eta_real)
            if self.fresnel == "schlick":
                return r * _fresnel.schlick(oh, self.f0.eval(si, active))
            return r

        def _gaf(self, lobe, wi, wo, h, oh):
            """``G(i, o)`` of :meth:`microfacet.MicrofacetBRDF.gaf` at ``i.h = o.h`` (Table 2.IV):
            Smith ``(z_o / c_o) / (1 + Lambda_i + Lambda_o)`` (Eq. 3.3), or separable
            ``G1(i) G1(o)``; V-groove ``min(1, 2 z_i z_h / ih, 2 z_o z_h / oh)``; normal map
            ``z_o z_h / oh``; without shadowing only the ``o`` factors remain."""
            ok = (wi.z > 0) & (wo.z > 0) & (oh > 0) & (h.z > 0)
            if self.gaf == "smith":
                if self.separable:
                    g = lobe.g1(wo) * (lobe.g1(wi) if self.shadowing else 1.0)
                else:
                    lam_o, co = lobe.lambda_c(wo)
                    ok &= co > 0
                    lam_i = lobe.lambda_c(wi)[0] if self.shadowing else 0.0
                    g = ratio(wo.z, co * (1.0 + lam_i + lam_o), ok)
            else:
                go = ratio(wo.z * h.z, oh, ok)
                if self.gaf == "vgroove":
                    go = 2.0 * go
                    gi = ratio(2.0 * wi.z * h.z, oh, ok)
                    g = dr.minimum(1.0, dr.minimum(go, gi) if self.shadowing else go)
                else:
                    g = go
            return dr.select(ok, g, 0.0)

        def _normal_pdf(self, lobe, h, wo):
            """Density of sampled normals: ``D_o(h)`` (Smith, Eq. 2.17) or ``D(h) z_h``."""
            if self.samples_visible:
                return lobe.vndf(h, wo)
            return lobe.ndf(h) * h.z

        def _reflecting(self, ctx, si, active):
            """``active`` where the view is above the surface and glossy reflection is asked."""
            active = active & (si.wi.z > 0)
            if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection):
                active = active & False
            return active

        def _half(self, ctx, si, light, active):
            """``(h, o.h, active)`` of ``light`` and the view, active where both are above the
            surface and ``o.h > 0``."""
            active = self._reflecting(ctx, si, active & (light.z > 0))
            h = dr.normalize(light + si.wi)
            oh = dr.dot(si.wi, h)
            return h, oh, active & (oh > 0)

        def _eval_pdf(self, ctx, si, light, active, want_value=True, want_pdf=True):
            view = si.wi
            h, oh, active = self._half(ctx, si, light, active)
            lobe = self._lobe(si, active)
            value = pdf = None
            if want_value:
                g = self._gaf(lobe, light, view, h, oh)
                s = ratio(lobe.ndf(h) * g, 4.0 * view.z, active)
                value = dr.select(active & (g > 0), self._fresnel(si, oh, active) * s, 0.0)
            if want_pdf:
                pdf = ratio(self._normal_pdf(lobe, h, view), 4.0 * oh, active)
            return value, pdf

        # ------------------------------------------------------ Mitsuba API
        def eval(self, ctx, si, wo, active=True):
            """``f_r cos theta_i = F D G / (4 z_o)`` (Listing 2.2); ``wo`` is the light."""
            return self._eval_pdf(ctx, si, wo, active, want_pdf=False)[0]

        def pdf(self, ctx, si, wo, active=True):
            """Solid-angle density of :meth:`sample`: normal density over ``4 o.h``."""
            return self._eval_pdf(ctx, si, wo, active, want_value=False)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            """Reflect the view about a sampled normal (Sec. 2.2, 3.2); the Smith weight is
            ``F G / G1(o)`` (Eq. 2.23), the others' ``F G o.h / (z_o z_h)``."""
            view = si.wi
            active = self._reflecting(ctx, si, active)
            lobe = self._lobe(si, active)
            h = lobe.sample_visible(sample2, view) if self.samples_visible else lobe.sample_p22(sample2)
            oh = dr.dot(view, h)
            light = 2.0 * oh * h - view
            active &= (light.z > 0) & (oh > 0)
            g = self._gaf(lobe, light, view, h, oh)
            pdf = ratio(self._normal_pdf(lobe, h, view), 4.0 * oh, active)
            if self.samples_visible:
                g1_o = lobe.g1(view)
                weight = ratio(g, g1_o, g1_o > 0)
            else:
                weight = ratio(g * oh, view.z * h.z, active & (h.z > 0))
            active &= pdf > 0
            bs = glossy_sample(light, pdf, active)
            return bs, dr.select(active, self._fresnel(si, oh, active) * weight, 0.0)

        def traverse(self, callback):
            lobe = mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous
            if self.isotropic:
                callback.put("alpha", self.alpha_u, lobe)
            else:
                callback.put("alpha_u", self.alpha_u, lobe)
                callback.put("alpha_v", self.alpha_v, lobe)
            callback.put("rho", self.rho, lobe)
            callback.put("mean_slope_u", self.xn, lobe)
            callback.put("mean_slope_v", self.yn, lobe)
            callback.put("specular_reflectance", self.specular_reflectance, mi.ParamFlags.Differentiable)
            if self.fresnel == "conductor":
                callback.put("eta", self.eta, mi.ParamFlags.Differentiable)
                callback.put("k", self.k, mi.ParamFlags.Differentiable)
            elif self.fresnel == "schlick":
                callback.put("schlick_f0", self.f0, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return (f"MicrofacetBSDF[{PLUGIN}, distribution={self.kind}, gaf={self.gaf}, "
                    f"shadowing={self.shadowing}, separable={self.separable}, fresnel={self.fresnel}]")

    MicrofacetBSDF.__name__ = MicrofacetBSDF.__qualname__ = "MicrofacetBSDF"
    return MicrofacetBSDF


bsdf_class = per_variant(_make_class)
