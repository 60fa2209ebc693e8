"""Noncentral slope distributions in Dr.Jit (thesis Ch. 2.3, 3.2): the Mitsuba twin of
:mod:`microfacet.distributions`.

Same math, same names, same branch structure as the NumPy oracle
(:class:`microfacet.distributions.base.SlopeDistribution`), written with Dr.Jit operations
on the arrays of the current Mitsuba variant, so that it traces into the renderer's own
kernels (one lane per shading point; no Python per lane). A :class:`Lobe` holds the
per-lane parameters ``(alpha_x, alpha_y, rho, x~n, y~n)`` read from textures.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

__all__ = ["Lobe", "BECKMANN", "GGX", "beckmann_visible_slope_quantile", "NEWTON_STEPS", "ratio"]

#: Name of the Beckmann slope distribution (Table 2.II).
BECKMANN = "beckmann"
#: Name of the GGX (Trowbridge-Reitz) slope distribution (Table 2.II).
GGX = "ggx"
INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
U_MIN = 1e-6        # float32 uniforms are clamped to [U_MIN, 1 - U_MIN] (as Mitsuba's Beckmann)
NEWTON_STEPS = 4    # fixed count of the Beckmann visible-slope inversion (see its docstring)


def ratio(num, den, ok):
    """``num / den`` where ``ok``, else 0, never dividing by 0.

    The scalar variants compute with Python floats, which raise instead of giving inf.

    Parameters
    ----------
    num, den : Float
        Numerator and denominator.
    ok : Bool
        The lanes where ``den`` may be divided by.

    Returns
    -------
    Float

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.slopes import ratio
    >>> ratio(1.0, 4.0, True), ratio(1.0, 0.0, False)
    (0.25, 0.0)
    """
    return dr.select(ok, num / dr.select(ok, den, 1.0), 0.0)


def beckmann_visible_slope_quantile(u, cos_theta):
    """Quantile ``x~ = Q2(u)`` of the standard Beckmann visible x-slope seen from ``theta``
    (Sec. 2.2, Table 2.V), vectorized with a fixed number of Newton steps.

    ``F2(x~) = (1 + erf(x~) + t exp(-x~^2)/sqrt(pi)) / (1 + erf(a) + t exp(-a^2)/sqrt(pi))``,
    ``a = cot theta``, ``t = tan theta``. We solve ``G(b) = Z u`` in the erf domain
    ``b = erf(x~)`` (as Mitsuba does), where ``G(b) = 1 + b + t exp(-erfinv(b)^2)/sqrt(pi)``
    is increasing and concave (``G' = 1 - t erfinv(b)``, ``G'' = -t dx~/db``). The initial
    guess is the exact solution at ``theta = pi/2``,
    ``b0 = erf(a) - (1 + erf(a)) erf(sqrt(-log u))``; a Newton step of a concave increasing
    function lands at or left of the root and the following ones then increase
    monotonically and quadratically to it, so ``b`` is clamped into ``(-1, erf(a)]`` and
    :data:`NEWTON_STEPS` steps reach float32 precision over ``u`` in ``[1e-6, 1 - 1e-6]`` and
    all views (checked against the float64 oracle
    :func:`microfacet.distributions.beckmann.visible_slope_quantile` in the tests).

    Parameters
    ----------
    u : Float
        A uniform number, clamped into ``[1e-6, 1 - 1e-6]``.
    cos_theta : Float
        Cosine of the view's elevation, clamped into ``[1e-6, 1]``.

    Returns
    -------
    Float
        The standard visible x-slope ``x~``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.slopes import NEWTON_STEPS, beckmann_visible_slope_quantile
    >>> from microfacet.distributions.beckmann import visible_slope_quantile
    >>> NEWTON_STEPS, round(beckmann_visible_slope_quantile(0.3, 0.5), 6)
    (4, -0.863384)
    >>> round(float(visible_slope_quantile(0.3, 0.5)), 6)     # the float64 oracle
    -0.863384
    """
    c = dr.clip(cos_theta, 1e-6, 1.0)
    t = dr.safe_sqrt(1.0 - c * c) / c
    a = c / dr.maximum(dr.safe_sqrt(1.0 - c * c), 1e-12)
    b_max = dr.erf(a)
    u = dr.clip(u, U_MIN, 1.0 - U_MIN)
    target = u * (1.0 + b_max + INV_SQRT_PI * t * dr.exp(-a * a))
    b = b_max - (b_max + 1.0) * dr.erf(dr.sqrt(-dr.log(u)))
    b_min = -1.0 + 2.0**-24
    for _ in range(NEWTON_STEPS):
        x = dr.erfinv(b)
        g = 1.0 + b + INV_SQRT_PI * t * dr.exp(-x * x) - target
        b = dr.clip(b - g / dr.maximum(1.0 - x * t, 1e-7), b_min, b_max)
    return dr.erfinv(b)


class Lobe:
    """Per-lane slope distribution ``P(x~, y~; alpha_x, alpha_y, rho, x~n, y~n)``.

    A standard ``kind`` distribution (``"beckmann"`` or ``"ggx"``) under the slope map of
    Eq. 3.4: the Dr.Jit twin of :class:`microfacet.distributions.base.SlopeDistribution`
    (:meth:`ndf`, :meth:`g1`, :meth:`vndf`, :meth:`sample_visible`, :meth:`sample_p22`, same
    names and formulas).

    Parameters
    ----------
    kind : str
        ``"beckmann"`` or ``"ggx"``.
    alpha_x, alpha_y : Float
        Roughness along x and y.
    rho : Float
        Slope correlation in ``(-1, 1)``.
    xn, yn : Float
        Mean slope ``(x~n, y~n)``.

    Examples
    --------
    The terms equal the NumPy oracle's:

    >>> import numpy as np
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.slopes import BECKMANN, GGX, Lobe
    >>> BECKMANN, GGX
    ('beckmann', 'ggx')
    >>> lobe = Lobe(BECKMANN, 0.2, 0.4, 0.3, 0.1, 0.0)
    >>> oracle = mf.Beckmann(alpha_x=0.2, alpha_y=0.4, rho=0.3, mean_slope=(0.1, 0.0))
    >>> h, k = np.array([0.1, 0.2, 0.97]) / 0.99519, np.array([0.3, 0.1, 0.9]) / 0.953939
    >>> round(lobe.ndf(mi.Vector3f(*h)), 5), round(float(oracle.ndf(h)), 5)
    (1.5694, 1.5694)
    >>> round(lobe.g1(mi.Vector3f(*k)), 6), round(float(oracle.g1(k)), 6)
    (1.034483, 1.034483)
    """

    def __init__(self, kind: str, alpha_x, alpha_y, rho, xn, yn):
        self.kind = kind
        self.alpha_x, self.alpha_y, self.rho, self.xn, self.yn = alpha_x, alpha_y, rho, xn, yn
        self.sqrt_one_minus_rho2 = dr.sqrt(1.0 - rho * rho)
        self.det = alpha_x * alpha_y * self.sqrt_one_minus_rho2    # Jacobian, Eq. 2.27

    # ------------------------------------------------------- standard <-> general
    def _unscale(self, dx, dy):
        """Inverse of the linear (roughness) part of Eq. 3.4 applied to slope offsets."""
        return dx / self.alpha_x, (self.alpha_x * dy - self.rho * self.alpha_y * dx) / self.det

    def _normal_from_standard(self, m):
        """Eq. 3.4 applied to a standard normal ``m`` (division-free, ``m_z >= 0``)."""
        hx = self.alpha_x * m.x - self.xn * m.z
        hy = self.alpha_y * (self.rho * m.x + self.sqrt_one_minus_rho2 * m.y) - self.yn * m.z
        return dr.normalize(mi.Vector3f(hx, hy, m.z))

    def warp(self, k):
        """Unnormalized standard direction ``k' = (a, b, c)`` of ``k`` (Eq. 3.3).

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        a, b, c : Float
            The components of ``k'``.
        """
        a = self.alpha_x * k.x + self.rho * self.alpha_y * k.y
        b = self.alpha_y * self.sqrt_one_minus_rho2 * k.y
        return a, b, k.z - k.x * self.xn - k.y * self.yn

    # ------------------------------------------------------------------- NDF
    def ndf(self, h):
        """``D(h) = P_std(X/z, Y/z) / (z^4 det)`` with ``(X, Y) = z m~`` (Eq. 2.11, 3.2);
        0 below the horizon (division-free, as the oracle's ``ndf``).

        Parameters
        ----------
        h : Vector3f
            Unit normal, local frame.

        Returns
        -------
        Float
            ``D(h)`` in 1/sr.
        """
        z = dr.select(h.z > 0, h.z, 1.0)
        x, y = self._unscale(-h.x - self.xn * z, -h.y - self.yn * z)
        if self.kind == BECKMANN:     # exp(-(x^2 + y^2)/z^2 - 4 log z) / pi  (Table 2.II)
            p = dr.exp(-(x * x + y * y) / (z * z) - 4.0 * dr.log(z)) * (1.0 / math.pi)
        else:                         # 1 / (pi (z^2 + x^2 + y^2)^2)
            r = z * z + x * x + y * y
            p = 1.0 / (math.pi * r * r)
        return dr.select(h.z > 0, p / self.det, 0.0)

    # ---------------------------------------------------------- Smith masking
    def lambda_c(self, k):
        """``(Lambda(k), c_k)``: Smith ``Lambda`` of the warped direction ``k'`` (Eq. 3.3,
        Table 2.III) and ``c_k = z_k - x_k x~n - y_k y~n``; ``Lambda`` is only meaningful
        where ``c_k > 0`` (callers mask the rest).

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        lam : Float
            Smith ``Lambda`` of ``k'``.
        c : Float
            ``c_k``.
        """
        a, b, c = self.warp(k)
        r2 = a * a + b * b
        cp = dr.maximum(c, 1e-30)
        if self.kind == BECKMANN:
            # (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2, v = c / sqrt(r2); 0 at r2 = 0
            v = cp * dr.rsqrt(dr.maximum(r2, 1e-30))
            lam = dr.maximum(0.5 * (dr.exp(-v * v) * INV_SQRT_PI / v - (1.0 - dr.erf(v))), 0.0)
        else:
            # (|k'| - c) / (2c) = r2 / (2c (|k'| + c)), without cancellation
            lam = r2 / (2.0 * cp * (dr.sqrt(r2 + cp * cp) + cp))
        return lam, c

    def projected_area(self, k):
        """``A(k) = c_k (1 + Lambda(k))`` (Eq. 3.3); 0 where ``c_k <= 0``.

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        Float
            ``A(k)``.
        """
        lam, c = self.lambda_c(k)
        return dr.select(c > 0, c * (1.0 + lam), 0.0)

    def g1(self, k):
        """Smith masking ``G1(k) = z_k / A(k)`` (Eq. 2.14, 3.3); 0 for ``z_k <= 0`` or ``c_k <= 0``.

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        Float
            ``G1(k)`` in ``[0, 1]``.
        """
        area = self.projected_area(k)
        return ratio(k.z, area, (k.z > 0) & (area > 0))

    # -------------------------------------------------------- visible normals
    def vndf(self, h, k):
        """``D_k(h) = <k,h>+ D(h) / A(k)`` (Eq. 2.17).

        Parameters
        ----------
        h : Vector3f
            Unit normal, local frame.
        k : Vector3f
            Unit view direction, local frame.

        Returns
        -------
        Float
            ``D_k(h)`` in 1/sr.
        """
        area = self.projected_area(k)
        kh = dr.maximum(dr.dot(k, h), 0.0)
        return ratio(kh * self.ndf(h), area, area > 0)

    def sample_visible(self, u, k):
        """Normal ``h`` distributed as :meth:`vndf` ``(., k)``: standard visible slopes
        sampled from ``k'`` (Table 2.V) and mapped by Eq. 3.4 (Sec. 2.2, 3.2).

        Parameters
        ----------
        u : Point2f
            Uniform numbers in ``[0, 1)^2``.
        k : Vector3f
            Unit view direction, local frame.

        Returns
        -------
        Vector3f
            Unit normal, local frame.
        """
        a, b, c = self.warp(k)
        c = dr.maximum(c, 0.0)
        r2 = a * a + b * b
        has_r = r2 > 0
        cos_t = dr.select(has_r, c * dr.rsqrt(r2 + c * c), 1.0)           # of k'
        inv_r = dr.select(has_r, dr.rsqrt(dr.select(has_r, r2, 1.0)), 0.0)
        cp, sp = dr.select(has_r, a * inv_r, 1.0), b * inv_r               # azimuth of k'
        m = self.sample_visible_std(u, cos_t)
        m = mi.Vector3f(cp * m.x - sp * m.y, sp * m.x + cp * m.y, m.z)
        return self._normal_from_standard(m)

    def sample_visible_std(self, u, cos_theta):
        """Standard visible normal for a view at ``theta`` in the xz plane (Table 2.V).

        Beckmann: ``x~ = Q2(u1)`` (:func:`beckmann_visible_slope_quantile`),
        ``y~ = erfinv(2 u2 - 1)``. GGX: the closed form of Heitz (JCGT 2018), a uniform disk
        point warped onto the visible half of the unit ellipsoid, as the oracle's.

        Parameters
        ----------
        u : Point2f
            Uniform numbers in ``[0, 1)^2``.
        cos_theta : Float
            ``cos theta`` of the standard view direction.

        Returns
        -------
        Vector3f
            Unit standard normal.
        """
        if self.kind == BECKMANN:
            x = beckmann_visible_slope_quantile(u.x, cos_theta)
            y = dr.erfinv(2.0 * dr.clip(u.y, U_MIN, 1.0 - U_MIN) - 1.0)
            return slope_normal(x, y)
        c = dr.clip(cos_theta, 0.0, 1.0)
        s = dr.safe_sqrt(1.0 - c * c)
        p = mi.warp.square_to_uniform_disk_concentric(u)
        w = 0.5 * (1.0 + c)
        t1 = p.x
        t2 = (1.0 - w) * dr.safe_sqrt(1.0 - t1 * t1) + w * p.y
        tz = dr.safe_sqrt(1.0 - t1 * t1 - t2 * t2)
        return mi.Vector3f(s * tz - c * t2, t1, c * tz + s * t2)

    def sample_p22(self, u):
        """Normal whose slope is distributed as ``P`` (density ``D(h) z_h``): Beckmann
        ``x~, y~ = erfinv(2u - 1)``; GGX ``tan^2 theta = u1 / (1 - u1)``, ``phi = 2 pi u2``.

        Parameters
        ----------
        u : Point2f
            Uniform numbers in ``[0, 1)^2``.

        Returns
        -------
        Vector3f
            Unit normal, local frame.
        """
        if self.kind == BECKMANN:
            s = dr.erfinv(2.0 * dr.clip(u, U_MIN, 1.0 - U_MIN) - 1.0)
            m = slope_normal(s.x, s.y)
        else:
            sin_p, cos_p = dr.sincos(2.0 * math.pi * u.y)
            sin_t, cos_t = dr.sqrt(u.x), dr.safe_sqrt(1.0 - u.x)
            m = mi.Vector3f(sin_t * cos_p, sin_t * sin_p, cos_t)
        return self._normal_from_standard(m)


def slope_normal(x, y):
    """Normal ``(-x~, -y~, 1) / sqrt(1 + x~^2 + y~^2)`` of a slope (Eq. 2.10)."""
    inv = dr.rsqrt(1.0 + x * x + y * y)
    return mi.Vector3f(-x * inv, -y * inv, inv)
