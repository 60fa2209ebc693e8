"""Analytic BRDF trees of the library as Mitsuba 3 BSDFs (Dr.Jit): :func:`mitsuba_bsdf_of`.

A tree is what ``microfacet.fit.load(path, model=...)`` returns for an analytic fit, made of
the classes of :data:`SUPPORTED`:

* :class:`microfacet.MicrofacetBRDF` (Beckmann or GGX, any roughness, correlation and mean
  slope; GAF and shadowing as in the library) with a Fresnel term of
  :mod:`microfacet.fresnel`: ``Schlick(f0, f90)``, ``F82Tint(f0, f82)``, ``Conductor(eta, k)``,
  ``Dielectric(eta)``, ``Tabulated`` or ``Ideal``. Its ``eval``, ``pdf`` and sampler are
  ``mf_microfacet``'s (:mod:`.bsdf`: the same lobe code, with the Fresnel term of the tree);
* :class:`microfacet.Lambertian` (``k_d z_i / pi``, cosine sampling);
* :class:`microfacet.diffuse.TransmittedLambertian` (a Lambertian under a smooth dielectric surface);
* :class:`microfacet.fit.SumBRDF` ``(*parts, weights)``: the sum, sampled as the library's
  mixture (part ``j`` with probability ``w_j``, chosen by ``sample1``, rescaled for the part);
* :class:`microfacet.layered.LayeredBRDF` ``(coat, base)``: ``f_c + (1 - E_c(z_i))(1 - E_c(z_o)) f_b``
  with the library's own ``E_c`` table (:attr:`LayeredBRDF.table`, interpolated linearly in
  ``mu^(1/3)`` as there) and the coat's sampling probability table
  (:attr:`LayeredBRDF.probability_table`), so ``eval`` and ``pdf`` are the library's.

Mitsuba's ``si.wi`` is the library's view ``o``, the ``wo`` argument its light ``i``; ``eval``
returns ``f cos theta_i``; ``sample`` returns the weight ``eval / pdf`` of the whole tree (the
balance heuristic over its parts, as the library's ``sample``). Constant RGB parameters are
``srgb`` textures (spectral variants upsample them as Mitsuba does); the RGB variants reproduce
the library's values (``tests/test_mitsuba_fits.py``).

Examples
--------
A clear coat over a coloured Lambertian base, used as a shape's ``bsdf`` in ``mi.load_dict``:

>>> import numpy as np
>>> import mitsuba as mi
>>> mi.set_variant("scalar_rgb")
>>> import microfacet as mf
>>> from microfacet.layered import LayeredBRDF
>>> from microfacet.mitsuba.tree import SUPPORTED, mitsuba_bsdf_of
>>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.05), fresnel=mf.fresnel.Dielectric(1.5))
>>> brdf = LayeredBRDF(coat, mf.Lambertian([0.8, 0.3, 0.1]))
>>> bsdf = mitsuba_bsdf_of(brdf)
>>> scene = mi.load_dict({"type": "scene", "sphere": {"type": "sphere", "bsdf": bsdf}})
>>> si = mi.SurfaceInteraction3f()
>>> si.wi = mi.Vector3f(0, 0.6, 0.8)
>>> value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.48, -0.36, 0.8))
>>> library = brdf.eval(np.array([0.48, -0.36, 0.8]), np.array([0.0, 0.6, 0.8])) * 0.8
>>> bool(np.allclose(np.array(value), library, rtol=1e-5)), "LayeredBRDF" in SUPPORTED
(True, True)
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import fresnel as _fr
from ..brdf import Lambertian, MicrofacetBRDF
from ..diffuse import TransmittedLambertian
from ..distributions import GGX as _GGX, Beckmann as _Beckmann
from . import fresnel as _fresnel
from .bsdf import LobeModel, MicrofacetLobe, glossy_sample
from .registry import variant_class
from .slopes import BECKMANN, GGX, Lobe, ratio
from .tabulated import InterpolatedColor, Table

__all__ = ["mitsuba_bsdf_of", "component_of", "fresnel_term", "bsdf_class", "SUPPORTED", "TreeBSDF", "TreeLobe"]

#: The BRDF classes a tree may be built of (their names).
SUPPORTED = ("MicrofacetBRDF", "Lambertian", "TransmittedLambertian", "SumBRDF", "LayeredBRDF")


# ------------------------------------------------------------------ constants
def _color(values):
    """A constant RGB parameter: a Python float where its three values are equal (exact in
    every variant), else an ``srgb`` texture (unbounded), evaluated as ``value(si, active)``."""
    v = np.broadcast_to(np.asarray(values, dtype=np.float64), (3,))
    if np.all(v == v[0]):
        c = float(v[0])
        return lambda si, active: c
    texture = mi.load_dict({"type": "srgb", "color": [float(x) for x in v], "unbounded": True})
    return lambda si, active: texture.eval(si, active)


def fresnel_term(fresnel):
    """A spectrum-valued Dr.Jit twin of a :mod:`microfacet.fresnel` term.

    Table 2.I, Schlick 1994 with ``f90``, F82-tint, conductor, dielectric, table, ideal; grey
    terms of float parameters are broadcast to the variant's spectrum.

    Parameters
    ----------
    fresnel : microfacet.fresnel.Fresnel
        The library's term.

    Returns
    -------
    callable
        ``F(si, oh, active) -> Spectrum``.

    Raises
    ------
    ValueError
        Naming the class of a term without a twin.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tree import fresnel_term
    >>> fresnel_term(mf.fresnel.Schlick(0.04))(mi.SurfaceInteraction3f(), 1.0, True)
    [0.04, 0.04, 0.04]
    """
    value = _fresnel_value(fresnel)
    return lambda si, oh, active: mi.UnpolarizedSpectrum(value(si, oh, active))


def _fresnel_value(fresnel):
    """``F(si, oh, active)``: the Dr.Jit twin of a :mod:`microfacet.fresnel` term (Table 2.I,
    Schlick 1994 with ``f90``, F82-tint, conductor, dielectric, table, ideal); ``ValueError``
    naming the class for another one."""
    if isinstance(fresnel, _fr.Ideal):
        return lambda si, oh, active: 1.0
    if isinstance(fresnel, _fr.Schlick):
        f0, f90 = _color(fresnel.f0), _color(getattr(fresnel, "f90", 1.0))
        return lambda si, oh, active: _fresnel.schlick(oh, f0(si, active), f90(si, active))
    if hasattr(_fr, "F82Tint") and isinstance(fresnel, _fr.F82Tint):
        f0, f82 = _color(fresnel.f0), _color(fresnel.f82)
        return lambda si, oh, active: _fresnel.f82_tint(oh, f0(si, active), f82(si, active))
    if isinstance(fresnel, _fr.Conductor):
        eta, k = _color(fresnel.eta), _color(fresnel.k)
        return lambda si, oh, active: _fresnel.conductor(oh, eta(si, active), k(si, active))
    if isinstance(fresnel, _fr.Dielectric):
        eta = _color(fresnel.eta)
        return lambda si, oh, active: _fresnel.dielectric(oh, eta(si, active))
    if isinstance(fresnel, _fr.Tabulated):
        table = InterpolatedColor(fresnel.cos_theta_d, fresnel.values)
        return lambda si, oh, active: table(dr.clip(oh, 0.0, 1.0), si.wavelengths)
    raise ValueError(f"no Mitsuba twin of the Fresnel term {type(fresnel).__name__}")


class _UniformT:
    """A table on :func:`microfacet.layered.grid` nodes (uniform in ``t = mu^(1/3)``), read as
    :func:`microfacet.layered.lerp` reads it: linear in ``t``, clamped at its ends. RGB tables
    through :class:`~.tabulated.InterpolatedColor` (the variant's spectrum), scalar ones as a
    ``Float``."""

    def __init__(self, values):
        from ..layered import grid
        values = np.asarray(values, dtype=np.float64)
        self.n = len(values)
        t = np.cbrt(grid(self.n))
        self.t0, self.scale = float(t[0]), float((self.n - 1) / (1.0 - t[0]))
        if values.ndim > 1:
            self.color = InterpolatedColor(t, values)
        else:
            self.color, self.table = None, Table(values)

    def __call__(self, mu, wavelengths=None):
        t = dr.cbrt(dr.clip(mu, 0.0, 1.0))
        if self.color is not None:
            return self.color(t, wavelengths)
        x = dr.clip((t - self.t0) * self.scale, 0.0, self.n - 1.0)
        j = dr.minimum(mi.Int32(x), self.n - 2)
        s = x - mi.Float(j)
        lo = self.table[j]
        return lo + s * (self.table[j + 1] - lo)


# ------------------------------------------------------------------ components
class _Lambertian:
    """``k_d z_i / pi``, cosine-weighted sampling (Eq. 1.9)."""

    diffuse = True

    def __init__(self, brdf: Lambertian):
        self.reflectance = _color(brdf.reflectance)

    def eval_pdf(self, ctx, si, light, active):
        ok = active & (si.wi.z > 0) & (light.z > 0)
        cos_pdf = dr.select(ok, light.z * (1.0 / dr.pi), 0.0)
        return mi.UnpolarizedSpectrum(self.reflectance(si, ok)) * cos_pdf, cos_pdf

    def sample(self, ctx, si, sample1, sample2, active):
        light = mi.warp.square_to_cosine_hemisphere(sample2)
        return light, active & (si.wi.z > 0) & (light.z > 0)


class _TransmittedLambertian(_Lambertian):
    """``R z_i / pi t(z_i) t(z_o) / t(1)^2``, ``t = 1 - F_dielectric(eta)``
    (:class:`microfacet.diffuse.TransmittedLambertian`), cosine-weighted sampling."""

    def __init__(self, brdf):
        super().__init__(brdf)
        self.eta = float(brdf.eta)
        self.t1 = float(brdf.transmittance(np.ones(1))[0])

    def _t(self, mu):
        return dr.select(mu > 0, 1.0 - _fresnel.dielectric(dr.clip(mu, 0.0, 1.0), self.eta), 0.0)

    def eval_pdf(self, ctx, si, light, active):
        value, pdf = super().eval_pdf(ctx, si, light, active)
        return value * (self._t(si.wi.z) * self._t(light.z) / (self.t1 * self.t1)), pdf


class _Sum:
    """``sum_j f_j``, part ``j`` sampled with probability ``w_j`` (:class:`microfacet.fit.SumBRDF`)."""

    def __init__(self, brdf):
        self.parts = [component_of(b) for b in brdf.brdfs]
        self.weights = [float(w) for w in brdf.weights]
        self.diffuse = any(p.diffuse for p in self.parts)

    def eval_pdf(self, ctx, si, light, active):
        value, pdf = None, 0.0
        for w, part in zip(self.weights, self.parts):
            v, p = part.eval_pdf(ctx, si, light, active)
            value = v if value is None else value + v
            pdf = pdf + w * p
        return value, pdf

    def sample(self, ctx, si, sample1, sample2, active):
        light, ok = None, None
        lo = 0.0
        for j, (w, part) in enumerate(zip(self.weights, self.parts)):
            last = j == len(self.parts) - 1
            if w <= 0:
                continue
            chosen = (sample1 >= lo) if last else (sample1 >= lo) & (sample1 < lo + w)
            s1 = dr.clip((sample1 - lo) / w, 0.0, 1.0)
            l_j, ok_j = part.sample(ctx, si, s1, sample2, active)
            if light is None:
                light, ok = l_j, ok_j & chosen
            else:
                light = dr.select(chosen, l_j, light)
                ok = dr.select(chosen, ok_j, ok)
            lo += w
        return light, ok


class _Layered:
    """``f_c + (1 - E_c(z_i))(1 - E_c(z_o)) f_b`` (:class:`microfacet.layered.LayeredBRDF`), the
    coat sampled with the library's probability ``p(z_o)``."""

    def __init__(self, brdf):
        self.coat = component_of(brdf.coat)
        self.base = component_of(brdf.base)
        self.diffuse = self.base.diffuse
        self.albedo = _UniformT(brdf.table)
        self.probability = _UniformT(brdf.probability_table)

    def eval_pdf(self, ctx, si, light, active):
        vc, pc = self.coat.eval_pdf(ctx, si, light, active)
        vb, pb = self.base.eval_pdf(ctx, si, light, active)
        wl = si.wavelengths
        t = (1.0 - self.albedo(light.z, wl)) * (1.0 - self.albedo(si.wi.z, wl))
        p = self.probability(si.wi.z)
        return vc + t * vb, p * pc + (1.0 - p) * pb

    def sample(self, ctx, si, sample1, sample2, active):
        p = self.probability(si.wi.z)
        coat = sample1 < p
        s1 = dr.clip(dr.select(coat, ratio(sample1, p, p > 0), ratio(sample1 - p, 1.0 - p, p < 1.0)), 0.0, 1.0)
        lc, okc = self.coat.sample(ctx, si, s1, sample2, active)
        lb, okb = self.base.sample(ctx, si, s1, sample2, active)
        return dr.select(coat, lc, lb), dr.select(coat, okc, okb)


class TreeLobe(MicrofacetLobe):
    """A :class:`microfacet.MicrofacetBRDF` of a tree.

    ``mf_microfacet``'s lobe code (:class:`.bsdf.MicrofacetLobe`; a plain object, since a
    second ``mi.BSDF`` instance inside a BSDF breaks Mitsuba's rendering) with constant
    parameters and the tree's Fresnel term (:func:`fresnel_term`).

    Parameters
    ----------
    brdf : microfacet.MicrofacetBRDF
        A GGX or Beckmann lobe.

    Raises
    ------
    ValueError
        For another distribution (e.g. a tabulated one).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tree import TreeLobe
    >>> lobe = TreeLobe(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)))
    >>> lobe.model.kind, lobe.params
    ('ggx', [0.3, 0.3, 0.0, 0.0, 0.0])
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> value, pdf = lobe.eval_pdf(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1))
    >>> round(value[0], 4)                   # D(n) / 4 = 1 / (4 pi alpha^2)
    0.8842
    """

    diffuse = False

    def __init__(self, brdf: MicrofacetBRDF):
        d = brdf.distribution
        if type(d) not in (_GGX, _Beckmann):
            raise ValueError(f"a tree's MicrofacetBRDF must be GGX or Beckmann, got {type(d).__name__}")
        kind = GGX if type(d) is _GGX else BECKMANN
        self.model = LobeModel(kind, brdf.gaf_model, brdf.shadowing, False, brdf.gaf_model == "smith")
        self.params = [float(v) for v in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)]
        self.fresnel_of = fresnel_term(brdf.fresnel)

    def lobe(self, si, active):
        return Lobe(self.model.kind, *(mi.Float(v) for v in self.params))

    def fresnel(self, si, oh, active):
        return self.fresnel_of(si, oh, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        """A light direction sampled by the lobe (:meth:`lobe_sample`), as the tree's
        components sample.

        Parameters
        ----------
        ctx : mi.BSDFContext
            The context.
        si : mi.SurfaceInteraction3f
            The view is ``si.wi``.
        sample1 : Float
            Unused (the tree's component choice uses it).
        sample2 : Point2f
            Uniform numbers in ``[0, 1)^2`` for the normal.
        active : Bool
            The lanes to compute.

        Returns
        -------
        light : Vector3f
            The sampled light direction.
        ok : Bool
            The lanes with a sample of positive density.
        """
        bs, _ = self.lobe_sample(ctx, si, sample2, active)
        return bs.wo, active & (bs.pdf > 0)

    def eval_pdf(self, ctx, si, light, active=True):
        """``(f_r cos theta_i, pdf)`` of the lobe toward ``light`` (:meth:`lobe_eval_pdf`).

        Parameters
        ----------
        ctx : mi.BSDFContext
            The context.
        si : mi.SurfaceInteraction3f
            The view is ``si.wi``.
        light : Vector3f
            Direction toward the light, local frame.
        active : Bool
            The lanes to compute.

        Returns
        -------
        value : Spectrum
            ``f_r cos theta_i``.
        pdf : Float
            Solid-angle density of :meth:`sample`.
        """
        return self.lobe_eval_pdf(ctx, si, light, active)


def component_of(brdf):
    """The Dr.Jit component of one node of a tree (module docstring).

    Parameters
    ----------
    brdf : object
        A node of a class of :data:`SUPPORTED`.

    Returns
    -------
    object
        A component with ``eval_pdf(ctx, si, light, active) -> (f cos theta_i, pdf)``,
        ``sample(ctx, si, sample1, sample2, active) -> (light, ok)`` and ``diffuse``.

    Raises
    ------
    ValueError
        Naming the class of an unsupported node (e.g. the tabulated
        :class:`~microfacet.fit.FittedBRDF`).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tree import component_of
    >>> part = component_of(mf.Lambertian(0.5))
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> value, pdf = part.eval_pdf(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1), True)
    >>> part.diffuse, round(value[0], 6), round(pdf, 6)          # k_d / pi, 1 / pi
    (True, 0.159155, 0.31831)
    """
    from ..fit.analytic import SumBRDF
    from ..fit.fitted import FittedBRDF
    from ..layered import LayeredBRDF
    if isinstance(brdf, FittedBRDF):
        raise ValueError("no Mitsuba BSDF for a FittedBRDF (the tabulated fit) in a BRDF tree: render it with "
                         "mf_fitted use=tabulated")
    if isinstance(brdf, MicrofacetBRDF):
        return TreeLobe(brdf)
    if isinstance(brdf, TransmittedLambertian):
        return _TransmittedLambertian(brdf)
    if isinstance(brdf, Lambertian):
        return _Lambertian(brdf)
    if isinstance(brdf, SumBRDF):
        return _Sum(brdf)
    if isinstance(brdf, LayeredBRDF):
        return _Layered(brdf)
    raise ValueError(f"no Mitsuba BSDF for a {type(brdf).__name__} in a BRDF tree (supported: "
                     f"{', '.join(SUPPORTED)})")


# ------------------------------------------------------------------ the BSDF
class TreeBSDF:
    """Mitsuba BSDF of a library BRDF tree (module docstring); built by :func:`mitsuba_bsdf_of`.

    Parameters
    ----------
    props : mi.Properties
        Mitsuba's properties (none are read).
    brdf : object, optional
        The tree (:meth:`set_tree`).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tree import mitsuba_bsdf_of
    >>> bsdf = mitsuba_bsdf_of(mf.Lambertian(0.5))
    >>> type(bsdf).__name__, bool(bsdf.flags() & mi.BSDFFlags.DiffuseReflection)
    ('TreeBSDF', True)
    """

    def __init__(self, props, brdf=None):
        mi.BSDF.__init__(self, props)
        self.set_tree(brdf)

    def set_tree(self, brdf):
        """Render ``brdf``: build its components and set the BSDF's flags (diffuse
        reflection when a component is diffuse).

        Parameters
        ----------
        brdf : BRDF or None
            A library BRDF tree (:func:`component_of` supports its nodes); ``None``: none yet.
        """
        self.brdf = brdf
        self.root = None if brdf is None else component_of(brdf)
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        if self.root is not None and self.root.diffuse:
            flags = flags | mi.BSDFFlags.DiffuseReflection
        self.m_components = [flags]
        self.m_flags = flags

    def _active(self, ctx, si, active):
        active = active & (si.wi.z > 0)
        if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection) and \
                not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            active = active & False
        return active

    def eval_pdf(self, ctx, si, wo, active=True):
        """``(f cos theta_i, pdf)`` of the tree; ``wo`` is the light."""
        active = self._active(ctx, si, active) & (wo.z > 0)
        value, pdf = self.root.eval_pdf(ctx, si, wo, active)
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

    def eval(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[1]

    def sample(self, ctx, si, sample1, sample2, active=True):
        """A direction from the tree's mixture sampler; weight ``eval / pdf`` of the tree."""
        active = self._active(ctx, si, active)
        light, ok = self.root.sample(ctx, si, sample1, sample2, active)
        value, pdf = self.eval_pdf(ctx, si, light, active & ok)
        ok = active & ok & (pdf > 0) & (light.z > 0)
        bs = glossy_sample(light, pdf, ok)
        return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return f"TreeBSDF[{self.brdf!r}]"


def bsdf_class() -> type:
    """The tree BSDF class of the current Mitsuba variant (:func:`.registry.variant_class`).

    Returns
    -------
    type
        A subclass of the variant's ``mi.BSDF``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.tree import bsdf_class
    >>> issubclass(bsdf_class(), mi.BSDF)
    True
    """
    return variant_class(TreeBSDF)


def mitsuba_bsdf_of(brdf):
    """A Mitsuba BSDF (of the current variant) that renders a library BRDF tree.

    Parameters
    ----------
    brdf : object
        The tree (module docstring): use the result as the ``bsdf`` of a shape in
        ``mi.load_dict``.

    Returns
    -------
    mi.BSDF
        A :class:`TreeBSDF`.

    Raises
    ------
    ValueError
        Naming the node for a BRDF the tree cannot hold (e.g. the tabulated
        :class:`~microfacet.fit.FittedBRDF`: render it with ``mf_fitted``).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tree import mitsuba_bsdf_of
    >>> bsdf = mitsuba_bsdf_of(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2), fresnel=mf.fresnel.Schlick(0.5)))
    >>> si = mi.SurfaceInteraction3f()
    >>> si.wi = mi.Vector3f(0, 0, 1)
    >>> round(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1))[0], 4)   # F(1) / (4 pi alpha^2)
    0.9947
    """
    return bsdf_class()(mi.Properties(), brdf)
