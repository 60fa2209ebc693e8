"""Beckmann slope distribution (thesis Tables 2.II, 2.III, 2.V)."""
from __future__ import annotations

import numpy as np

from ..geometry import sin_from_cos
from .base import SlopeDistribution

__all__ = ["Beckmann", "visible_slope_cdf", "visible_slope_quantile"]


def _scipy_special(name: str):
    """SciPy's special function ``name``, imported at its first call rather than with the
    package (SciPy's import is a noticeable part of every command's start)."""
    def f(x):
        from scipy import special
        return getattr(special, name)(x)
    f.__name__ = name
    return f


erfc, erfcx, erfinv = (_scipy_special(name) for name in ("erfc", "erfcx", "erfinv"))

_SQRT_PI = np.sqrt(np.pi)
_U_MIN = 2.0**-53  # uniforms are clamped to [_U_MIN, 1 - _U_MIN]


_GL_T, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_T, _GL_W = 0.5 * (_GL_T + 1.0), 0.5 * _GL_W      # on [0, 1]


def _cdf(x, t):
    """Unnormalized CDF of the standard visible x-slope, ``erfc(-x) + t exp(-x^2)/sqrt(pi)``."""
    return erfc(-x) + t * np.exp(-x * x) / _SQRT_PI


def _ccdf(x, t, a, erfc_a=None, exp_a=None):
    """Unnormalized complementary CDF, ``2 t / sqrt(pi) int_x^a (a - s) exp(-s^2) ds``.

    Closed form ``erfc(x) - erfc(a) + t (exp(-a^2) - exp(-x^2)) / sqrt(pi)`` far from
    ``a``; where ``a - x < 1`` it cancels, so a 12-point Gauss-Legendre rule of
    ``int_0^{a-x} s exp(-(a-s)^2) ds`` (exact to double precision there) is used instead.
    """
    erfc_a = erfc(a) if erfc_a is None else erfc_a
    exp_a = np.exp(-a * a) if exp_a is None else exp_a
    out = erfc(x) - erfc_a + t * (exp_a - np.exp(-x * x)) / _SQRT_PI
    near = a - x < 1.0
    if np.any(near):
        an, tn = a[near], t[near]
        dn = (an - x[near])[:, None]
        s = dn * _GL_T
        out[near] = 2.0 * tn / _SQRT_PI * dn[:, 0] * np.sum(_GL_W * s * np.exp(-(an[:, None] - s) ** 2), axis=-1)
    return out


def _pdf(x, t):
    """Unnormalized PDF ``2 exp(-x^2) (1 - x t) / sqrt(pi)`` = derivative of :func:`_cdf`."""
    return 2.0 * np.exp(-x * x) * (1.0 - x * t) / _SQRT_PI


def _view(cos_theta):
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 1e-12, 1.0)
    s = sin_from_cos(c)
    with np.errstate(divide="ignore"):
        a = c / s
    t = s / c
    return t, a, erfc(-a) + t * np.exp(-a * a) / _SQRT_PI


def visible_slope_cdf(x, cos_theta, complement: bool = False):
    """CDF ``F2(x~)`` (or ``1 - F2`` with ``complement``) of the standard visible x-slope
    seen from ``theta`` in the xz plane (Sec. 2.2, Table 2.V).

    ``P2(x~) ∝ (cot theta - x~) exp(-x~^2)`` on ``x~ < cot theta``, so
    ``F2(x~) = (erfc(-x~) + t exp(-x~^2)/sqrt(pi)) / (erfc(-a) + t exp(-a^2)/sqrt(pi))``
    with ``a = cot theta``, ``t = tan theta``.

    Parameters
    ----------
    x : array_like
        Standard x-slopes.
    cos_theta : array_like
        ``cos theta`` of the view, ``(0, 1]``.
    complement : bool
        Return ``1 - F2`` (accurate in the upper tail).

    Returns
    -------
    ndarray
        ``F2(x~)`` (or ``1 - F2``) in ``[0, 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> visible_slope_cdf(np.array([-10.0, 0.0, 10.0]), 1.0).round(4)    # view along the normal
    array([0. , 0.5, 1. ])
    """
    x, cos_theta = np.broadcast_arrays(np.asarray(x, float), np.asarray(cos_theta, float))
    t, a, z = _view(cos_theta)
    xa = np.minimum(x, a)
    inside = (_ccdf(xa, t, a) if complement else _cdf(xa, t)) / z
    return np.where(x >= a, 0.0 if complement else 1.0, inside)


