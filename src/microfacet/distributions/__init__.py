"""Microfacet slope distributions: standard forms plus roughness, correlation and shear."""
from .base import SlopeDistribution
from .beckmann import Beckmann
from .ggx import GGX

__all__ = ["SlopeDistribution", "Beckmann", "GGX"]
