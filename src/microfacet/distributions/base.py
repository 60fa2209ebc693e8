"""Slope distributions with roughness, correlation and mean slope (thesis Ch. 2.3, 3.2).

A distribution is a *standard* slope PDF ``P_std`` (alpha = 1, rho = 0, zero mean)
plus the linear slope map of Eq. 3.4: a sample ``m~`` of ``P_std`` becomes

    h~ = (alpha_x m~x + x~n,  alpha_y (rho m~x + sqrt(1 - rho^2) m~y) + y~n).

Every quantity of the transformed surface (NDF, Smith masking, visible normals and
their sampling) is the standard one evaluated at transformed arguments (roughness and
shear invariance, Eq. 2.26, 3.2, 3.3). Parameters may be scalars or arrays that
broadcast against the leading dimensions of the directions (one surface per texel).

Examples
--------
>>> import numpy as np
>>> from microfacet.distributions.base import MIN_ALPHA
>>> MIN_ALPHA[np.dtype(np.float64)], MIN_ALPHA[np.dtype(np.float32)]
(1e-14, 1e-06)
"""
from __future__ import annotations

import numpy as np

from ..geometry import dot, normalize

__all__ = ["SlopeDistribution", "MIN_ALPHA"]

#: Smallest accepted roughness ``alpha_x``, ``alpha_y`` per result type: about 100 (float64) and
#: 17 (float32) units in the last place of 1. Directions are resolved to about one such unit, so
#: a narrower lobe is not resolved at its own rounded samples: its NDF at the half vector of a
#: sampled pair, recomputed from the rounded directions, underflows (float64 alpha 1e-100, or
#: float32 alpha 1e-9: 20-80 % of the sheared samples had pdf 0), and further down the arithmetic
#: leaves the type's range (GGX evaluated NaN from alpha <= 1e-153 in float64 and 1e-18 in
#: float32; Beckmann float32 sampled NaN directions from 1e-19). The distribution checks float64's
#: bound; a float32 :class:`microfacet.MicrofacetBRDF` checks float32's (:meth:`SlopeDistribution.check_dtype`).
MIN_ALPHA = {np.dtype(np.float64): 1e-14, np.dtype(np.float32): 1e-6}


