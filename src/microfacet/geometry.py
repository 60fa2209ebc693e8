"""Directions, frames, slopes and sampling warps (thesis Ch. 1.3-1.4, 2.1).

Conventions: the local shading frame has z along the macro normal; directions are
unit vectors pointing away from the surface, stored as ``(..., 3)`` float64 arrays.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "dot", "normalize", "unit_deviation", "spherical_to_cartesian", "cartesian_to_spherical",
    "slope_to_normal", "normal_to_slope", "half_vector", "reflect",
    "io_to_hd", "hd_to_io", "rot_z", "rot_y", "orthonormal_basis",
    "to_local", "to_world", "square_to_concentric_disk",
    "square_to_cosine_hemisphere", "cosine_hemisphere_pdf",
]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis, broadcasting leading axes.

    Parameters
    ----------
    a, b : (..., n) array_like
        Vectors (leading axes broadcast).

    Returns
    -------
    (...) ndarray
        The dot products.

    Examples
    --------
    >>> import numpy as np
    >>> dot(np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 1.0]]), np.array([0.0, 0.0, 1.0]))
    array([3., 1.])
    """
    return np.einsum("...i,...i->...", *np.broadcast_arrays(a, b))


def normalize(v: np.ndarray) -> np.ndarray:
    """``v / |v|`` over the last axis (zero vectors stay zero).

    Parameters
    ----------
    v : (..., n) array_like
        Vectors.

    Returns
    -------
    (..., n) ndarray
        Unit vectors (zero where ``v`` is zero).

    Examples
    --------
    >>> normalize(np.array([[3.0, 0.0, 4.0], [0.0, 0.0, 0.0]]))
    array([[0.6, 0. , 0.8],
           [0. , 0. , 0. ]])
    """
    v = np.asarray(v, dtype=np.float64)
    n = np.sqrt(dot(v, v))[..., None]
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def unit_deviation(w: np.ndarray) -> float:
    """Largest ``| |w|^2 - 1 |`` over the directions ``w (..., 3)``; ``inf`` if any
    component is NaN or infinite, 0 for an empty array. (NumPy reference of
    :func:`microfacet.kernels.unit_deviation`.)

    Parameters
    ----------
    w : (..., 3) array_like
        Directions.

    Returns
    -------
    float
        The largest deviation.

    Examples
    --------
    >>> import numpy as np
    >>> unit_deviation(np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])) < 1e-15
    True
    >>> round(unit_deviation(np.array([0.0, 0.0, 1.1])), 2)
    0.21
    """
    w = np.asarray(w, dtype=np.float64)
    if w.size == 0:
        return 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        e = np.max(np.abs(w[..., 0] ** 2 + w[..., 1] ** 2 + w[..., 2] ** 2 - 1.0))
    return float(e) if np.isfinite(e) else np.inf


def sin_from_cos(c) -> np.ndarray:
    """``sin theta = sqrt((1 - c)(1 + c))`` of ``c = cos theta`` in ``[0, 1]``: ``1 - c c`` loses
    ``1 - c^2`` to the rounding of ``c^2`` near normal views (1e-9 of it at ``c = 1 - 8e-8``, which
    cost the Beckmann visible-slope quantile 205 ulps)."""
    c = np.asarray(c, dtype=np.float64)
    return np.sqrt((1.0 - c) * (1.0 + c))


