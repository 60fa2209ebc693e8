"""Errors raised by microfacet for bad files and bad input."""


class MicrofacetError(Exception):
    """A file, a parameter or an argument is unusable; the message says which and why."""


class NormalMapWarning(UserWarning):
    """A normal map was decoded, but some texels were repaired or the map looks inconsistent."""


class HeightMapWarning(UserWarning):
    """A height map was read, but it looks like something else (a tangent-space normal map)."""