def visible_slope_quantile(u, cos_theta, max_iter: int = 64):
    """Quantile ``Q2(u) = F2^{-1}(u)`` of :func:`visible_slope_cdf`, to double precision.

    Safeguarded Newton-bisection on ``F2 - u`` for ``u < 1/2`` and on
    ``(1 - u) - (1 - F2)`` otherwise, so both tails keep full relative precision.

    Parameters
    ----------
    u : array_like
        Probabilities in ``[0, 1]``.
    cos_theta : array_like
        ``cos theta`` of the view, ``(0, 1]``.
    max_iter : int
        Iterations of the Newton-bisection.

    Returns
    -------
    ndarray
        Standard x-slopes.

    Examples
    --------
    >>> import numpy as np
    >>> x = visible_slope_quantile(np.array([0.25, 0.5, 0.75]), 0.5)
    >>> visible_slope_cdf(x, 0.5).round(12)                             # the inverse of the CDF
    array([0.25, 0.5 , 0.75])
    """
    u = np.clip(np.asarray(u, dtype=np.float64), _U_MIN, 1.0 - _U_MIN)
    u, cos_theta = np.broadcast_arrays(u, np.asarray(cos_theta, dtype=np.float64))
    t, a, z = _view(cos_theta)
    shape = u.shape
    u, t, a, z = (v.ravel() for v in (u, t, a, z))
    upper = u >= 0.5
    target = np.where(upper, 1.0 - u, u) * z
    lo = np.full_like(u, -8.0)
    hi = np.minimum(a, 8.0)
    x = np.clip(erfinv(2.0 * u - 1.0), lo, hi)
    erfc_a, exp_a = erfc(a), np.exp(-a * a)
    out = x.copy()
    idx = np.arange(u.size)
    for _ in range(max_iter):
        r = np.empty_like(x)                                   # increasing in x
        r[~upper] = _cdf(x[~upper], t[~upper]) - target[~upper]
        r[upper] = target[upper] - _ccdf(x[upper], t[upper], a[upper], erfc_a[upper], exp_a[upper])
        lo = np.where(r < 0, x, lo)
        hi = np.where(r > 0, x, hi)
        pdf = _pdf(x, t)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = r / pdf
        xn = x - step
        # Newton converges quadratically: a step this small leaves an error ~ step^2
        converged = (np.abs(step) <= 1e-12 * np.maximum(1.0, np.abs(x))) | (r == 0)
        bad = ~converged & ~((xn > lo) & (xn < hi))
        xn = np.where(bad, 0.5 * (lo + hi), xn)
        done = converged | (hi - lo <= 4e-16 * np.maximum(1.0, np.abs(x)))
        out[idx] = xn
        keep = ~done
        if not keep.any():
            break
        idx, x, t, a, target, upper, lo, hi, erfc_a, exp_a = (
            v[keep] for v in (idx, xn, t, a, target, upper, lo, hi, erfc_a, exp_a))
    return out.reshape(shape)