def spherical_to_cartesian(theta, phi) -> np.ndarray:
    """Unit direction of elevation ``theta`` and azimuth ``phi`` (Dupuy 2015, Eq. 1.2).

    Parameters
    ----------
    theta, phi : array_like
        Elevation from +z and azimuth from +x, radians (broadcast together).

    Returns
    -------
    (..., 3) ndarray
        Unit directions.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.geometry import spherical_to_cartesian
    >>> spherical_to_cartesian(np.pi / 2, 0.0).round(12)      # on the horizon, along x
    array([1., 0., 0.])
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(theta, phi)`` of unit directions, inverse of Eq. 1.2; ``phi`` in (-pi, pi].

    Parameters
    ----------
    w : (..., 3) array_like
        Unit directions.

    Returns
    -------
    theta, phi : (...) ndarray
        Elevation in ``[0, pi]`` and azimuth in ``(-pi, pi]``, radians.

    Examples
    --------
    >>> import numpy as np
    >>> theta, phi = cartesian_to_spherical(np.array([0.0, 1.0, 1.0]) / np.sqrt(2))
    >>> np.degrees(theta).round(6), np.degrees(phi).round(6)
    (np.float64(45.0), np.float64(90.0))
    """
    w = np.asarray(w, dtype=np.float64)
    theta = np.arctan2(np.hypot(w[..., 0], w[..., 1]), w[..., 2])
    return theta, np.arctan2(w[..., 1], w[..., 0])


def slope_to_normal(x, y) -> np.ndarray:
    """Normal of slope ``(x~, y~)``: ``(-x~, -y~, 1) / sqrt(1 + x~^2 + y~^2)`` (Eq. 2.10).

    Parameters
    ----------
    x, y : array_like
        Slopes ``x~, y~``.

    Returns
    -------
    (..., 3) ndarray
        Unit normals.

    Examples
    --------
    >>> slope_to_normal(0.0, 0.0)
    array([-0., -0.,  1.])
    >>> slope_to_normal(-1.0, 0.0).round(4)          # a facet tilted 45 degrees toward +x
    array([ 0.7071, -0.    ,  0.7071])
    """
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return normalize(np.stack([-x, -y, np.ones_like(x)], axis=-1))


