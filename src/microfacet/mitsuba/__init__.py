"""Mitsuba 3 BSDF plugins of ``microfacet`` (Dr.Jit), registered per variant::

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")          # or scalar_rgb, *_spectral, *_mono, cuda_*
    import microfacet.mitsuba as mfm
    mfm.register()                         # registers the plugins for the current variant
    bsdf = mi.load_dict({"type": "mf_microfacet", "distribution": "ggx",
                         "alpha_u": 0.2, "alpha_v": 0.4, "rho": 0.3,
                         "mean_slope_u": 0.1, "material": "Au"})

Plugins: ``mf_microfacet`` (:mod:`microfacet.mitsuba.bsdf`), the noncentral microfacet BRDF
of :class:`microfacet.MicrofacetBRDF`; ``mf_fitted`` (:mod:`microfacet.mitsuba.fitted`), a
fit of :mod:`microfacet.fit`; ``mf_leadr`` (:mod:`microfacet.mitsuba.leadr`), a LEADR
pyramid of :mod:`microfacet.leadr` over a base material; ``mf_glints``
(:mod:`microfacet.mitsuba.glints`), the patch BRDF of a glint microsurface. ``mi.set_variant`` is global and plugins are
registered per variant: call :func:`register` again after switching variants.
"""
from __future__ import annotations

__all__ = ["register", "PLUGINS"]

PLUGINS = ("mf_microfacet", "mf_fitted", "mf_leadr", "mf_glints")


def register() -> tuple[str, ...]:
    """Register the plugins of :data:`PLUGINS` that support the current Mitsuba variant
    (``mf_fitted``, ``mf_leadr``, ``mf_glints``: RGB variants); returns their names. Raises ``RuntimeError`` if Mitsuba is missing or no variant is set."""
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("microfacet.mitsuba needs Mitsuba 3: pip install 'microfacet[mitsuba]'") from e
    if not mi.variant():
        raise RuntimeError("microfacet.mitsuba.register(): set a Mitsuba variant first "
                           "(mi.set_variant('llvm_ad_rgb'))")
    from . import bsdf, fitted, glints, leadr
    names = []
    for module in (bsdf, fitted, leadr, glints):
        try:
            cls = module.bsdf_class()
        except RuntimeError:        # a variant the plugin does not support (e.g. spectral)
            continue
        mi.register_bsdf(module.PLUGIN, lambda props, cls=cls: cls(props))
        names.append(module.PLUGIN)
    return tuple(names)