def _param(value, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _positive(value, name: str) -> np.ndarray:
    v = _param(value, name)
    if np.any(v <= 0):
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _roughness(value, name: str) -> np.ndarray:
    """``value`` as a roughness: finite and ``>= MIN_ALPHA[float64]`` (``ValueError`` naming ``name``)."""
    v = _positive(value, name)
    low = MIN_ALPHA[np.dtype(np.float64)]
    if np.any(v < low):
        raise ValueError(f"{name} must be >= {low:g} (a narrower lobe is below float64's direction resolution), "
                         f"got {float(np.min(v))!r}")
    return v


class SlopeDistribution:
    """Microfacet slope distribution ``P(x~, y~; alpha_x, alpha_y, rho, x~n, y~n)``.

    Parameters
    ----------
    alpha : float, optional
        Isotropic roughness (sets ``alpha_x = alpha_y = alpha``).
    alpha_x, alpha_y : float, optional
        Roughness (slope scale) along x and y, ``> 0``.
    rho : float
        Slope correlation, ``-1 < rho < 1`` (Eq. 2.26).
    mean_slope : (float, float)
        Mean slope ``(x~n, y~n)`` of the sheared (noncentral) surface (Eq. 3.2).

    Notes
    -----
    Subclasses provide the standard-form functions ``p22_std``, ``p1_std``,
    ``lambda_std``, ``sample_visible_std``, ``sample_p22_std`` and
    ``second_moment_std``.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.distributions import GGX, SlopeDistribution
    >>> d = GGX(alpha_x=0.3, alpha_y=0.1, rho=0.2, mean_slope=(0.1, 0.0))
    >>> isinstance(d, SlopeDistribution), d.alpha_x, d.alpha_y, d.rho
    (True, array(0.3), array(0.1), array(0.2))
    >>> h = np.array([0.0, 0.0, 1.0])
    >>> float(d.ndf(h).round(4))                     # D(h) at the macro normal
    8.6989
    """

    def __init__(self, alpha=None, *, alpha_x=None, alpha_y=None, rho=0.0, mean_slope=(0.0, 0.0)):
        if alpha is not None:
            if alpha_x is not None or alpha_y is not None:
                raise ValueError("give either alpha or (alpha_x, alpha_y), not both")
            alpha_x = alpha_y = alpha
        elif alpha_x is None or alpha_y is None:
            raise ValueError("give alpha, or both alpha_x and alpha_y")
        self.alpha_x = _roughness(alpha_x, "alpha_x" if alpha is None else "alpha")
        self.alpha_y = _roughness(alpha_y, "alpha_y" if alpha is None else "alpha")
        self.rho = _param(rho, "rho")
        if np.any(np.abs(self.rho) >= 1):
            raise ValueError(f"rho must lie in (-1, 1), got {rho!r}")
        ms = _param(mean_slope, "mean_slope")
        if ms.shape[-1:] != (2,):
            raise ValueError(f"mean_slope must have a last axis of size 2, got shape {ms.shape}")
        self.mean_slope = ms
        self.xn, self.yn = ms[..., 0], ms[..., 1]
        self.sqrt_one_minus_rho2 = np.sqrt(1.0 - self.rho**2)

    # ---------------------------------------------------------------- parameters
    @classmethod
    def from_ellipse(cls, alpha1, alpha2, phi, mean_slope=(0.0, 0.0)):
        """Distribution of ellipse radii ``alpha1, alpha2`` whose ``alpha1`` axis lies at
        azimuth ``phi`` in slope space (Eq. 2.29-2.31).

        ``alpha_x^2 = (a1^2 + a2^2 + (a1^2 - a2^2) cos 2phi)/2``,
        ``alpha_y^2 = (a1^2 + a2^2 - (a1^2 - a2^2) cos 2phi)/2``,
        ``rho = (a1^2 - a2^2) cos phi sin phi / (alpha_x alpha_y)``.

        Parameters
        ----------
        alpha1, alpha2 : float
            Ellipse radii (roughness along the ellipse's axes), ``> 0``.
        phi : float
            Azimuth of the ``alpha1`` axis, radians.
        mean_slope : (float, float)
            Mean slope ``(x~n, y~n)``.

        Returns
        -------
        SlopeDistribution
            A distribution of this class.
        """
        a1, a2 = _roughness(alpha1, "alpha1") ** 2, _roughness(alpha2, "alpha2") ** 2
        phi = _param(phi, "phi")
        ax = np.sqrt(0.5 * (a1 + a2 + (a1 - a2) * np.cos(2 * phi)))
        ay = np.sqrt(0.5 * (a1 + a2 - (a1 - a2) * np.cos(2 * phi)))
        rho = (a1 - a2) * np.cos(phi) * np.sin(phi) / (ax * ay)
        return cls(alpha_x=ax, alpha_y=ay, rho=rho, mean_slope=mean_slope)

    def check_dtype(self, dtype) -> None:
        """``ValueError`` (one line, naming the parameter and the smallest accepted value) if a
        roughness of this distribution is below ``MIN_ALPHA[dtype]``, the smallest one results of
        ``dtype`` represent (:class:`microfacet.MicrofacetBRDF` calls it with its ``dtype``).

        Parameters
        ----------
        dtype : dtype
            The BRDF's arithmetic type (float32 or float64).

        Examples
        --------
        >>> from microfacet import Beckmann
        >>> Beckmann(alpha=1e-12).check_dtype(np.float32)
        Traceback (most recent call last):
        ...
        ValueError: alpha_x must be >= 1e-06 for dtype float32 (a narrower lobe is below float32's direction resolution; use float64), got 1e-12
        """
        dtype = np.dtype(dtype)
        low = MIN_ALPHA.get(dtype)
        if low is None:
            return
        for name, v in (("alpha_x", self.alpha_x), ("alpha_y", self.alpha_y)):
            if np.any(v < low):
                raise ValueError(f"{name} must be >= {low:g} for dtype {dtype} (a narrower lobe is below "
                                 f"{dtype}'s direction resolution; use float64), got {float(np.min(v))!r}")

    @property
    def ellipse(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(alpha1, alpha2, phi)``, the inverse of :meth:`from_ellipse` (Eq. 2.32-2.34).

        ``alpha1 >= alpha2`` are the principal slope scales and ``phi`` in
        ``(-pi/2, pi/2]`` the azimuth of the ``alpha1`` axis, computed as
        ``phi = atan2(2 rho ax ay, ax^2 - ay^2) / 2``. Note: Eq. 2.34 as printed has the
        opposite sign (it inverts Eq. 2.25, whose angle is ``-phi``); we keep Eq. 2.29-2.31
        as the definition and invert them consistently.
        """
        ax2, ay2 = self.alpha_x**2, self.alpha_y**2
        cxy = self.rho * self.alpha_x * self.alpha_y
        root = np.sqrt((ax2 - ay2) ** 2 + 4.0 * cxy**2)
        alpha1 = np.sqrt(0.5 * (ax2 + ay2 + root))
        alpha2 = np.sqrt(np.maximum(0.5 * (ax2 + ay2 - root), 0.0))
        return alpha1, alpha2, 0.5 * np.arctan2(2.0 * cxy, ax2 - ay2)

    def moments(self) -> tuple[np.ndarray, ...]:
        """Linear slope moments ``(E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~])`` (Eq. 3.5-3.9).

        Second moments are ``inf`` when the distribution's are not finite (GGX).

        Returns
        -------
        tuple of 5 ndarray
            ``E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~]``.
        """
        m2 = self.second_moment_std
        if not np.isfinite(m2):
            inf = np.full(np.shape(self.xn), np.inf)
            return self.xn, self.yn, inf, inf, inf
        ax, ay = self.alpha_x, self.alpha_y
        return (self.xn, self.yn, ax * ax * m2 + self.xn**2, ay * ay * m2 + self.yn**2,
                self.rho * ax * ay * m2 + self.xn * self.yn)

    def __repr__(self) -> str:
        f = lambda v: np.round(v, 6).tolist()  # noqa: E731
        return (f"{type(self).__name__}(alpha_x={f(self.alpha_x)}, alpha_y={f(self.alpha_y)}, "
                f"rho={f(self.rho)}, mean_slope={f(self.mean_slope)})")

    # ------------------------------------------------------- standard <-> general
    @property
    def _det(self) -> np.ndarray:
        """Jacobian ``alpha_x alpha_y sqrt(1 - rho^2)`` of the slope map (Eq. 2.27)."""
        return self.alpha_x * self.alpha_y * self.sqrt_one_minus_rho2

    def to_standard(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Standard slope ``m~`` of the slope ``h~`` (inverse of Eq. 3.4).

        Parameters
        ----------
        x, y : array_like
            Slopes of this distribution.

        Returns
        -------
        xm, ym : ndarray
            Standard slopes.
        """
        return self._unscale(x - self.xn, y - self.yn)

    def _unscale(self, dx, dy) -> tuple[np.ndarray, np.ndarray]:
        """Inverse of the linear (roughness) part of Eq. 3.4 applied to slope offsets."""
        return dx / self.alpha_x, (self.alpha_x * dy - self.rho * self.alpha_y * dx) / (
            self.alpha_x * self.alpha_y * self.sqrt_one_minus_rho2)

    def from_standard(self, xm, ym) -> tuple[np.ndarray, np.ndarray]:
        """Slope ``h~`` of the standard slope ``m~`` (Eq. 3.4).

        Parameters
        ----------
        xm, ym : array_like
            Standard slopes.

        Returns
        -------
        x, y : ndarray
            Slopes of this distribution.
        """
        return (self.alpha_x * xm + self.xn,
                self.alpha_y * (self.rho * xm + self.sqrt_one_minus_rho2 * ym) + self.yn)

    def _normal_from_standard(self, m: np.ndarray) -> np.ndarray:
        """Eq. 3.4 applied to a standard normal ``m`` (division-free, ``m_z >= 0``)."""
        mx, my, mz = m[..., 0], m[..., 1], m[..., 2]
        hx = self.alpha_x * mx - self.xn * mz
        hy = self.alpha_y * (self.rho * mx + self.sqrt_one_minus_rho2 * my) - self.yn * mz
        return normalize(np.stack(np.broadcast_arrays(hx, hy, mz), axis=-1))

    def _warp(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unnormalized standard direction ``k' = (a, b, c)`` of ``k`` (Eq. 3.3)."""
        x, y, z = k[..., 0], k[..., 1], k[..., 2]
        a = self.alpha_x * x + self.rho * self.alpha_y * y
        b = self.alpha_y * self.sqrt_one_minus_rho2 * y
        return a, b, z - x * self.xn - y * self.yn

    # ------------------------------------------------------------ NDF and slopes
    def p22(self, x, y) -> np.ndarray:
        """Slope PDF ``P(x~, y~)`` (Eq. 2.27 with the shear of Eq. 3.2).

        Parameters
        ----------
        x, y : array_like
            Slopes.

        Returns
        -------
        ndarray
            Density per unit slope area.
        """
        xm, ym = self.to_standard(np.asarray(x, float), np.asarray(y, float))
        return self.p22_std(xm, ym) / self._det

    def ndf(self, h) -> np.ndarray:
        """Microfacet NDF ``D(h) = P(h~) / cos^4 theta_h`` (Eq. 2.11, 3.2); 0 below the horizon.

        Evaluated division-free as ``P_std(X/z, Y/z) / z^4`` with ``(X, Y) = z m~`` the
        standard slope scaled by ``z = z_h``, so it stays finite at grazing normals.

        Parameters
        ----------
        h : (..., 3) array_like
            Unit microfacet normals.

        Returns
        -------
        (...) ndarray
            ``D(h)``, per steradian.
        """
        h = np.asarray(h, dtype=np.float64)
        z = h[..., 2]
        zs = np.where(z > 0, z, 1.0)
        xm, ym = self._unscale(-h[..., 0] - self.xn * zs, -h[..., 1] - self.yn * zs)
        return np.where(z > 0, self.p22_std_over_z4(xm, ym, zs) / self._det, 0.0)

    def p22_std_over_z4(self, x, y, z):
        """``P_std(x / z, y / z) / z^4`` for ``z > 0`` (overridden where a stabler form exists).

        Parameters
        ----------
        x, y : array_like
            Standard slopes times ``z``.
        z : array_like
            ``z > 0`` (the normal's ``z``).

        Returns
        -------
        ndarray
            ``P_std(x / z, y / z) / z^4``.
        """
        return self.p22_std(x / z, y / z) / (z * z) ** 2

    # -------------------------------------------------------------- Smith masking
    def lambda_(self, k) -> np.ndarray:
        """Smith ``Lambda(k) = A(k) / c_k - 1 = Lambda_std(k')``; ``inf`` where ``c_k <= 0``.

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions.

        Returns
        -------
        (...) ndarray
            ``Lambda >= 0``.
        """
        return self._lambda_c(np.asarray(k, dtype=np.float64))[0]

    def _lambda_c(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Lambda(k), c_k)`` from the warped direction ``k' = (a, b, c)`` (Eq. 3.3)."""
        a, b, c = self._warp(k)
        return self.lambda_warped(a, b, c), c

    def lambda_warped(self, a, b, c):
        """Standard ``Lambda`` of the unnormalized direction ``k' = (a, b, c)`` (Eq. 3.3);
        ``inf`` where ``c <= 0``. Radial distributions depend on ``cot theta' = c / sqrt(a^2 + b^2)``
        only (Sec. 2.4); a non-radial (e.g. tabulated anisotropic) one overrides this.

        Parameters
        ----------
        a, b, c : array_like
            Components of the warped direction ``k'`` (need not be unit).

        Returns
        -------
        ndarray
            ``Lambda >= 0`` (``inf`` where ``c <= 0``).
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.lambda_std(np.where(c > 0, c / np.sqrt(a * a + b * b), 0.0))

    def projected_area(self, k) -> np.ndarray:
        """Projected area of the microsurface toward ``k``, ``A(k) = int <k,h>+ D(h) dw_h``.

        Equals ``c_k (1 + Lambda(k))`` with ``c_k = z_k - x_k x~n - y_k y~n`` (Eq. 3.3);
        0 where ``c_k <= 0``.

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions.

        Returns
        -------
        (...) ndarray
            ``A(k) >= 0`` (1 toward the normal of an unsheared surface).
        """
        lam, c = self._lambda_c(np.asarray(k, dtype=np.float64))
        with np.errstate(invalid="ignore"):
            return np.where(c > 0, c * (1.0 + lam), 0.0)

    def g1(self, k) -> np.ndarray:
        """Smith masking ``G1(k) = z_k / A(k) = (z_k / c_k) G1_std(k')`` (Eq. 2.14, 3.3).

        May exceed 1 for sheared surfaces; 0 for ``z_k <= 0`` or ``c_k <= 0``.

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions.

        Returns
        -------
        (...) ndarray
            ``G1 >= 0``.
        """
        k = np.asarray(k, dtype=np.float64)
        area = self.projected_area(k)
        ok = (k[..., 2] > 0) & (area > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ok, k[..., 2] / area, 0.0)

    # ----------------------------------------------------------- visible normals
    def vndf(self, h, k) -> np.ndarray:
        """Distribution of visible normals ``D_k(h) = <k,h>+ D(h) G1(k) / z_k`` (Eq. 2.17).

        Parameters
        ----------
        h : (..., 3) array_like
            Unit microfacet normals.
        k : (..., 3) array_like
            Unit view directions.

        Returns
        -------
        (...) ndarray
            ``D_k(h)``, per steradian.
        """
        h, k = np.asarray(h, float), np.asarray(k, float)
        area = self.projected_area(k)
        kh = np.maximum(dot(k, h), 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(area > 0, kh * self.ndf(h) / area, 0.0)

    def vp22(self, x, y, k) -> np.ndarray:
        """Distribution of visible slopes ``P_vis(h~; k)`` (Eq. 2.15).

        Parameters
        ----------
        x, y : array_like
            Slopes.
        k : (..., 3) array_like
            Unit view directions.

        Returns
        -------
        ndarray
            Density per unit slope area.
        """
        k = np.asarray(k, dtype=np.float64)
        area = self.projected_area(k)
        proj = np.maximum(k[..., 2] - k[..., 0] * x - k[..., 1] * y, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(area > 0, proj * self.p22(x, y) / area, 0.0)

    def sample_visible(self, u, k) -> np.ndarray:
        """Normal ``h`` distributed as ``vndf(., k)`` from uniforms ``u`` in ``[0,1)^2``.

        Samples the standard visible slopes from ``k'`` and maps them by Eq. 3.4
        (Sec. 2.2, 3.2). Directions with ``c_k <= 0`` see no microfacet; they return a
        normal whose ``vndf`` is 0.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.
        k : (..., 3) array_like
            Unit view directions.

        Returns
        -------
        (..., 3) ndarray
            Unit microfacet normals.
        """
        u = np.asarray(u, dtype=np.float64)
        k = np.asarray(k, dtype=np.float64)
        a, b, c = self._warp(k)
        a, b, c = np.broadcast_arrays(a, b, np.maximum(c, 0.0))
        r2 = a * a + b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_t = np.where(r2 > 0, c / np.sqrt(r2 + c * c), 1.0)      # of k'
            inv_r = np.where(r2 > 0, 1.0 / np.sqrt(r2), 0.0)
        cp, sp = np.where(r2 > 0, a * inv_r, 1.0), b * inv_r            # azimuth of k'
        shape = np.broadcast_shapes(u.shape[:-1], cos_t.shape)
        m = self.sample_visible_std(np.broadcast_to(u, shape + (2,)), np.broadcast_to(cos_t, shape))
        m = np.stack([cp * m[..., 0] - sp * m[..., 1], sp * m[..., 0] + cp * m[..., 1], m[..., 2]], -1)
        return self._normal_from_standard(m)

    def sample_p22(self, u) -> np.ndarray:
        """Normal ``h`` whose slope is distributed as ``P`` (density ``D(h) z_h``).

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.

        Returns
        -------
        (..., 3) ndarray
            Unit microfacet normals.
        """
        return self._normal_from_standard(self.sample_p22_std(np.asarray(u, dtype=np.float64)))

    # --------------------------------------------------------- standard form API
    second_moment_std: float = np.nan
    #: Whether ``sample_visible`` exists; Smith BRDFs then sample visible normals,
    #: otherwise slopes of ``P`` (``supports_smith_vndf_sampling``, Listing 2.1).
    supports_visible_sampling: bool = True

    @staticmethod
    def p22_std(x, y):  # pragma: no cover - interface
        """Standard slope PDF ``P_std(x~, y~)`` (``alpha = 1``, no shear; Table 2.II).

        Parameters
        ----------
        x, y : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope area.
        """
        raise NotImplementedError

    @staticmethod
    def p1_std(x):  # pragma: no cover - interface
        """Standard marginal slope PDF ``P1(x~) = int P_std(x~, y~) dy~`` (Eq. 2.39).

        Parameters
        ----------
        x : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope.
        """
        raise NotImplementedError

    @staticmethod
    def lambda_std(cot_theta):  # pragma: no cover - interface
        """Standard Smith ``Lambda`` of a direction of elevation ``theta`` (Table 2.III).

        Parameters
        ----------
        cot_theta : array_like
            ``cot theta`` of the direction; ``<= 0`` gives ``inf``.

        Returns
        -------
        ndarray
            ``Lambda >= 0``.
        """
        raise NotImplementedError

    def g1_std(self, cot_theta):
        """Standard Smith masking ``G1 = 1 / (1 + Lambda)`` (Table 2.III).

        Parameters
        ----------
        cot_theta : array_like
            ``cot theta`` of the direction.

        Returns
        -------
        ndarray
            ``G1`` in ``[0, 1]``.
        """
        return 1.0 / (1.0 + self.lambda_std(cot_theta))

    @staticmethod
    def sample_visible_std(u, cos_theta):  # pragma: no cover - interface
        """Standard visible normal for a view at ``theta`` in the xz plane (Sec. 2.2).

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
        raise NotImplementedError

    @staticmethod
    def sample_p22_std(u):  # pragma: no cover - interface
        """Standard normal whose slope is distributed as ``P_std``.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.

        Returns
        -------
        (..., 3) ndarray
            Unit normals of the standard surface.
        """
        raise NotImplementedError