def normal_to_slope(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slope ``(x~, y~) = (-x_h / z_h, -y_h / z_h)`` of an upper normal (Eq. 2.9).

    Parameters
    ----------
    h : (..., 3) array_like
        Unit normals with ``z > 0``.

    Returns
    -------
    x, y : (...) ndarray
        Slopes.

    Examples
    --------
    >>> import numpy as np
    >>> x, y = normal_to_slope(np.array([1.0, 0.0, 1.0]) / np.sqrt(2))
    >>> float(x.round(12)), float(y)
    (-1.0, -0.0)
    """
    h = np.asarray(h, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -h[..., 0] / h[..., 2], -h[..., 1] / h[..., 2]


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Halfway vector ``h = (i + o) / |i + o|`` (Eq. 2.5); zero where ``i = -o``.

    Parameters
    ----------
    wi, wo : (..., 3) array_like
        Unit light and view directions.

    Returns
    -------
    (..., 3) ndarray
        Unit half vectors.

    Examples
    --------
    >>> import numpy as np
    >>> wi, wo = np.array([1.0, 0.0, 1.0]) / np.sqrt(2), np.array([-1.0, 0.0, 1.0]) / np.sqrt(2)
    >>> half_vector(wi, wo).round(12)
    array([0., 0., 1.])
    """
    h = np.asarray(wi, float) + np.asarray(wo, float)
    n2 = dot(h, h)
    with np.errstate(divide="ignore"):
        inv = np.where(n2 > 0, 1.0 / np.sqrt(n2), 0.0)
    h *= inv[..., None]
    return h


def reflect(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction ``2 (w.n) n - w`` (Eq. 2.4).

    Parameters
    ----------
    w : (..., 3) array_like
        Direction to mirror.
    n : (..., 3) array_like
        Unit normal.

    Returns
    -------
    (..., 3) ndarray
        The mirrored direction.

    Examples
    --------
    >>> import numpy as np
    >>> reflect(np.array([0.6, 0.0, 0.8]), np.array([0.0, 0.0, 1.0])).round(12)
    array([-0.6,  0. ,  0.8])
    """
    return 2.0 * dot(w, n)[..., None] * n - w


def rot_z(v: np.ndarray, angle) -> np.ndarray:
    """Rotate ``v`` by ``angle`` about z (right-handed).

    Parameters
    ----------
    v : (..., 3) array_like
        Vectors.
    angle : float or array_like
        Rotation angle, radians (broadcast with ``v[..., 0]``).

    Returns
    -------
    (..., 3) ndarray
        Rotated vectors.

    Examples
    --------
    >>> import numpy as np
    >>> rot_z(np.array([1.0, 0.0, 0.0]), np.pi / 2).round(12)
    array([0., 1., 0.])
    """
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, np.broadcast_to(z, np.shape(c * x))], -1)


def rot_y(v: np.ndarray, angle) -> np.ndarray:
    """Rotate ``v`` by ``angle`` about y (right-handed).

    Parameters
    ----------
    v : (..., 3) array_like
        Vectors.
    angle : float or array_like
        Rotation angle, radians (broadcast with ``v[..., 0]``).

    Returns
    -------
    (..., 3) ndarray
        Rotated vectors.

    Examples
    --------
    >>> import numpy as np
    >>> rot_y(np.array([0.0, 0.0, 1.0]), np.pi / 2).round(12)
    array([1., 0., 0.])
    """
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, np.broadcast_to(y, np.shape(c * x)), c * z - s * x], -1)


def io_to_hd(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rusinkiewicz halfway and difference vectors of ``(i, o)`` (Eq. 1.8, left).

    ``h = (i + o)/|i + o|`` and ``d = Rot_y(-theta_h) Rot_z(-phi_h) i``.

    Parameters
    ----------
    wi, wo : (..., 3) array_like
        Unit light and view directions.

    Returns
    -------
    h, d : (..., 3) ndarray
        Halfway and difference vectors.

    Examples
    --------
    >>> import numpy as np
    >>> wi, wo = spherical_to_cartesian(0.3, 0.0), spherical_to_cartesian(0.3, np.pi)
    >>> h, d = io_to_hd(wi, wo)                      # mirror pair: h is the normal, d = i at theta_d
    >>> h.round(12), np.allclose(d, wi)
    (array([0., 0., 1.]), False)
    """
    h = half_vector(wi, wo)
    theta_h, phi_h = cartesian_to_spherical(h)
    return h, rot_y(rot_z(np.asarray(wi, float), -phi_h), -theta_h)


def hd_to_io(h: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse Rusinkiewicz map (Eq. 1.8, right): ``i = Rot_z(phi_h) Rot_y(theta_h) d``,
    ``o = 2 (i.h) h - i``.

    Parameters
    ----------
    h, d : (..., 3) array_like
        Unit halfway and difference vectors.

    Returns
    -------
    wi, wo : (..., 3) ndarray
        Light and view directions.

    Examples
    --------
    >>> import numpy as np
    >>> wi, wo = spherical_to_cartesian(0.4, 0.1), spherical_to_cartesian(0.7, 2.0)
    >>> i2, o2 = hd_to_io(*io_to_hd(wi, wo))          # the round trip
    >>> bool(np.allclose(i2, wi) and np.allclose(o2, wo))
    True
    """
    h = np.asarray(h, dtype=np.float64)
    theta_h, phi_h = cartesian_to_spherical(h)
    wi = rot_z(rot_y(np.asarray(d, float), theta_h), phi_h)
    return wi, reflect(wi, h)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangents ``(s, t)`` with ``(s, t, n)`` right-handed and orthonormal.

    Branchless construction of Duff et al. 2017 ("Building an Orthonormal Basis, Revisited",
    JCGT 6(1)), vectorized.

    Parameters
    ----------
    n : (..., 3) array_like
        Unit normals.

    Returns
    -------
    s, t : (..., 3) ndarray
        Unit tangents.

    Examples
    --------
    >>> import numpy as np
    >>> n = normalize(np.array([1.0, 2.0, 2.0]))
    >>> s, t = orthonormal_basis(n)
    >>> bool(np.allclose(np.cross(s, t), n)), float(abs(dot(s, n)).round(12))
    (True, 0.0)
    """
    n = np.asarray(n, dtype=np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    s = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    t = np.stack([b, sign + y * y * a, -y], axis=-1)
    return s, t


def to_local(v: np.ndarray, s: np.ndarray, t: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World vector ``v`` expressed in the frame ``(s, t, n)``.

    Parameters
    ----------
    v : (..., 3) array_like
        World vectors.
    s, t, n : (..., 3) array_like
        Orthonormal frame (tangent, bitangent, normal).

    Returns
    -------
    (..., 3) ndarray
        Coordinates in the frame.

    Examples
    --------
    >>> import numpy as np
    >>> n = normalize(np.array([0.0, 1.0, 1.0]))
    >>> s, t = orthonormal_basis(n)
    >>> to_local(n, s, t, n).round(12)              # the normal is z of its own frame
    array([0., 0., 1.])
    """
    return np.stack([dot(v, s), dot(v, t), dot(v, n)], axis=-1)


def to_world(v: np.ndarray, s: np.ndarray, t: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Local vector ``v`` of the frame ``(s, t, n)`` in world coordinates.

    Parameters
    ----------
    v : (..., 3) array_like
        Local coordinates.
    s, t, n : (..., 3) array_like
        Orthonormal frame (tangent, bitangent, normal).

    Returns
    -------
    (..., 3) ndarray
        World vectors.

    Examples
    --------
    >>> import numpy as np
    >>> n = normalize(np.array([0.0, 1.0, 1.0]))
    >>> s, t = orthonormal_basis(n)
    >>> v = np.array([0.3, -0.2, 0.9])
    >>> bool(np.allclose(to_world(to_local(v, s, t, n), s, t, n), v))
    True
    """
    return v[..., 0:1] * s + v[..., 1:2] * t + v[..., 2:3] * n


def square_to_concentric_disk(u: np.ndarray) -> np.ndarray:
    """Concentric map of ``[0,1)^2`` onto the unit disk, ``(..., 2)`` (Shirley & Chiu 1997).

    Parameters
    ----------
    u : (..., 2) array_like
        Points of ``[0, 1)^2``.

    Returns
    -------
    (..., 2) ndarray
        Points of the unit disk.

    Examples
    --------
    >>> import numpy as np
    >>> square_to_concentric_disk(np.array([[0.5, 0.5], [1.0, 0.5]]))
    array([[0., 0.],
           [1., 0.]])
    """
    u = 2.0 * np.asarray(u, dtype=np.float64) - 1.0
    a, b = u[..., 0], u[..., 1]
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        phi = np.where(first, (np.pi / 4) * (b / a), np.pi / 2 - (np.pi / 4) * (a / b))
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def square_to_cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted upper-hemisphere direction (Malley's method, Listing 1.3).

    Parameters
    ----------
    u : (..., 2) array_like
        Points of ``[0, 1)^2``.

    Returns
    -------
    (..., 3) ndarray
        Unit directions, density :func:`cosine_hemisphere_pdf`.

    Examples
    --------
    >>> import numpy as np
    >>> w = square_to_cosine_hemisphere(np.random.default_rng(0).random((100_000, 2)))
    >>> w.shape, bool(np.all(w[:, 2] >= 0)), float(w[:, 2].mean().round(2))      # E[cos] = 2/3
    ((100000, 3), True, 0.67)
    """
    p = square_to_concentric_disk(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - dot(p, p)))
    return np.concatenate([p, z[..., None]], axis=-1)


def cosine_hemisphere_pdf(w: np.ndarray) -> np.ndarray:
    """Solid-angle density ``max(0, cos theta) / pi`` of the cosine warp.

    Parameters
    ----------
    w : (..., 3) array_like
        Unit directions.

    Returns
    -------
    (...) ndarray
        Density per steradian (0 below the horizon).

    Examples
    --------
    >>> import numpy as np
    >>> cosine_hemisphere_pdf(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])) * np.pi
    array([1., 0.])
    """
    return np.maximum(0.0, np.asarray(w, float)[..., 2]) / np.pi
