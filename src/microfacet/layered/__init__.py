"""Layered materials: a dielectric coat over any BRDF of the library.

:class:`LayeredBRDF` ``(coat, base)`` is ``f = f_c + (1 - E_c(cos theta_i)) (1 - E_c(cos theta_o)) f_b``,
the energy-conserving coupling of Kelemen & Szirmay-Kalos 2001 and Weidlich & Wilkie 2007
(without refraction of the base's directions), with ``E_c`` the coat lobe's directional
albedo (:func:`coat_albedo`, tabulated per coat). See :mod:`microfacet.layered.coat` and
the Layered coats guide of the documentation.

Examples
--------
>>> import numpy as np
>>> import microfacet as mf
>>> from microfacet.layered import LayeredBRDF
>>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.05), fresnel=mf.fresnel.Dielectric(1.5))
>>> paint = LayeredBRDF(coat, mf.Lambertian([0.8, 0.3, 0.1]))
>>> w = np.array([0.0, 0.0, 1.0])
>>> (paint.eval(np.array([0.6, 0.0, 0.8]), w) * np.pi).round(3)    # off the highlight: the base, dimmed by the coat
array([0.737, 0.278, 0.095])
"""
from .coat import (LUMINANCE, NODES, PROBABILITY_BOUNDS, QUADRATURE_ORDER, QUADRATURE_ORDERS, TABLE_NODES, LayeredBRDF,
                   albedo_table, coat_albedo, grid, lerp, lobe_albedo, luminance, sampled_albedo)

__all__ = ["LayeredBRDF", "coat_albedo", "albedo_table", "lobe_albedo", "sampled_albedo", "lerp", "grid", "luminance",
           "NODES", "TABLE_NODES", "QUADRATURE_ORDERS", "QUADRATURE_ORDER", "PROBABILITY_BOUNDS", "LUMINANCE"]
