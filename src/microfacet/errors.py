"""Errors raised by microfacet for bad files and bad input."""


class MicrofacetError(Exception):
    """A file, a parameter or an argument is unusable; the message says which and why.

    Examples
    --------
    >>> import microfacet as mf
    >>> issubclass(mf.MicrofacetError, Exception)
    True
    >>> try:
    ...     mf.measured.load("no-such-file.binary")
    ... except mf.MicrofacetError as e:
    ...     print(type(e).__name__)
    MicrofacetError
    """


class NormalMapWarning(UserWarning):
    """A normal map was decoded, but some texels were repaired or the map looks inconsistent.

    Examples
    --------
    >>> issubclass(NormalMapWarning, UserWarning)
    True
    """


class HeightMapWarning(UserWarning):
    """A height map was read, but it looks like something else (a tangent-space normal map).

    Examples
    --------
    >>> issubclass(HeightMapWarning, UserWarning)
    True
    """
