"""The downsampling operator of displaced surfaces of arbitrary reflectance (thesis Ch. 5.1).

A displaced surface is the sum of two independent random slope processes: the
displacement map's (its LEADR MIP pyramid) and the base material's microfacets (a
Beckmann lobe: analytic roughness, or any material fitted by power iterations and
converted with ``fit.to_beckmann()``, Ch. 4). The slope PDF of the sum is the
convolution of the two PDFs (Eq. 5.1-5.3); for Beckmann lobes it is Beckmann again and
its linear moments are the sum of the two (Listing 5.1). Adding the base to every MIP
level gives a pyramid whose texels are the microfacet BRDFs of the displaced surface at
that resolution, so the surface shades at any resolution with one lookup per pixel.

Also here: the *naive* MIP mapping that Fig. 5.3 compares against (unit normals
averaged and renormalized, shaded with the base lobe only) and box supersampling of
per-texel shading (the reference of the comparisons).
"""
from __future__ import annotations

import numpy as np

from ..brdf import MicrofacetBRDF
from .maps import base_moments, slopes_to_moments
from .moments import convolve, from_moments

__all__ = ["base_lobe", "downsample_operator", "naive_slopes", "naive_pyramid", "box_average",
           "FilteredSurface"]


def base_lobe(base) -> np.ndarray:
    """Moments ``(5,)`` of a base material: ``None`` (a mirror: zeros), an isotropic
    ``alpha``, ``(alpha_x, alpha_y)``, a :class:`~microfacet.Beckmann`, a BRDF whose
    ``distribution`` is Beckmann, any object with ``to_beckmann()`` (a fit of
    :mod:`microfacet.fit`, converted by equal second slope moments, App. C), or the
    moments ``(5,)`` themselves.

    Parameters
    ----------
    base : None, float, (float, float), Beckmann, BRDF, fit or array-like (5,)
        The base material.

    Returns
    -------
    numpy.ndarray, shape (5,)
        Its moments ``E1..E5`` (float64).

    References
    ----------
    Dupuy 2015, thesis, App. C.

    Examples
    --------
    >>> base_lobe(None)
    array([0., 0., 0., 0., 0.])
    >>> base_lobe(0.2)
    array([0.  , 0.  , 0.02, 0.02, 0.  ])
    """
    if base is not None and hasattr(base, "to_beckmann"):
        base = base.to_beckmann()
    if isinstance(base, (np.ndarray, list, tuple)) and np.shape(base) == (5,):
        return np.asarray(base, dtype=np.float64)
    E = base_moments(base)
    return np.zeros(5) if E is None else E


def downsample_operator(pyramid, base) -> list[np.ndarray]:
    """Every level of a LEADR ``pyramid`` (``mf.leadr.bake``) merged with the ``base``
    material (:func:`base_lobe`) by moment addition (Ch. 5, Listing 5.1). The result's
    levels are the displaced surface's Beckmann BRDFs at each resolution (same dtype as
    the input levels). Merging is affine in the moments, so it commutes with the MIP
    averaging: ``downsample_operator(bake(h), b) == bake(h, roughness=b)`` up to rounding.

    Parameters
    ----------
    pyramid : list of (H_k, W_k, 5) arrays
        A LEADR moment pyramid.
    base : see :func:`base_lobe`
        The base material merged into every level.

    Returns
    -------
    list of numpy.ndarray
        The merged levels, in the input levels' dtype.

    References
    ----------
    Dupuy 2015, thesis, Ch. 5, Listing 5.1; Dupuy et al. 2013.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> merged = downsample_operator(pyramid, 0.2)
    >>> len(merged), round(float(merged[0][0, 0, 2] - pyramid[0][0, 0, 2]), 4)     # + 0.2^2 / 2
    (5, 0.02)
    """
    b = base_lobe(base)
    return [convolve(level, b).astype(np.asarray(level).dtype) for level in pyramid]


