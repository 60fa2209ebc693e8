"""Mitsuba 3 BSDF plugins of ``microfacet`` (Dr.Jit), registered per variant::

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")          # or scalar_rgb, *_spectral, *_mono, cuda_*
    import microfacet.mitsuba as mfm
    mfm.register()                         # registers the plugins for the current variant
    bsdf = mi.load_dict({"type": "mf_microfacet", "distribution": "ggx",
                         "alpha_u": 0.2, "alpha_v": 0.4, "rho": 0.3,
                         "mean_slope_u": 0.1, "material": "Au"})

Plugins: ``mf_microfacet`` (:mod:`microfacet.mitsuba.bsdf`), the noncentral microfacet BRDF
of :class:`microfacet.MicrofacetBRDF`. ``mi.set_variant`` is global and plugins are
registered per variant: call :func:`register` again after switching variants.
"""
from __future__ import annotations

__all__ = ["register", "PLUGINS"]

PLUGINS = ("mf_microfacet",)


def register() -> tuple[str, ...]:
    """Register every plugin of :data:`PLUGINS` for the current Mitsuba variant; returns
    their names. Raises ``RuntimeError`` if Mitsuba is missing or no variant is set."""
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("microfacet.mitsuba needs Mitsuba 3: pip install 'microfacet[mitsuba]'") from e
    if not mi.variant():
        raise RuntimeError("microfacet.mitsuba.register(): set a Mitsuba variant first "
                           "(mi.set_variant('llvm_ad_rgb'))")
    from .bsdf import PLUGIN, bsdf_class
    cls = bsdf_class()
    mi.register_bsdf(PLUGIN, lambda props: cls(props))
    return PLUGINS
