"""Microfacet slope distributions: standard forms plus roughness, correlation and shear."""
from .base import SlopeDistribution
from .beckmann import Beckmann
from .ggx import GGX
from .tabulated import TabulatedAnisotropic, TabulatedIsotropic

__all__ = ["SlopeDistribution", "Beckmann", "GGX", "TabulatedIsotropic", "TabulatedAnisotropic"]
