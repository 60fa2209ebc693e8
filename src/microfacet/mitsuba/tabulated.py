"""Tabulated slope distributions and tables in Dr.Jit (thesis Ch. 4.2, 4.4; Dupuy et al.
2015): the Mitsuba twins of :mod:`microfacet.distributions.tabulated` and of
:class:`microfacet.fresnel.Tabulated`.

Same tables, same interpolation, same sampling as the NumPy oracle (the tables are
the oracle's own arrays, uploaded once as float32): ``D`` log-linear in ``theta``;
isotropic ``Lambda`` from the cubic Hermite ``L1`` table, visible slopes by inverting
the tail tables (bisection over the fine nodes, linear in ``s`` within a cell) and the
conditional CDF of ``y~``; anisotropic ``D`` log-bilinear on the oracle's refined grid
(its Catmull-Rom refinement in azimuth and elevation is precomputed there), ``Lambda``
from the bilinear projected-area table, slopes of ``P`` by cell, safeguarded Newton on
the cell marginal and the closed-form azimuth quantile. Every search is
a bisection with a fixed step count (enough for the table), so the code traces into
one branch-free kernel. Indices are clamped into their tables, so inactive lanes
(NaN, out of range) gather valid memory.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..distributions.tabulated import GL4_T, GL4_W, THETA_CAP, HALF_PI, TabulatedAnisotropic, TabulatedIsotropic
from .slopes import Lobe, slope_normal, ratio

__all__ = ["Table", "SortedSearch", "TabulatedIsotropicLobe", "TabulatedAnisotropicLobe", "tabulated_lobe",
           "InterpolatedColor", "luminance", "NEWTON_STEPS"]

#: Fixed Newton steps of the elevation sampling (safeguarded; float32 converges in < 8).
NEWTON_STEPS = 12
#: Newton steps within a refined anisotropic cell (started at the linear guess inside a
#: cell of ~1/8000 of the mass, the marginal is nearly linear: float32 converges in <= 4).
CELL_NEWTON_STEPS = 6
U_MIN = 2.0**-24


def _steps(width: int) -> int:
    """Bisection steps that shrink a bracket ``[lo, lo + width)`` to one index:
    ``ceil(log2(width))`` (each step leaves at most ``ceil(width / 2)``)."""
    return int(math.ceil(math.log2(width))) if width > 1 else 0


class Table:
    """A table read by indexing, clamped into its range.

    ``dr.gather`` of the variant's ``Float`` / ``Float64`` / ``UInt32``, or NumPy indexing in
    the scalar variants (whose ``Float`` is a Python float).

    Parameters
    ----------
    values : array_like
        The values (flattened).
    dtype : str, optional
        ``"float32"`` (default), ``"float64"`` or ``"uint32"``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.tabulated import Table
    >>> t = Table([1.0, 2.0, 4.0])
    >>> t[1], t[7], t[-1]                 # indices are clamped into the table
    (2.0, 4.0, 1.0)
    """

    def __init__(self, values, dtype: str = "float32"):
        a = np.ascontiguousarray(np.asarray(values).ravel(), dtype=dtype)
        self.size = a.size
        self.scalar = not dr.is_array_v(mi.Float)
        self.type = {"float32": mi.Float, "float64": mi.Float64, "uint32": mi.UInt32}[dtype]
        self.data = a if self.scalar else self.type(a)

    def __getitem__(self, index):
        """Value at ``index`` (clamped into the table)."""
        if self.scalar:
            return self.type(self.data[min(max(int(index), 0), self.size - 1)])
        index = dr.clip(mi.Int32(index), 0, self.size - 1)
        return dr.gather(self.type, self.data, mi.UInt32(index))


def index_of(x, n: int):
    """``floor(x)`` as an index clamped into ``[0, n - 1]`` (NaN gives 0)."""
    x = dr.select(x >= 0, x, 0.0)
    return mi.Int32(dr.minimum(x, float(n - 1)))


def bisect_le(f, target, lo, hi, steps: int):
    """Largest ``k`` in ``[lo, hi)`` with ``f(k) <= target`` for increasing ``f`` (``lo``
    assumed to qualify; ``hi`` an exclusive sentinel), ``steps`` halvings."""
    for _ in range(steps):
        go = hi - lo > 1
        mid = (lo + hi) >> 1
        value = f(mid)
        lo = dr.select(go & (value <= target), mid, lo)
        hi = dr.select(go & (value > target), mid, hi)
    return lo


_T_MIN, _R_MIN = 2.0**-48, 2.0**-24       # t and 1 - t are clamped to these (octaves)
_T_MIN_BITS, _R_MIN_BITS, _HALF_BITS = (int(np.float32(f).view(np.uint32)) for f in (_T_MIN, _R_MIN, 0.5))


class SortedSearch:
    """``k(v)``, the largest ``k`` in ``[0, n - 2]`` with ``x[k] <= v`` (0 if none), for sorted
    nodes ``x`` and ``v <= v_max``.

    What ``np.searchsorted(x, v, "right") - 1`` clipped into the intervals gives, found by the
    cutpoint method (Chen and Asau 1974; Devroye 1986, Sec. III.2.4): a guide maps the cell of
    ``v`` to the first node that can answer, and a bisection with the fixed step count of the
    widest bracket (:attr:`width` nodes) finishes. The cells are the octaves of ``t`` below 1/2
    (down to ``2^-48``) and of ``1 - t`` above (down to ``2^-24``),
    ``t = (v - x_0) / (x_(n-1) - x_0)`` (float32 exponent bits), each split into
    ``per_octave`` cells (high mantissa bits): fine at both ends, where CDF tables crowd (runs
    of nodes of tiny mass) and ``cos theta`` tables too. Exact: the nodes' cells are computed
    with the kernel's float32 operations, and each bracket is widened by one cell on either
    side.

    Parameters
    ----------
    x : array_like
        Sorted nodes (float32).
    v_max : float, optional
        The largest value searched.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import numpy as np
    >>> from microfacet.mitsuba.tabulated import SortedSearch
    >>> x = [0.0, 0.5, 0.75, 1.0]
    >>> search = SortedSearch(x)
    >>> [search(v) for v in (-1.0, 0.6, 0.75, 1.0)]
    [0, 1, 2, 2]
    >>> [int(k) for k in np.clip(np.searchsorted(x, [-1.0, 0.6, 0.75, 1.0], "right") - 1, 0, 2)]
    [0, 1, 2, 2]
    """

    def __init__(self, x, v_max: float = math.inf):
        x = np.asarray(x, dtype=np.float32).ravel()
        self.n = n = x.size
        per_octave = 1 << min(10, max(4, int(math.ceil(math.log2(n))) - 1))
        self.shift = 23 - int(math.log2(per_octave))
        self.half = (_HALF_BITS - _T_MIN_BITS) >> self.shift     # cells below t = 1/2
        self.cells = cells = self.half + ((_HALF_BITS - _R_MIN_BITS) >> self.shift) + 1
        self.x = Table(x)
        self.x0 = float(x[0])
        self.inv_range = float(np.float32(1.0 / max(float(x[-1]) - float(x[0]), 1e-30)))
        t = np.clip((x - np.float32(self.x0)) * np.float32(self.inv_range), np.float32(0), np.float32(1))
        bits = lambda f: f.view(np.uint32).astype(np.int64)  # noqa: E731
        cell = self._cell_of(t < 0.5, bits(np.maximum(t, np.float32(_T_MIN))),
                             bits(np.maximum(np.float32(1) - t, np.float32(_R_MIN))), np.where, np.clip)
        g = np.arange(cells)
        below = np.searchsorted(cell, np.maximum(g - 1, 0), side="left")          # nodes in cells < g - 1
        upto = np.searchsorted(cell, np.minimum(g + 1, cells - 1), side="right")  # nodes in cells <= g + 1
        last = np.clip(np.searchsorted(x, np.float32(min(v_max, x[-1])), side="right") - 1, 0, n - 2)
        lo = np.clip(below - 1, 0, last)
        hi = np.clip(upto - 1, lo, last)
        self.width = int((hi - lo).max()) + 1
        self.steps = _steps(self.width)
        self.guide = Table(lo, "uint32")

    def _cell_of(self, low, bits_t, bits_r, select, clip):
        """Cell from the float32 bits of ``t`` (``low``: ``t < 1/2``) or of ``1 - t``."""
        c = select(low, (bits_t - _T_MIN_BITS) >> self.shift, self.cells - 1 - ((bits_r - _R_MIN_BITS) >> self.shift))
        return clip(c, 0, self.cells - 1)

    def _cell(self, v):
        """The cell of ``v``, as in ``__init__`` but with Dr.Jit's float32 operations."""
        t = dr.clip((v - self.x0) * self.inv_range, 0.0, 1.0)
        q, r = dr.maximum(t, _T_MIN), dr.maximum(1.0 - t, _R_MIN)
        if self.x.scalar:
            bits_t, bits_r = (int(np.float32(f).view(np.uint32)) for f in (q, r))
        else:
            bits_t, bits_r = (mi.Int32(dr.reinterpret_array(mi.UInt32, mi.Float(f))) for f in (q, r))
        return self._cell_of(t < 0.5, bits_t, bits_r, dr.select, dr.clip)

    def __call__(self, v):
        lo = mi.Int32(self.guide[self._cell(v)])
        return bisect_le(lambda j: self.x[j], v, lo, dr.minimum(lo + self.width, self.n - 1), self.steps)


