"""microfacet — multiscale microfacet rendering in slope space.

Microfacet BRDFs with roughness, correlation and mean slope (Dupuy 2015, Ch. 2-3),
BRDF fitting by power iterations (Ch. 4), LEAN/LEADR prefiltering (Ch. 3, 5) and glints.
"""
from . import fresnel, geometry, measured
from .brdf import BRDF, Lambertian, MicrofacetBRDF
from .distributions import GGX, Beckmann, SlopeDistribution
from .errors import MicrofacetError
from . import fit  # noqa: E402  (after the core it builds on)
from . import leadr  # noqa: E402
from . import glints  # noqa: E402
from . import batch  # noqa: E402

__version__ = "0.1.0"
__all__ = ["BRDF", "Beckmann", "GGX", "Lambertian", "MicrofacetBRDF", "MicrofacetError",
           "SlopeDistribution", "batch", "fit", "fresnel", "geometry", "glints", "leadr", "measured"]
