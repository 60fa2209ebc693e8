"""BRDF fitting by power iterations (thesis Ch. 4; Dupuy et al., EGSR 2015).

``fit(brdf)`` extracts a tabulated slope distribution from the backscattering of any
BRDF and a tabulated Fresnel term, and returns a :class:`FittedBRDF` (a
:class:`~microfacet.MicrofacetBRDF`) that converts to Beckmann or GGX and saves to a
versioned ``.npz`` file read back by ``load``. ``fit_analytic(brdf, model, diffuse=...)``
fits an analytic GGX or Beckmann BRDF (with an optional Lambertian base, a
:class:`SumBRDF`) to the data by least squares, started from that conversion.
"""
from .analytic import SumBRDF, fit_analytic
from .fitted import FORMAT, VERSION, FittedBRDF, fit, fit_names, load

__all__ = ["FORMAT", "VERSION", "FittedBRDF", "SumBRDF", "fit", "fit_analytic", "fit_names", "load"]
