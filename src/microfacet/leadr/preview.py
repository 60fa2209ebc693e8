"""Preview of the filtered appearance of a moment pyramid at several MIP levels.

Each shown level is shaded texel by texel with the Beckmann BRDF of its moments
(:func:`~microfacet.leadr.from_moments`, Smith G, Schlick F0 = 0.04): a flat square
lit by a directional light at 30 degrees from the normal in the xz plane and seen from
the mirror direction, so a smooth flat texel shows the highlight and filtered texels
spread it. Levels are shown side by side, enlarged (nearest) to the size of the first.
"""
from __future__ import annotations

import numpy as np

from ..brdf import MicrofacetBRDF
from ..fresnel import Schlick
from .moments import from_moments

__all__ = ["shade_level", "preview_image"]

_THETA = np.radians(30.0)
WI = np.array([np.sin(_THETA), 0.0, np.cos(_THETA)])
WO = np.array([-np.sin(_THETA), 0.0, np.cos(_THETA)])


def shade_level(level, min_alpha: float = 0.02) -> np.ndarray:
    """Linear RGB radiance ``(H, W, 3)`` of each texel of a moment map under unit
    irradiance (``f_r cos theta_i``, module docstring). ``min_alpha`` floors the
    roughness so that single-facet texels stay visible rather than sub-pixel spikes.

    Parameters
    ----------
    level : array-like, shape (H, W, 5)
        One level of LEAN moments ``E1..E5``.
    min_alpha : float, optional
        Smallest roughness used per texel (default 0.02).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3)
        Linear RGB radiance of each texel.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> image = shade_level(pyramid[1])
    >>> image.shape, bool((image >= 0).all())
    ((8, 8, 3), True)
    """
    E = np.asarray(level, dtype=np.float64)
    brdf = MicrofacetBRDF(from_moments(E, min_alpha=min_alpha), fresnel=Schlick(0.04))
    return brdf.eval_cos(WI, WO)


def _enlarge(img: np.ndarray, shape) -> np.ndarray:
    rows = np.arange(shape[0]) * img.shape[0] // shape[0]
    cols = np.arange(shape[1]) * img.shape[1] // shape[1]
    return img[rows][:, cols]


def preview_image(pyramid, max_side: int = 256, count: int = 5, gap: int = 4) -> np.ndarray:
    """Linear RGB preview ``(H, W, 3)``: ``count`` consecutive levels starting at the first
    whose larger side is at most ``max_side``, normalised so that the brightest 0.5 % of
    the coarsest shown level is at display white.

    Parameters
    ----------
    pyramid : list of (H_k, W_k, 5) arrays
        A moment pyramid (:func:`microfacet.leadr.bake`), level 0 first.
    max_side : int, optional
        Largest side of the first level shown, in pixels (default 256).
    count : int, optional
        Number of consecutive levels shown side by side (default 5).
    gap : int, optional
        Pixels between the levels (default 4).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3)
        Linear RGB image, the levels left to right.

    Examples
    --------
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> preview_image(pyramid, max_side=16, count=3).shape
    (16, 56, 3)
    """
    first = next(k for k, lv in enumerate(pyramid) if max(lv.shape[:2]) <= max_side)
    levels = list(range(first, min(first + count, len(pyramid))))
    shape = pyramid[first].shape[:2]
    tiles = [_enlarge(shade_level(pyramid[k]), shape) for k in levels]
    white = np.percentile(tiles[-1], 99.5)
    white = white if white > 0 else max(float(np.max(tiles[0])), 1e-12)
    sep = np.ones((shape[0], gap, 3)) * white
    out = [tiles[0]]
    for t in tiles[1:]:
        out += [sep, t]
    return np.concatenate(out, axis=1) / white