def expm1(x):
    """``exp(x) - 1`` without cancellation (Kahan: ``(u - 1) x / log u``, ``u = e^x``)."""
    u = dr.exp(x)
    d = u - 1.0
    return dr.select(d == 0.0, x, dr.select(u == 0.0, -1.0, d * ratio(x, dr.log(u), d != 0.0)))


def interval_integral(la, lb, ta, tb, theta):
    """``int_{ta}^{theta} D(s) cos s sin s ds`` for ``D`` log-linear from ``e^la`` to
    ``e^lb`` over ``[ta, tb]``, the closed form of
    :func:`microfacet.distributions.tabulated.interval_integral`."""
    beta = (lb - la) / (tb - ta)
    dt = theta - ta
    bd = beta * dt
    da = dr.exp(la)
    grow = dr.select(bd < 50.0, da * expm1(dr.minimum(bd, 50.0)), dr.exp(la + bd) - da)
    st = theta + ta
    out = (da * (2.0 * beta * dr.cos(st) + 4.0 * dr.sin(st)) * dr.sin(dt)
           + grow * (beta * dr.sin(2.0 * theta) - 2.0 * dr.cos(2.0 * theta)))
    return dr.maximum(out / (2.0 * (beta * beta + 4.0)), 0.0)


def invert_cdf(v, ta, tb, cdf, pdf, steps: int = NEWTON_STEPS):
    """``theta`` in ``[ta, tb]`` with ``cdf(theta) = v cdf(tb)``: safeguarded Newton
    (bisection when a step leaves the bracket), ``steps`` fixed steps, as
    :func:`microfacet.distributions.tabulated.invert_cdf`."""
    target = v * cdf(tb)
    lo, hi = ta, tb
    x = ta + v * (tb - ta)
    for _ in range(steps):
        f = cdf(x) - target
        lo = dr.select(f < 0, x, lo)
        hi = dr.select(f > 0, x, hi)
        p = pdf(x)
        xn = x - ratio(f, p, p > 0)
        bad = (xn <= lo) | (xn >= hi) | (p <= 0) | (xn != xn)
        x = dr.select(f == 0, x, dr.select(bad, 0.5 * (lo + hi), xn))
    return x