def box_average(values, factor: int, weights=None) -> np.ndarray:
    """Average of ``values (H, W, ...)`` over ``factor x factor`` blocks, optionally
    weighted by ``weights (H, W)`` (e.g. projected areas); ``H`` and ``W`` must be
    multiples of ``factor``.

    Parameters
    ----------
    values : array-like, shape (H, W, ...)
        The values to average.
    factor : int
        Block side in texels; divides ``H`` and ``W``.
    weights : array-like, shape (H, W), optional
        Per-texel weights (default: equal); blocks of zero weight give 0.

    Returns
    -------
    numpy.ndarray, shape (H / factor, W / factor, ...)
        The block averages.

    Examples
    --------
    >>> import numpy as np
    >>> box_average(np.arange(16.0).reshape(4, 4), 2)
    array([[ 2.5,  4.5],
           [10.5, 12.5]])
    """
    v = np.asarray(values, dtype=np.float64)
    f = int(factor)
    h, w = v.shape[:2]
    if f < 1 or h % f or w % f:
        raise ValueError(f"map {h}x{w} is not made of {f}x{f} blocks")
    extra = v.shape[2:]
    if weights is None:
        return v.reshape(h // f, f, w // f, f, *extra).mean(axis=(1, 3))
    wt = np.asarray(weights, dtype=np.float64).reshape((h, w) + (1,) * len(extra))
    num = (v * wt).reshape(h // f, f, w // f, f, *extra).sum(axis=(1, 3))
    den = np.broadcast_to(wt, v.shape).reshape(h // f, f, w // f, f, *extra).sum(axis=(1, 3))
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


def naive_slopes(level0, factor: int) -> np.ndarray:
    """Slopes ``(H / f, W / f, 2)`` of naive MIP mapping of a normal map: the unit normals
    of the texels' mean slopes (``level0[..., :2]``) averaged over ``f x f`` blocks and
    renormalized (the "naive MIP mapping" of Fig. 5.3, which loses the roughness that
    the normals' spread should become).

    Parameters
    ----------
    level0 : array-like, shape (H, W, >=2)
        Level-0 moments; ``[..., :2]`` are the texels' mean slopes.
    factor : int
        Block side ``f`` in texels.

    Returns
    -------
    numpy.ndarray, shape (H / f, W / f, 2)
        Slopes of the renormalized mean normals.

    References
    ----------
    Dupuy 2015, thesis, Fig. 5.3.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import slopes_to_moments
    >>> level0 = slopes_to_moments(np.array([[[1.0, 0.0], [-1.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]]]))
    >>> naive_slopes(level0, 2)          # the averaged normal is flat: a mirror
    array([[[-0., -0.]]])
    """
    E = np.asarray(level0, dtype=np.float64)
    n = np.stack([-E[..., 0], -E[..., 1], np.ones(E.shape[:2])], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    m = box_average(n, factor)
    return np.stack([-m[..., 0] / m[..., 2], -m[..., 1] / m[..., 2]], axis=-1)


def naive_pyramid(level0, base=None, levels: int | None = None) -> list[np.ndarray]:
    """Moment pyramid ``(H_k, W_k, 5)`` of naive MIP mapping: each level a single facet
    of the averaged normal (:func:`naive_slopes`, factor ``2^k``) with the ``base`` lobe
    only. Stops at the first level whose size is not a whole number of blocks.

    Parameters
    ----------
    level0 : array-like, shape (H, W, 5)
        Level-0 moments (only ``E1, E2``, the mean slopes, are used).
    base : see :func:`base_lobe`, optional
        The base lobe of every level (default ``None``: a mirror).
    levels : int, optional
        Most levels (default: down to the smallest whole level).

    Returns
    -------
    list of numpy.ndarray
        The levels ``(H_k, W_k, 5)``, level 0 first.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> naive = naive_pyramid(pyramid[0], base=0.2)
    >>> top = naive[-1][0, 0]
    >>> round(float(top[2] - top[0] ** 2), 4)      # only the base lobe's variance is left: 0.2^2 / 2
    0.02
    """
    E = np.asarray(level0, dtype=np.float64)
    h, w = E.shape[:2]
    b = base_lobe(base)
    out, k = [], 0
    while (levels is None or k < levels) and h % (1 << k) == 0 and w % (1 << k) == 0 \
            and (1 << k) <= min(h, w):
        out.append(slopes_to_moments(naive_slopes(E, 1 << k), b))
        k += 1
    return out


class FilteredSurface:
    """A displaced surface ready to shade at any resolution (Ch. 5, Fig. 5.2).

    Parameters
    ----------
    pyramid : list of (H_k, W_k, 5)
        LEADR pyramid of the displacement (``mf.leadr.bake(height, scale)``).
    base : see :func:`base_lobe`
        The base material's microfacet lobe, merged into every level.
    fresnel : Fresnel, optional
        Fresnel term of the BRDFs :meth:`brdf` returns (a fit's ``to_beckmann().fresnel``
        when ``base`` is a fit and ``fresnel`` is not given).

    References
    ----------
    Dupuy 2015, thesis, Ch. 5, Fig. 5.2; Dupuy et al. 2013.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> surface = FilteredSurface(bake(gaussian_heightfield((16, 16), 0.3, seed=0)), base=0.1)
    >>> surface.moments(np.array([0.5, 0.5]), footprint=1.0).round(4)       # the whole map
    array([ 0.    ,  0.    ,  0.1186,  0.0699, -0.0005])
    >>> brdf = surface.brdf(np.array([0.5, 0.5]), footprint=1.0)
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> brdf.eval(n, n).round(3)
    array([0.437, 0.437, 0.437])
    """

    def __init__(self, pyramid, base=None, fresnel=None):
        if fresnel is None and base is not None and hasattr(base, "to_beckmann"):
            fresnel = base.to_beckmann().fresnel
        if fresnel is None and isinstance(base, MicrofacetBRDF):
            fresnel = base.fresnel
        self.base = base_lobe(base)
        self.fresnel = fresnel
        self.levels = downsample_operator(pyramid, self.base)

    def moments(self, uv, footprint=0.0) -> np.ndarray:
        """Filtered moments ``(..., 5)`` at ``uv`` over ``footprint`` (``mf.leadr.lookup``).

        Parameters
        ----------
        uv : array-like, shape (..., 2)
            Texture coordinates.
        footprint : float or array-like, optional
            Pixel footprint in uv units (:func:`microfacet.leadr.lookup`; default 0).

        Returns
        -------
        numpy.ndarray, shape (..., 5)
            The filtered moments.
        """
        from .mip import lookup
        return lookup(self.levels, uv, footprint)

    def brdf(self, uv, footprint=0.0, shadowing: bool = True) -> MicrofacetBRDF:
        """Per-pixel :class:`~microfacet.MicrofacetBRDF` (Beckmann parameters as arrays
        over ``uv``'s leading shape) of the filtered surface.

        Parameters
        ----------
        uv : array-like, shape (..., 2)
            Texture coordinates (:func:`microfacet.leadr.lookup`).
        footprint : float or array-like, optional
            Pixel footprint in uv units, as for :func:`microfacet.leadr.lookup` (default 0:
            level 0).
        shadowing : bool, optional
            Include Smith shadowing-masking in the BRDF (default ``True``).

        Returns
        -------
        MicrofacetBRDF
            Beckmann BRDF with per-pixel parameters of shape ``uv.shape[:-1]``.
        """
        return MicrofacetBRDF(from_moments(self.moments(uv, footprint)), self.fresnel,
                              shadowing=shadowing)
