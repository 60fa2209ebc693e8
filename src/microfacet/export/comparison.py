"""The comparison sphere of the exports: every consumer's render of an exported material and
the library's own render share its pixels, frame and light, and are compared by :func:`rel_l1`.

An orthographic unit sphere filling the image (:class:`microfacet.render.Sphere`, one sample
at each pixel centre), lit by one directional light of irradiance 1 from :data:`LIGHT`.

Examples
--------
>>> import microfacet as mf
>>> image = library_render(mf.Lambertian(0.5), 8)
>>> image.shape, rel_l1(image, image)
((8, 8, 3), 0.0)
"""
from __future__ import annotations

import numpy as np

__all__ = ["LIGHT", "library_render", "rel_l1"]

#: Direction toward the comparison light.
LIGHT = (-0.5, 0.5, 1.0)
def library_render(brdf, size: int, light=LIGHT) -> np.ndarray:
    """The library's ``(size, size, 3)`` render: ``E f cos`` at each pixel centre, ``E = 1``.

    Parameters
    ----------
    brdf : BRDF
        Any library BRDF.
    size : int
        Image width and height in pixels.
    light : (3,) sequence
        Direction toward the light (normalised here); default :data:`LIGHT`.

    Returns
    -------
    (size, size, 3) ndarray
        Linear radiance, 0 outside the sphere.

    Examples
    --------
    >>> import microfacet as mf
    >>> image = library_render(mf.Lambertian([1.0, 1.0, 1.0]), 16, light=LIGHT)
    >>> image.shape, round(float(image.max()) * np.pi, 2)          # E cos / pi, largest where n faces the light
    ((16, 16, 3), 1.0)
    """
    from ..render import Sphere
    s = Sphere(size, supersample=1)
    w = np.asarray(light, float) / np.linalg.norm(light)
    return s.image(np.nan_to_num(brdf.eval_cos(s.to_local(w), s.wo)))


def rel_l1(image: np.ndarray, reference: np.ndarray) -> float:
    """``sum |a - b| / sum |b|`` over the pixels at radius ``< 0.95`` of the sphere.

    Parameters
    ----------
    image, reference : (n, n, 3) ndarray
        Renders of the comparison sphere.

    Returns
    -------
    float
        The relative L1 difference (the rim, where renderers' pixel footprints differ most,
        left out).

    Examples
    --------
    >>> import microfacet as mf
    >>> reference = library_render(mf.Lambertian([0.5, 0.5, 0.5]), 16)
    >>> round(rel_l1(1.1 * reference, reference), 6)
    0.1
    """
    n = reference.shape[0]
    k = (np.arange(n) + 0.5) / n * 2 - 1
    inside = k[None, :] ** 2 + k[:, None] ** 2 < 0.95 ** 2
    return float(np.abs(image[inside] - reference[inside]).sum() / np.abs(reference[inside]).sum())
