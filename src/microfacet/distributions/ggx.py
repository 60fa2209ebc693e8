"""GGX (Trowbridge-Reitz) slope distribution (thesis Tables 2.II, 2.III, 2.V)."""
from __future__ import annotations

import numpy as np

from ..geometry import sin_from_cos, square_to_concentric_disk
from .base import SlopeDistribution

__all__ = ["GGX"]


class GGX(SlopeDistribution):
    """GGX slopes: ``P_std(x~, y~) = 1 / (pi (1 + x~^2 + y~^2)^2)`` (Table 2.II).

    Its first slope moments are finite, its second ones are not.

    Parameters
    ----------
    alpha : float, optional
        Isotropic roughness (sets ``alpha_x = alpha_y = alpha``), ``> 0``.
    alpha_x, alpha_y : float, optional
        Roughness (slope scale) along x and y, ``> 0``.
    rho : float
        Slope correlation, ``-1 < rho < 1`` (Eq. 2.26).
    mean_slope : (float, float)
        Mean slope ``(x~n, y~n)`` of the sheared surface (Eq. 3.2).

    Examples
    --------
    >>> import numpy as np
    >>> d = GGX(alpha=0.2)
    >>> float(d.ndf(np.array([0.0, 0.0, 1.0])).round(4))   # D(n) = 1 / (pi alpha^2), as Beckmann's
    7.9577
    >>> h = np.array([np.sin(0.6), 0.0, np.cos(0.6)])
    >>> from microfacet.distributions import Beckmann
    >>> round(float(d.ndf(h) / Beckmann(alpha=0.2).ndf(h)), 1)    # the longer tail, 34 degrees off the normal
    748.2
    """

    second_moment_std = np.inf

    @staticmethod
    def p22_std(x, y):
        r = 1.0 + x * x + y * y
        return 1.0 / (np.pi * r * r)

    @staticmethod
    def p22_std_over_z4(x, y, z):
        r = z * z + x * x + y * y
        return 1.0 / (np.pi * r * r)

    @staticmethod
    def p1_std(x):
        """Marginal ``P1(x~) = 1 / (2 (1 + x~^2)^(3/2))`` (Eq. 2.39).

        Parameters
        ----------
        x : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope.
        """
        return 0.5 * (1.0 + np.asarray(x, float) ** 2) ** -1.5

    @staticmethod
    def lambda_std(cot_theta):
        """``Lambda(v) = (sqrt(1 + 1/v^2) - 1) / 2`` (Table 2.III), in the cancellation-free
        form ``w / (2 (1 + sqrt(1 + w)))``, ``w = 1/v^2``, where ``w <= 1``.

        Parameters
        ----------
        cot_theta : array_like
            ``cot theta`` of the direction; ``<= 0`` gives ``inf``.

        Returns
        -------
        ndarray
            ``Lambda >= 0``.
        """
        v = np.asarray(cot_theta, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            w = 1.0 / (v * v)
            r = np.sqrt(1.0 + w)
            lam = np.where(w > 1.0, 0.5 * (r - 1.0), 0.5 * w / (1.0 + r))
        return np.where(v > 0, lam, np.inf)

    @classmethod
    def lambda_warped(cls, a, b, c):
        """``Lambda = (|k'| - c) / (2c) = r2 / (2c (|k'| + c))``, ``r2 = a^2 + b^2``: Table 2.III
        at ``cot theta = c / sqrt(r2)``, without cancellation or overflow.

        Parameters
        ----------
        a, b, c : array_like
            Components of the warped direction ``k'`` (need not be unit).

        Returns
        -------
        ndarray
            ``Lambda >= 0`` (``inf`` where ``c <= 0``).
        """
        r2 = a * a + b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = r2 / (2.0 * c * (np.sqrt(r2 + c * c) + c))
        return np.where(c > 0, lam, np.inf)

    @staticmethod
    def sample_visible_std(u, cos_theta):
        """Standard visible normal for a view at ``theta`` in the xz plane, in closed form.

        A uniform point of the unit disk, warped onto the projection of the visible
        hemisphere of the (unit) ellipsoid, lifted onto it (Heitz 2018, "Sampling the GGX
        distribution of visible normals"). This is an exact transform of the
        visible-slope PDF of Eq. 2.15, equivalent to the quantiles of Table 2.V.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.
        cos_theta : array_like
            ``cos theta`` of the view, ``(0, 1]``.

        Returns
        -------
        (..., 3) ndarray
            Unit normals of the standard surface.
        """
        c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
        s = sin_from_cos(c)
        p = square_to_concentric_disk(u)
        t1, t2 = p[..., 0], p[..., 1]
        w = 0.5 * (1.0 + c)
        t2 = (1.0 - w) * np.sqrt(np.maximum(0.0, 1.0 - t1 * t1)) + w * t2
        tz = np.sqrt(np.maximum(0.0, 1.0 - t1 * t1 - t2 * t2))
        # basis T1 = (0, 1, 0), T2 = V x T1 = (-c, 0, s), V = (s, 0, c)
        return np.stack([s * tz - c * t2, t1, c * tz + s * t2], axis=-1)

    @staticmethod
    def sample_p22_std(u):
        """Standard normal with GGX slopes: ``tan^2 theta = u1 / (1 - u1)``, ``phi = 2 pi u2``.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.

        Returns
        -------
        (..., 3) ndarray
            Unit normals of the standard surface.
        """
        u = np.asarray(u, dtype=np.float64)
        cos_t = np.sqrt(1.0 - u[..., 0])
        sin_t = np.sqrt(u[..., 0])
        phi = 2.0 * np.pi * u[..., 1]
        return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
