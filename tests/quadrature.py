"""Slope-space quadrature for the tests (see :mod:`microfacet.validation`)."""
from microfacet.validation import integrate_hemisphere, integrate_slopes, lobe_shape  # noqa: F401