class Beckmann(SlopeDistribution):
    """Beckmann (Gaussian) slopes: ``P_std(x~, y~) = exp(-x~^2 - y~^2) / pi`` (Table 2.II).

    Slope standard deviation per axis is ``alpha / sqrt(2)`` (the thesis's, Mitsuba's and
    pbrt's convention).

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
    >>> d = Beckmann(alpha=0.2)
    >>> float(d.ndf(np.array([0.0, 0.0, 1.0])).round(4))   # D(n) = 1 / (pi alpha^2)
    7.9577
    >>> round(1 / (np.pi * 0.2**2), 4)
    7.9577
    >>> float(d.g1(np.array([np.sin(1.2), 0.0, np.cos(1.2)])).round(4))   # Smith masking at 69 degrees
    0.9997
    """

    second_moment_std = 0.5  # E[x~^2] of the standard surface (Eq. 3.17)

    @classmethod
    def from_moments(cls, e1, e2, e3, e4, e5) -> "Beckmann":
        """Beckmann surface of linear slope moments ``E[x~], E[y~], E[x~^2], E[y~^2], E[x~y~]``
        (Eq. 3.5-3.9): ``alpha_x^2 = 2 (E3 - E1^2)``, ``alpha_y^2 = 2 (E4 - E2^2)``,
        ``rho = 2 (E5 - E1 E2) / (alpha_x alpha_y)``.

        Parameters
        ----------
        e1, e2, e3, e4, e5 : float or array_like
            ``E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~]``.

        Returns
        -------
        Beckmann
            The distribution with these moments.
        """
        e1, e2, e3, e4, e5 = (np.asarray(e, dtype=np.float64) for e in (e1, e2, e3, e4, e5))
        vx, vy = e3 - e1 * e1, e4 - e2 * e2
        if np.any(vx <= 0) or np.any(vy <= 0):
            raise ValueError("slope moments need E[x~^2] > E[x~]^2 and E[y~^2] > E[y~]^2")
        ax, ay = np.sqrt(2.0 * vx), np.sqrt(2.0 * vy)
        return cls(alpha_x=ax, alpha_y=ay, rho=2.0 * (e5 - e1 * e2) / (ax * ay),
                   mean_slope=np.stack(np.broadcast_arrays(e1, e2), axis=-1))

    @staticmethod
    def p22_std(x, y):
        return np.exp(-x * x - y * y) / np.pi

    @staticmethod
    def p22_std_over_z4(x, y, z):
        with np.errstate(over="ignore", divide="ignore"):
            return np.exp(-(x * x + y * y) / (z * z) - 4.0 * np.log(z)) / np.pi

    @staticmethod
    def p1_std(x):
        """Marginal ``P1(x~) = exp(-x~^2) / sqrt(pi)`` (Eq. 2.39).

        Parameters
        ----------
        x : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope.
        """
        return np.exp(-np.asarray(x, float) ** 2) / _SQRT_PI

    @staticmethod
    def lambda_std(cot_theta):
        """``Lambda(v) = (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2``, ``v = cot theta`` (Table 2.III),
        written with ``erfcx`` so that it stays accurate for large ``v``; ``inf`` for ``v <= 0``.

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
        return np.where(v > 0, _lambda(np.maximum(v, 0.0)), np.inf)

    @classmethod
    def lambda_warped(cls, a, b, c):
        r2 = a * a + b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            return _lambda(np.where(c > 0, c / np.sqrt(r2), 0.0))

    @staticmethod
    def sample_visible_std(u, cos_theta):
        """Standard visible normal for a view at ``theta`` in the xz plane: ``x~ = Q2(u1)``
        (numerically inverted, :func:`visible_slope_quantile`), ``y~ = erfinv(2 u2 - 1)``
        (Table 2.V).

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
        u = np.asarray(u, dtype=np.float64)
        x = visible_slope_quantile(u[..., 0], cos_theta)
        y = erfinv(2.0 * np.clip(u[..., 1], _U_MIN, 1.0 - _U_MIN) - 1.0)
        return _slope_normal(x, y)

    @staticmethod
    def sample_p22_std(u):
        """Standard normal with Gaussian slopes ``x~, y~ = erfinv(2u - 1)``.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1)``.

        Returns
        -------
        (..., 3) ndarray
            Unit normals of the standard surface.
        """
        s = erfinv(2.0 * np.clip(np.asarray(u, float), _U_MIN, 1.0 - _U_MIN) - 1.0)
        return _slope_normal(s[..., 0], s[..., 1])


def _lambda(v):
    """Beckmann Lambda for ``v >= 0`` (``inf`` at 0, 0 at ``inf``)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.maximum(0.5 * np.exp(-v * v) * (1.0 / (v * _SQRT_PI) - erfcx(v)), 0.0)


def _slope_normal(x, y):
    inv = 1.0 / np.sqrt(1.0 + x * x + y * y)
    return np.stack([-x * inv, -y * inv, inv], axis=-1)
