"""An orthographic view of the unit sphere: per-pixel normals, tangent frames, coverage.

World frame: x to the right of the image, y up, z toward the viewer; the camera looks
down ``-z``, so the view direction (toward the viewer) is ``+z`` at every pixel. Image
row 0 is the top (``y = +1``).

Examples
--------
>>> from microfacet.render.sphere import VIEW
>>> VIEW                                  # the orthographic camera looks down -z
array([0., 0., 1.])
"""
from __future__ import annotations

import numpy as np

from ..geometry import dot, normalize, orthonormal_basis, to_local, to_world

__all__ = ["Sphere", "tangent_frame", "VIEW"]

#: World direction toward the (orthographic) viewer.
VIEW = np.array([0.0, 0.0, 1.0])


def tangent_frame(n: np.ndarray, tangent=(1.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Shading tangents ``(s, t)`` of normals ``n``: ``s`` is ``tangent`` projected on the
    tangent plane, ``s = normalize(a - (a.n) n)``, and ``t = n x s``.

    ``(s, t, n)`` is right-handed and orthonormal, and the local x axis (``alpha_x``,
    ``phi = 0`` of :meth:`SlopeDistribution.from_ellipse`) follows the world direction
    ``tangent`` wherever it can. Where ``n`` is parallel to ``tangent`` the projection
    vanishes and the frame falls back to :func:`~microfacet.geometry.orthonormal_basis`.

    Parameters
    ----------
    n : (..., 3) array_like
        Unit normals.
    tangent : (float, float, float)
        World direction to follow.

    Returns
    -------
    s, t : (..., 3) ndarray
        Unit tangent and bitangent.

    Examples
    --------
    >>> import numpy as np
    >>> s, t = tangent_frame(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
    >>> s.round(6), t.round(6)
    (array([[1., 0., 0.],
           [1., 0., 0.]]), array([[ 0.,  1.,  0.],
           [ 0.,  0., -1.]]))
    """
    n = np.asarray(n, dtype=np.float64)
    a = np.broadcast_to(np.asarray(tangent, dtype=np.float64), n.shape)
    s_proj = a - dot(a, n)[..., None] * n
    degenerate = (dot(s_proj, s_proj) < 1e-18)[..., None]
    s_fallback, _ = orthonormal_basis(n)
    s = np.where(degenerate, s_fallback, normalize(s_proj))
    return s, np.cross(n, s)


def _pixel_centres(size: int, sub: int) -> tuple[np.ndarray, np.ndarray]:
    """Image-plane ``(x, y)`` in ``[-1, 1]`` of a ``sub x sub`` grid in every pixel,
    shaped ``(size, size, sub*sub)``."""
    k = (np.arange(size * sub) + 0.5) / (size * sub) * 2.0 - 1.0
    x = k.reshape(1, size, 1, sub)
    y = -k.reshape(size, 1, sub, 1)
    x, y = np.broadcast_arrays(x, y)
    return x.reshape(size, size, sub * sub), y.reshape(size, size, sub * sub)


class Sphere:
    """Unit sphere filling a ``size x size`` orthographic image.

    Each pixel touched by the sphere is shaded once, at the centroid of its covered
    ``supersample x supersample`` subpixels (the pixel centre inside the disk), and
    composited over the background with its coverage, so silhouettes are antialiased
    without extra shading work.

    Parameters
    ----------
    size : int
        Image width and height, pixels.
    supersample : int
        Subpixels per axis for the coverage.
    tangent : (float, float, float)
        World direction the local x axis follows (:func:`tangent_frame`).

    Attributes
    ----------
    mask : (size, size) bool
        Pixels with nonzero coverage; shaded values are ``(N, ...)`` arrays over them.
    coverage : (N,) float
        Covered fraction of each such pixel.
    n, s, t : (N, 3) float
        World normal and tangents (:func:`tangent_frame`) of each shaded pixel.
    wo : (N, 3) float
        View direction :data:`VIEW` in each local frame ``(s, t, n)``.

    Examples
    --------
    >>> import numpy as np
    >>> sphere = Sphere(32)
    >>> sphere.wo.shape == sphere.n.shape, bool(np.allclose(sphere.wo[:, 2], sphere.n[:, 2]))   # wo: the view in each local frame
    (True, True)
    >>> image = sphere.image(np.ones((len(sphere.wo), 3)))     # per-pixel values back to a (32, 32, 3) image
    >>> image.shape, float(image[16, 16, 0]), float(image[0, 0, 0])
    ((32, 32, 3), 1.0, 0.0)
    """

    def __init__(self, size: int, supersample: int = 4, tangent=(1.0, 0.0, 0.0)):
        if int(size) != size or size < 1:
            raise ValueError(f"size must be a positive integer, got {size!r}")
        self.size = int(size)
        x, y = _pixel_centres(self.size, supersample)
        inside = x * x + y * y < 1.0
        covered = inside.sum(axis=-1)
        self.mask = covered > 0
        self.coverage = covered[self.mask] / inside.shape[-1]
        cx = (x * inside).sum(-1)[self.mask] / covered[self.mask]   # centroid of covered subpixels
        cy = (y * inside).sum(-1)[self.mask] / covered[self.mask]
        cz = np.sqrt(np.maximum(0.0, 1.0 - cx * cx - cy * cy))
        self.n = normalize(np.stack([cx, cy, cz], axis=-1))
        self.s, self.t = tangent_frame(self.n, tangent)
        self.wo = self.to_local(VIEW)

    @property
    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The per-pixel local frames ``(s, t, n)``."""
        return self.s, self.t, self.n

    def to_local(self, w_world) -> np.ndarray:
        """World directions (``(3,)`` or ``(N, 3)``) in each pixel's local frame.

        Parameters
        ----------
        w_world : (3,) or (N, 3) array_like
            World directions.

        Returns
        -------
        (N, 3) ndarray
            Local directions.
        """
        return to_local(np.asarray(w_world, dtype=np.float64), self.s, self.t, self.n)

    def to_world(self, w_local) -> np.ndarray:
        """Local directions ``(N, 3)`` in world coordinates.

        Parameters
        ----------
        w_local : (N, 3) array_like
            Local directions.

        Returns
        -------
        (N, 3) ndarray
            World directions.
        """
        return to_world(np.asarray(w_local, dtype=np.float64), self.s, self.t, self.n)

    def image(self, values, background=0.0) -> np.ndarray:
        """Scatter per-pixel ``values`` ``(N, C)`` into a ``(size, size, C)`` image,
        blended with ``background`` by coverage: ``c v + (1 - c) bg``.

        Parameters
        ----------
        values : (N, C) array_like
            One value per shaded pixel.
        background : float or (C,) array_like
            Background value.

        Returns
        -------
        (size, size, C) ndarray
            The image.
        """
        values = np.asarray(values, dtype=np.float64)
        c = self.coverage.reshape((-1,) + (1,) * (values.ndim - 1))
        out = np.empty((self.size, self.size) + values.shape[1:])
        out[...] = background
        out[self.mask] = c * values + (1.0 - c) * out[self.mask]
        return out