def sample_interval(v, ta, tb, las, lbs):
    """``theta`` in ``[ta, tb]`` with density ``∝ sum_c D_c cos sin`` from the uniform ``v``,
    each ``D_c`` log-linear: :func:`invert_cdf` on the closed-form CDF
    (:func:`interval_integral`), as :func:`microfacet.distributions.tabulated.sample_interval`."""
    def cdf(x):
        out = 0.0
        for la, lb in zip(las, lbs):
            out = out + interval_integral(la, lb, ta, tb, x)
        return out

    def pdf(x):
        w = (x - ta) / (tb - ta)
        out = 0.0
        for la, lb in zip(las, lbs):
            out = out + dr.exp(la + w * (lb - la))
        return out * 0.5 * dr.sin(2.0 * x)

    return invert_cdf(v, ta, tb, cdf, pdf)


def _normal(theta, phi):
    s, c = dr.sincos(theta)
    sp, cp = dr.sincos(phi)
    return mi.Vector3f(s * cp, s * sp, c)


class _TabulatedLobe(Lobe):
    """Shared parts of the tabulated lobes: the fit's (scalar) roughness map and the
    elevation grid of Listing 4.1."""

    def __init__(self, tables: "_Tables"):
        d = tables.dist
        super().__init__("tabulated", *(mi.Float(float(v)) for v in
                                         (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)))
        self.t = tables

    def _locate(self, theta):
        """Interval ``i`` and weight ``t`` of ``theta`` in the elevation grid
        (:func:`microfacet.distributions.tabulated.locate`)."""
        return self._locate_in(theta, self.t.n_theta)

    @staticmethod
    def _locate_in(theta, n: int):
        theta = dr.clip(theta, 0.0, HALF_PI)
        i = dr.minimum(index_of(dr.sqrt(theta / HALF_PI) * (n - 1), n), n - 2)
        fi = mi.Float(i)
        ta = (fi / (n - 1)) ** 2 * HALF_PI
        tb = ((fi + 1.0) / (n - 1)) ** 2 * HALF_PI
        return i, dr.clip((theta - ta) / (tb - ta), 0.0, 1.0)

    def ndf(self, h):
        """``D(h) = P_std(X/z, Y/z) / (z^4 det)`` with the interpolated table (Eq. 2.11).

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
        r2 = x * x + y * y
        q = z * z + r2
        p = self.d_interp(dr.atan2(dr.sqrt(r2), z), x, y) / (q * q)
        return dr.select(h.z > 0, p / self.det, 0.0)


class TabulatedIsotropicLobe(_TabulatedLobe):
    """:class:`~microfacet.distributions.tabulated.TabulatedIsotropic` under the fit's slope map
    (Eq. 3.4): radial ``P`` (Eq. 4.12), visible-normal sampling (Sec. 4.4).

    Made by :func:`tabulated_lobe`; its elevation sampling inverts its tables with
    :data:`NEWTON_STEPS` safeguarded Newton steps.

    Parameters
    ----------
    tables : _Tables
        The fit's tables (:func:`tabulated_lobe`).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import numpy as np
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tabulated import tabulated_lobe
    >>> from microfacet.mitsuba.tabulated import NEWTON_STEPS
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), 16)
    >>> lobe = tabulated_lobe(fit.distribution)()
    >>> type(lobe).__name__, NEWTON_STEPS
    ('TabulatedIsotropicLobe', 12)
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> bool(np.isclose(lobe.ndf(mi.Vector3f(*n)), fit.distribution.ndf(n), rtol=1e-5))
    True
    """

    def d_interp(self, theta, x=None, y=None):
        """``D`` interpolated log-linearly in ``theta``.

        Parameters
        ----------
        theta : Float
            Polar angle of the normal in radians.
        x, y : Float, optional
            Unused (the anisotropic lobe's azimuth).

        Returns
        -------
        Float
            The interpolated ``D``.
        """
        i, t = self._locate(theta)
        ld = self.t.log_ndf
        a = ld[i]
        return dr.exp(a + t * (ld[i + 1] - a))

    # ----------------------------------------------------------------- tables
    def _fine(self, xi):
        """Fine-grid coordinate ``s`` of the slope magnitude ``xi = tan(s^2 theta_cap)``."""
        return dr.sqrt(dr.minimum(dr.atan(xi), THETA_CAP) / THETA_CAP)

    def _l1(self, xi):
        """``L1(xi)``: cubic Hermite in ``s`` with ``dL1/ds = -L0 dxi/ds`` (the oracle's ``_L1``)."""
        m = self.t.m
        f = self._fine(xi) * (m - 1)
        k = dr.minimum(index_of(f, m), m - 2)
        t = dr.clip(f - mi.Float(k), 0.0, 1.0)
        y0, y1 = self.t.L1[k], self.t.L1[k + 1]
        d0, d1 = self.t.dL1[k], self.t.dL1[k + 1]
        t2 = t * t
        t3 = t2 * t
        val = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * d0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * d1
        return dr.maximum(val, 0.0)

    def lambda_c(self, k):
        """``(Lambda(k), c_k)`` with ``Lambda = L1(a) / a``, ``a = cot theta'`` of the warped
        direction (Eq. 2.14, 3.3).

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        lam : Float
            ``Lambda`` of ``k'``.
        c : Float
            ``c_k``.
        """
        a, b, c = self.warp(k)
        cot = dr.maximum(c, 1e-30) * dr.rsqrt(dr.maximum(a * a + b * b, 1e-30))
        return self._l1(cot) / cot, c

    # --------------------------------------------------------------- sampling
    def sample_visible_std(self, u, cos_theta):
        """Standard visible normal for a view at ``theta`` in the xz plane (Sec. 2.2, 4.4):
        ``x~`` inverts the visible CDF written with the tail tables, ``y~`` the
        conditional CDF (:meth:`TabulatedIsotropic.sample_visible_std`).

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
        c = dr.clip(cos_theta, 0.0, 1.0)
        sn = dr.safe_sqrt(1.0 - c * c)
        a = dr.minimum(c / dr.maximum(sn, 1e-30), 1e8)
        u1 = dr.clip(u.x, U_MIN, 1.0 - U_MIN)
        x = self._visible_x(a, u1)
        y = self._conditional_y(dr.abs(x), dr.clip(u.y, 0.0, 1.0))
        return slope_normal(x, y)

    def _visible_x(self, a, u1):
        t, m = self.t, self.t.m
        l1a = self._l1(a)
        z = a + l1a
        half = 0.5 * a + t.L1_0                     # x~ <= 0: F(0) Z = a / 2 + L1(0)
        left = u1 * z <= half
        target = dr.select(left, u1 * z, (1.0 - u1) * z)

        def f(k):    # decreasing: (a + xi) L0 + L1 left, (a - xi) L0 - L1 + L1(a) right
            l0, q = t.L0[k], t.xiL0_L1[k]
            return dr.select(left, a * l0 + q, a * l0 - q + l1a)

        s_a = self._fine(a)
        kmax = index_of(s_a * (m - 1), m)
        kmax = dr.select(mi.Float(kmax) / (m - 1) > s_a, kmax - 1, kmax)
        lo = dr.zeros(mi.Int32, dr.width(a)) if not t.scalar else 0
        hi = dr.select(left, m - 1, kmax + 1)
        k = bisect_le(lambda j: -f(j), -target, lo, hi, _steps(m))
        k = dr.select(left, dr.minimum(k, m - 2), k)
        kn = dr.minimum(k + 1, m - 1)
        at_end = (u1 * z > half) & (k + 1 > kmax)
        f0 = f(k)
        f1 = dr.select(at_end, 0.0, f(kn))
        s0 = mi.Float(k) / (m - 1)
        s_end = dr.select(at_end, s_a, mi.Float(kn) / (m - 1))
        w = dr.select(f0 > f1, ratio(f0 - target, f0 - f1, f0 > f1), 0.5)
        s = s0 + dr.clip(w, 0.0, 1.0) * (s_end - s0)
        xi = dr.tan(s * s * THETA_CAP)
        return dr.select(left, -xi, dr.minimum(xi, a))

    def _conditional_y(self, xi, u2):
        """``y~`` from the conditional CDF of ``|y~|`` given ``|x~| = xi``, rows mixed
        linearly in ``s`` (sign from ``u2``)."""
        m = self.t.m
        sign = dr.select(u2 >= 0.5, 1.0, -1.0)
        v = dr.clip(dr.abs(2.0 * u2 - 1.0), 0.0, 1.0 - U_MIN)
        f = self._fine(xi) * (m - 1)
        k = dr.minimum(index_of(f, m), m - 2)
        w = dr.clip(f - mi.Float(k), 0.0, 1.0)
        t, n = self.t, self.t.n_eta
        j0 = self._row_search(k, v, 0 * k, n - 1, _steps(n - 1))
        start = mi.Int32(t.next_row_start[k * n + j0])
        j1 = self._row_search(k + 1, v, start, dr.minimum(start + t.next_row_width, n - 1), t.next_row_steps)
        return sign * ((1.0 - w) * self._row_quantile(k, v, j0) + w * self._row_quantile(k + 1, v, j1))

    def _row_search(self, k, v, lo, hi, steps: int):
        """Largest ``j`` in ``[lo, hi)`` with ``y_cdf[k, j] <= v``, ``steps`` halvings."""
        row = k * self.t.n_eta
        return bisect_le(lambda j: self.t.y_cdf[row + j], v, lo, hi, steps)

    def _row_quantile(self, k, v, lo):
        """``tan eta`` at ``v`` in row ``k``, linear in ``eta`` within the interval ``lo``."""
        t = self.t
        row = k * t.n_eta
        c0, c1 = t.y_cdf[row + lo], t.y_cdf[row + lo + 1]
        w = dr.clip(ratio(v - c0, c1 - c0, c1 > c0), 0.0, 1.0)
        e0 = t.eta[lo]
        return dr.tan(e0 + w * (t.eta[lo + 1] - e0))

    def sample_p22(self, u):
        """Normal with slopes distributed as ``P``: ``theta`` from the marginal
        ``2 pi D cos sin`` (interval by its mass, then the closed-form CDF), ``phi = 2 pi u2``.

        Parameters
        ----------
        u : Point2f
            Uniform numbers in ``[0, 1)^2``.

        Returns
        -------
        Vector3f
            Unit normal, local frame.
        """
        t = self.t
        v = dr.clip(u.x, U_MIN, 1.0 - U_MIN)
        i = t.mass_search(v)
        c0 = t.mass_cdf[i]
        mass = t.mass_cdf[i + 1] - c0
        r = dr.clip(dr.select(mass > 0, ratio(v - c0, mass, mass > 0), 0.5), 0.0, 1.0)
        ld = t.log_ndf
        th = sample_interval(r, t.theta[i], t.theta[i + 1], (ld[i],), (ld[i + 1],))
        return self._normal_from_standard(_normal(th, 2.0 * math.pi * u.y))


class TabulatedAnisotropicLobe(_TabulatedLobe):
    """:class:`~microfacet.distributions.tabulated.TabulatedAnisotropic` under the fit's slope map.

    ``P`` over ``(theta, phi)`` log-bilinear on the refined grid (the oracle's ``log_ndf``,
    ``theta_fine`` x ``n_fine``), ``Lambda`` from the projected-area table (node azimuths),
    slopes of ``P`` sampled exactly from the interpolant (App. A). Made by
    :func:`tabulated_lobe`.

    Parameters
    ----------
    tables : _Tables
        The fit's tables (:func:`tabulated_lobe`).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import numpy as np
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tabulated import tabulated_lobe
    >>> brdf = mf.MicrofacetBRDF(mf.Beckmann(alpha_x=0.2, alpha_y=0.4, rho=0.3))
    >>> fit = mf.fit.fit(brdf, 12, anisotropic=True)
    >>> lobe = tabulated_lobe(fit.distribution)()
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> type(lobe).__name__, bool(np.isclose(lobe.ndf(mi.Vector3f(*n)), fit.distribution.ndf(n), rtol=1e-5))
    ('TabulatedAnisotropicLobe', True)
    """

    def _locate(self, theta):
        """Interval and weight of ``theta`` in the refined elevation grid."""
        return self._locate_in(theta, self.t.n_theta_fine)

    @staticmethod
    def _wrap(phi, n: int, dphi: float):
        """Interval ``j``, next node ``j1`` (periodic) and weight of ``phi`` on ``n`` azimuths."""
        f = (phi - 2.0 * math.pi * dr.floor(phi / (2.0 * math.pi))) / dphi
        j = index_of(f, n)
        w = dr.clip(f - mi.Float(j), 0.0, 1.0)
        j1 = dr.select(j + 1 >= n, 0 * j, j + 1)
        return j, j1, w

    def _log_column(self, i, j, t):
        """``ln D`` linear in ``theta`` along the refined azimuth ``j``."""
        ld, q = self.t.log_ndf, self.t.n_fine
        a = ld[i * q + j]
        return a + t * (ld[(i + 1) * q + j] - a)

    def d_interp(self, theta, x, y):
        """``D`` log-bilinear (the oracle's ``_d_interp``); ``phi = atan2(-y~, -x~)`` is the
        azimuth of the normal of slope ``(x~, y~)``.

        Parameters
        ----------
        theta : Float
            Polar angle of the normal in radians.
        x, y : Float
            Its standard slope ``(x~, y~)`` (for the azimuth).

        Returns
        -------
        Float
            The interpolated ``D``.
        """
        i, t = self._locate(theta)
        j, j1, w = self._wrap(dr.atan2(-y, -x), self.t.n_fine, self.t.dphi_fine)
        a = self._log_column(i, j, t)
        return dr.exp(a + w * (self._log_column(i, j1, t) - a))

    def lambda_c(self, k):
        """``(Lambda(k), c_k)``, ``Lambda = A(k') / cos theta_k' - 1`` from the bilinear
        projected-area table (Eq. 2.14, 3.3).

        Parameters
        ----------
        k : Vector3f
            Unit direction, local frame.

        Returns
        -------
        lam : Float
            ``Lambda`` of ``k'``.
        c : Float
            ``c_k``.
        """
        a, b, c = self.warp(k)
        r = dr.sqrt(a * a + b * b)
        th = dr.atan2(r, dr.maximum(c, 0.0))
        area = self._area(th, dr.atan2(b, a))
        lam = dr.maximum(area * ratio(dr.sqrt(r * r + c * c), c, c > 0) - 1.0, 0.0)
        return lam, c

    def _area(self, theta, phi):
        t = self.t
        n = t.n_lambda
        theta = dr.clip(theta, 0.0, HALF_PI)
        s = dr.asin(dr.sqrt(theta / HALF_PI)) / HALF_PI * (n - 1)
        i = dr.minimum(index_of(s, n), n - 2)
        t0, t1 = t.theta_k[i], t.theta_k[i + 1]
        wt = dr.clip((theta - t0) / (t1 - t0), 0.0, 1.0)
        j, j1, w = self._wrap(phi, t.n_phi, t.dphi)
        A = t.area
        q = t.n_phi

        def row(r):
            return (1.0 - w) * A[r * q + j] + w * A[r * q + j1]

        return (1.0 - wt) * row(i) + wt * row(i + 1)

    def sample_p22(self, u):
        """Normal whose slope is distributed as the interpolated ``P`` (App. A, the oracle's
        ``sample_p22_std``): a cell by its mass, ``theta`` by safeguarded Newton
        (:data:`CELL_NEWTON_STEPS`) on the cell marginal ``m(theta) = dphi D_j exp_mean(b)
        cos sin`` (its CDF by 4-point Gauss-Legendre from the cell's edge, where the
        oracle uses 8: on these small smooth cells both are exact to float32), ``phi`` in
        closed form
        ``w = log1p(v expm1(b)) / b``, ``b = ln D_(j+1) - ln D_j`` at ``theta``.

        Parameters
        ----------
        u : Point2f
            Uniform numbers in ``[0, 1)^2``.

        Returns
        -------
        Vector3f
            Unit normal, local frame.
        """
        t = self.t
        cdf = t.cell_cdf
        v = dr.clip(u.x, U_MIN, 1.0 - U_MIN) * t.cell_total
        c = t.cell_search(v)
        zero = 0 * c
        c0 = cdf[c]
        mass = cdf[c + 1] - c0
        r = dr.clip(dr.select(mass > 0, ratio(v - c0, mass, mass > 0), 0.5), 0.0, 1.0)
        q = t.n_fine
        i = c // q
        j = c - i * q
        j1 = dr.select(j + 1 >= q, zero, j + 1)
        ld = t.log_ndf
        a0, a1 = ld[i * q + j], ld[(i + 1) * q + j]            # ln D at the cell's corners
        b0, b1 = ld[i * q + j1] - a0, ld[(i + 1) * q + j1] - a1
        ta, tb = t.theta_fine[i], t.theta_fine[i + 1]
        inv_dt, da, db = 1.0 / (tb - ta), a1 - a0, b1 - b0

        def marginal(x):
            w = (x - ta) * inv_dt
            return dr.exp(a0 + w * da) * exp_mean(b0 + w * db) * 0.5 * dr.sin(2.0 * x)

        def partial(x):
            out = 0.0
            for gt, gw in zip(GL4_T, GL4_W):
                out = out + float(gw) * marginal(ta + (x - ta) * float(gt))
            return (x - ta) * out

        th = invert_cdf(r, ta, tb, partial, marginal, CELL_NEWTON_STEPS)
        w = dr.clip((th - ta) / (tb - ta), 0.0, 1.0)
        b = b0 + w * (b1 - b0)
        v2 = dr.clip(u.y, 0.0, 1.0)
        small = dr.abs(b) < 1e-4
        wphi = dr.select(small, v2 * (1.0 + 0.5 * b * (1.0 - v2)),
                         ratio(log1p(v2 * expm1(b)), b, dr.abs(b) >= 1e-4))
        wphi = dr.clip(dr.select(wphi == wphi, wphi, v2), 0.0, 1.0)
        return self._normal_from_standard(_normal(th, (mi.Float(j) + wphi) * t.dphi_fine))

    def sample_visible(self, u, k):  # pragma: no cover - guarded by samples_visible
        raise NotImplementedError("anisotropic tables sample slopes of P")


def log1p(x):
    """``log(1 + x)`` without cancellation (Kahan: ``log(u) x / (u - 1)``, ``u = 1 + x``)."""
    u = 1.0 + x
    d = u - 1.0
    return dr.select(d == 0.0, x, dr.log(u) * ratio(x, d, d != 0.0))


def exp_mean(b):
    """``int_0^1 e^(w b) dw = expm1(b) / b`` (``1 + b / 2`` near 0), as the oracle's; with
    Kahan's ``expm1(b) = (u - 1) b / log u`` (:func:`expm1`) the ``b`` cancels:
    ``(u - 1) / log u``, ``u = e^b`` (``-1 / b`` where ``u`` underflows)."""
    u = dr.exp(b)
    big = dr.abs(b) >= 1e-4
    return dr.select(big, dr.select(u == 0.0, ratio(-1.0, b, big), ratio(u - 1.0, dr.log(u), big & (u > 0.0))),
                     1.0 + 0.5 * b)


class _Tables:
    """The oracle distribution's tables as :class:`Table` s (built once per plugin)."""

    def __init__(self, dist):
        self.dist = dist
        self.scalar = not dr.is_array_v(mi.Float)
        self.n_theta = dist.n_theta
        self.theta = Table(dist.theta)
        if isinstance(dist, TabulatedIsotropic):
            self.log_ndf = Table(dist.log_ndf)
            self.m = len(dist.s_fine)
            h = dist.s_fine[1] - dist.s_fine[0]
            self.L0, self.L1 = Table(dist.L0), Table(dist.L1)
            self.L1_0 = float(np.float32(dist.L1[0]))
            self.xiL0_L1 = Table(dist.xi * dist.L0 + dist.L1)
            self.dL1 = Table(-dist.L0 * dist.dxi_ds * h)
            self.eta = Table(dist.eta_nodes[0])
            self.n_eta = dist.eta_nodes.shape[1]
            self.y_cdf = Table(dist.y_cdf)
            start, self.next_row_width = next_row_window(np.asarray(dist.y_cdf, dtype=np.float32)
                                                         .reshape(dist.eta_nodes.shape), 1.0 - U_MIN)
            self.next_row_start = Table(start, "uint32")
            self.next_row_steps = _steps(self.next_row_width)
            self.mass_cdf = Table(dist._mass_cdf)
            self.mass_search = SortedSearch(dist._mass_cdf, 1.0 - U_MIN)
            self.lobe = TabulatedIsotropicLobe
        else:
            self.n_phi, self.dphi = dist.n_phi, float(dist.dphi)
            self.n_fine, self.dphi_fine = dist.n_fine, float(dist.dphi_fine)
            self.n_theta_fine = dist.n_theta_fine
            self.theta_fine = Table(dist.theta_fine)
            self.log_ndf = Table(dist.log_ndf)
            self.theta_k = Table(dist.theta_k)
            self.n_lambda = len(dist.theta_k)
            self.area = Table(dist.area_table)
            self.cell_cdf = Table(dist._cell_cdf)
            self.cell_total = float(np.float32(dist._cell_cdf[-1]))
            self.cell_search = SortedSearch(dist._cell_cdf, float(np.float32(1.0 - U_MIN) * np.float32(self.cell_total)))
            self.lobe = TabulatedAnisotropicLobe


def next_row_window(cdf: np.ndarray, v_max: float) -> tuple[np.ndarray, int]:
    """``(start, width)``: where ``j`` is row ``k``'s answer (the largest ``j <= n - 2`` with
    ``cdf[k, j] <= v``, ``0 <= v <= v_max``), row ``k + 1``'s answer lies in
    ``[start[k, j], start[k, j] + width)``, for the conditional CDF rows (as float32)
    of neighbouring fine nodes, which differ little: a short bisection there instead of
    one over the whole row. Empty intervals (never an answer) are skipped."""
    m, n = cdf.shape
    c = cdf.astype(np.float64)
    v_max = float(np.float32(v_max))

    def answer(row, v):                    # the largest j <= n - 2 with row[j] <= v, >= 0
        return np.clip(np.searchsorted(row, v, side="right") - 1, 0, n - 2)

    start = np.zeros((m, n), dtype=np.int64)
    width = 1
    for k in range(m - 1):
        a, b = c[k], c[k + 1]
        lo = np.where(np.arange(n - 1) == 0, 0, answer(b, a[:-1]))
        top = np.append(np.minimum(a[1:-1], v_max), v_max)       # v < a[j + 1] (or v_max at the end)
        hi = answer(b, top)
        live = ((a[:-1] < a[1:]) | (np.arange(n - 1) == n - 2)) & (a[:-1] <= v_max)
        start[k, :-1] = lo
        if live.any():
            width = max(width, int((hi - lo)[live].max()) + 1)
    return start, width


def tabulated_lobe(dist):
    """A factory of the Dr.Jit lobe of a tabulated distribution (its tables uploaded once).

    Parameters
    ----------
    dist : TabulatedIsotropic or TabulatedAnisotropic
        A fit's distribution (:mod:`microfacet.distributions.tabulated`).

    Returns
    -------
    callable
        ``() -> TabulatedIsotropicLobe | TabulatedAnisotropicLobe``.

    Raises
    ------
    TypeError
        For another distribution.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import numpy as np
    >>> import microfacet as mf
    >>> from microfacet.mitsuba.tabulated import tabulated_lobe
    >>> fit = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), 16)
    >>> make = tabulated_lobe(fit.distribution)
    >>> k = np.array([0.6, 0.0, 0.8])
    >>> bool(np.isclose(make().g1(mi.Vector3f(*k)), fit.distribution.g1(k), rtol=1e-4))
    True
    >>> tabulated_lobe(mf.GGX(alpha=0.3))
    Traceback (most recent call last):
    ...
    TypeError: not a tabulated distribution: GGX
    """
    if not isinstance(dist, (TabulatedIsotropic, TabulatedAnisotropic)):
        raise TypeError(f"not a tabulated distribution: {type(dist).__name__}")
    tables = _Tables(dist)
    return lambda: tables.lobe(tables)


class InterpolatedColor:
    """Piecewise-linear ``x -> colour`` table clamped at its ends, as ``np.interp`` per RGB
    channel (:class:`microfacet.fresnel.Tabulated`), evaluated as the variant's spectrum.

    RGB as is; spectral variants interpolate the spectra of the nodes' colours, each
    upsampled by Mitsuba's sRGB model (``srgb_model_fetch`` at load, ``srgb_model_eval`` at
    the wavelengths; colours above 1 scaled as Mitsuba's unbounded ``srgb`` texture does);
    monochrome variants interpolate the nodes' luminance.

    Parameters
    ----------
    x : array_like
        Sorted nodes (e.g. ``cos theta_d``).
    rgb : array_like
        ``(len(x), 3)`` colours.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.tabulated import InterpolatedColor
    >>> table = InterpolatedColor([0.0, 1.0], [[1, 0, 0], [0, 0, 1]])
    >>> table(0.25), table(2.0)
    ([0.75, 0, 0.25], [0, 0, 1])
    """

    def __init__(self, x, rgb):
        x = np.asarray(x, dtype=np.float64).ravel()
        rgb = np.asarray(rgb, dtype=np.float64).reshape(len(x), 3)
        self.search = SortedSearch(x)
        if mi.is_spectral:
            scale = np.where(rgb.max(axis=1) > 1.0, 2.0 * rgb.max(axis=1), 1.0)
            coeff = np.array([np.array(mi.srgb_model_fetch(mi.ScalarColor3f(*(c / k)))).ravel()
                              for c, k in zip(rgb, scale)])
            self.channels = [Table(coeff[:, c]) for c in range(3)] + [Table(scale)]
        elif mi.is_monochromatic:
            self.channels = [Table([luminance(c) for c in rgb])]
        else:
            self.channels = [Table(rgb[:, c]) for c in range(3)]

    def __call__(self, value, wavelengths=None):
        """The colour at ``value``.

        Parameters
        ----------
        value : Float
            Where the table is read (clamped to its ends).
        wavelengths : Spectrum, optional
            The spectral variants' ``si.wavelengths``.

        Returns
        -------
        UnpolarizedSpectrum
        """
        x = self.search.x
        i = self.search(value)
        x0, x1 = x[i], x[i + 1]
        t = dr.clip(ratio(value - x0, x1 - x0, x1 > x0), 0.0, 1.0)
        if mi.is_spectral:
            def node(j):
                c = mi.Vector3f(*(ch[j] for ch in self.channels[:3]))
                return mi.srgb_model_eval(c, wavelengths) * self.channels[3][j]
            return (1.0 - t) * node(i) + t * node(i + 1)
        out = []
        for ch in self.channels:
            a = ch[i]
            out.append(a + t * (ch[i + 1] - a))
        return mi.UnpolarizedSpectrum(*out)


def luminance(rgb) -> float:
    """Mitsuba's luminance of a linear sRGB colour, as a Python float in any variant.

    Parameters
    ----------
    rgb : sequence of float
        A linear sRGB colour.

    Returns
    -------
    float

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.tabulated import luminance
    >>> luminance([1, 1, 1]), round(luminance([0, 1, 0]), 4)
    (1.0, 0.7152)
    """
    return float(np.asarray(mi.luminance(mi.ScalarColor3f(*(float(c) for c in rgb)))).ravel()[0])
