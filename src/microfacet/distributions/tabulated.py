"""Tabulated slope distributions (thesis Ch. 4.2, 4.4; Dupuy et al. 2015, Sec. 5, App. A).

The standard surface (alpha = 1, rho = 0, zero mean; roughness, correlation and shear
come from :class:`SlopeDistribution`) is given by its NDF ``D`` at the nodes of the
elevation grid ``theta_j = (j / (n - 1))^2 pi / 2`` of Listing 4.1 (dense near the
normal, where sharp lobes live), and, for anisotropic tables, at the azimuths
``phi_k = 2 pi k / m`` of the normal. ``D`` is interpolated log-linearly in ``theta``
(exact for Gaussian-like tails to second order, where linear interpolation of a sharp
Beckmann lobe errs by tens of percent between nodes) and, for anisotropic tables, ``ln D``
periodically linearly in ``phi`` too (log-bilinear), on a grid refined by cubic
interpolation of the nodes (:class:`TabulatedAnisotropic`); the slope PDF is
``P(h~) = D(h) cos^4 theta_h`` (Eq. 2.11), normalized so that
``int P dh~ = int D cos theta_h dw_h = 1`` (Eq. 2.12, 2.8) for the interpolant (closed
form for radial tables; closed form in ``phi`` and Gauss-Legendre in ``theta`` per cell,
exact to rounding, for anisotropic ones). Every other table (Smith ``Lambda``, the marginal and
conditional CDFs used for sampling) is derived from that interpolant.

- :class:`TabulatedIsotropic`: radial ``P`` (Eq. 4.12). ``Lambda`` is a 1D function of
  ``cot theta`` (Sec. 2.4) obtained from the cumulative moments of the marginal ``P1``,
  ``Lambda(a) = int_a^inf (s - a) P1(s) ds / a`` (Eq. 2.14); visible slopes are sampled
  as in Sec. 2.2 / 4.4: the visible x-slope by inverting its CDF
  ``(int_{-inf}^x (a - s) P1(s) ds) / (a (1 + Lambda(a)))``, which the same two 1D
  tables give for every view ``a = cot theta``, then ``y~`` from the tabulated
  conditional CDF of ``P(x~, .)``.
- :class:`TabulatedAnisotropic`: ``P`` over ``(theta, phi)``; ``Lambda`` from a 2D
  table of the projected area ``A(k) = int <k,h>+ D(h) dw_h`` over ``(theta_k, phi_k)``
  (Eq. 2.14, ``Lambda = A / cos theta_k - 1``); slopes are sampled exactly from the
  interpolated ``D cos theta`` (cell, then ``theta``, then ``phi``; App. A).
"""
from __future__ import annotations

import numpy as np

from ..geometry import sin_from_cos
from .base import SlopeDistribution

__all__ = ["TabulatedIsotropic", "TabulatedAnisotropic", "theta_grid", "azimuthal_cosine_spectrum",
           "circular_projection", "refine_radial"]

HALF_PI = 0.5 * np.pi
_U_MIN = 2.0**-53
_GL_T, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_T, _GL_W = 0.5 * (_GL_T + 1.0), 0.5 * _GL_W          # on [0, 1]
GL4_T, GL4_W = np.polynomial.legendre.leggauss(4)
GL4_T, GL4_W = 0.5 * (GL4_T + 1.0), 0.5 * GL4_W
_Y_SPLIT = 2
#: Largest elevation of the fine sampling grids: slopes up to 1e7 (the mass beyond is
#: below 1e-13 for any table, as ``P <= D_max / r^4``).
THETA_CAP = np.arctan(1e7)


def theta_grid(n: int) -> np.ndarray:
    """Elevation nodes ``theta_j = (j / (n - 1))^2 pi / 2`` (Listing 4.1).

    Parameters
    ----------
    n : int
        Number of nodes.

    Returns
    -------
    (n,) ndarray
        Elevations from 0 to ``pi / 2``, radians.

    Examples
    --------
    >>> import numpy as np
    >>> np.degrees(theta_grid(5))
    array([ 0.   ,  5.625, 22.5  , 50.625, 90.   ])
    """
    u = np.linspace(0.0, 1.0, n)
    return u * u * HALF_PI


def locate(theta, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Interval ``i`` and weight ``t`` of ``theta`` in :func:`theta_grid` ``(n)``:
    ``theta = (1 - t) theta_i + t theta_{i+1}``."""
    theta = np.clip(np.asarray(theta, dtype=np.float64), 0.0, HALF_PI)
    u = np.sqrt(theta * (1.0 / HALF_PI)) * (n - 1)
    i = np.minimum(u.astype(np.intp), n - 2)
    # theta = (u / (n - 1))^2 pi/2: t = (u^2 - i^2) / (2 i + 1), exact on the grid
    t = (u - i) * (u + i) / (2 * i + 1)
    return i, np.clip(t, 0.0, 1.0)


def hat_weights(theta: np.ndarray, weight) -> np.ndarray:
    """``int hat_j(theta) weight(theta) dtheta`` for the piecewise-linear hats of the
    nodes ``theta`` (8-point Gauss-Legendre per interval: exact to rounding for the
    smooth weights used here)."""
    a, b = theta[:-1, None], theta[1:, None]
    t = a + (b - a) * _GL_T
    w = (b - a) * _GL_W * weight(t)
    out = np.zeros(len(theta))
    out[:-1] += np.sum(w * (1.0 - _GL_T), axis=1)
    out[1:] += np.sum(w * _GL_T, axis=1)
    return out


def azimuthal_cosine_spectrum(theta_k, theta_h, m: int) -> np.ndarray:
    """Real DFT over the azimuth difference of ``c[i, j, d] = <k_i, h_j>+`` with
    ``k_i = (theta_k[i], phi)`` and ``h_j = (theta_h[j], phi - 2 pi d / m)``:
    ``<k, h>+ = max(0, cos cos + sin sin cos(2 pi d / m))`` depends on ``phi_k - phi_h``
    only, so a node rule over a uniform azimuth grid is a circular convolution in
    ``phi`` (Eq. 2.14, Eq. 4.8) diagonalized by the DFT. Returns ``(len(theta_k),
    len(theta_h), m // 2 + 1)`` (real, as ``c`` is even in ``d``).

    Parameters
    ----------
    theta_k, theta_h : (n_k,), (n_h,) array_like
        Elevations of the directions and of the normals, radians.
    m : int
        Azimuth nodes.

    Returns
    -------
    (n_k, n_h, m // 2 + 1) ndarray
        The real spectrum.

    Examples
    --------
    >>> import numpy as np
    >>> c = azimuthal_cosine_spectrum(theta_grid(4), theta_grid(5), 8)
    >>> c.shape                                                   # (n_k, n_h, m // 2 + 1)
    (4, 5, 5)
    """
    tk, th = np.asarray(theta_k, float)[:, None, None], np.asarray(theta_h, float)[None, :, None]
    c = np.cos(tk) * np.cos(th) + np.sin(tk) * np.sin(th) * np.cos(np.arange(m) * (2.0 * np.pi / m))
    return np.fft.rfft(np.maximum(c, 0.0), axis=-1).real


def circular_projection(spectrum: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A[i, a] = sum_j sum_b <k_ia, h_jb>+ x[j, b]`` for node weights ``x`` ``(n_h, m)``
    (:func:`azimuthal_cosine_spectrum`): ``irfft(sum_j C[i, j] rfft(x_j))``, exact to
    rounding, ``O(n_k n_h m)`` instead of ``O(n_k n_h m^2)``.

    Parameters
    ----------
    spectrum : (n_k, n_h, m // 2 + 1) ndarray
        From :func:`azimuthal_cosine_spectrum`.
    x : (n_h, m) ndarray
        Node weights.

    Returns
    -------
    (n_k, m) ndarray
        ``A[i, a]``.

    Examples
    --------
    >>> import numpy as np
    >>> theta, m = theta_grid(6), 8
    >>> x = np.random.default_rng(0).random((6, m))
    >>> A = circular_projection(azimuthal_cosine_spectrum(theta, theta, m), x)
    >>> k = lambda t, p: np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    >>> direct = sum(max(0.0, k(theta[2], 0.0) @ k(theta[j], 2 * np.pi * b / m)) * x[j, b]
    ...              for j in range(6) for b in range(m))
    >>> bool(np.isclose(A[2, 0], direct))                          # the O(m^2) sum, by FFT
    True
    """
    m = x.shape[-1]
    xf = np.fft.rfft(x, axis=-1)
    return np.fft.irfft(np.einsum("ijf,jf->if", spectrum, xf), n=m, axis=-1)


def _cos_sin(t):
    return 0.5 * np.sin(2.0 * t)


def log_table(d: np.ndarray) -> np.ndarray:
    """``ln D`` with zeros floored at ``1e-280 max D``, so that they interpolate to 0."""
    return np.log(np.maximum(d, 1e-280 * np.max(d)))


def interval_integral(la, lb, ta, tb, theta):
    """``int_{ta}^{theta} D(s) cos s sin s ds`` for ``D = exp(la + (s - ta) beta)``,
    ``beta = (lb - la) / (tb - ta)`` (log-linear interpolation of the nodes), in closed
    form: ``e^la [ (2 beta cos(theta + ta) + 4 sin(theta + ta)) sin(theta - ta)
    + (e^(beta (theta - ta)) - 1)(beta sin 2 theta - 2 cos 2 theta) ] / (2 (beta^2 + 4))``,
    written without cancellation for small intervals."""
    beta = (lb - la) / (tb - ta)
    dt = theta - ta
    bd = beta * dt
    da = np.exp(la)
    grow = np.where(bd < 50.0, da * np.expm1(np.minimum(bd, 50.0)), np.exp(la + bd) - da)
    st = theta + ta
    out = (da * (2.0 * beta * np.cos(st) + 4.0 * np.sin(st)) * np.sin(dt)
           + grow * (beta * np.sin(2.0 * theta) - 2.0 * np.cos(2.0 * theta)))
    return np.maximum(out / (2.0 * (beta * beta + 4.0)), 0.0)


def invert_cdf(v, ta, tb, cdf, pdf, iterations: int = 60):
    """``theta`` in ``[ta, tb]`` with ``cdf(theta) = v cdf(tb)`` for an increasing ``cdf``
    with derivative ``pdf``: safeguarded Newton (bisection when a step leaves the
    bracket)."""
    total = cdf(tb)
    target = v * total
    lo, hi = ta.copy(), tb.copy()
    x = ta + v * (tb - ta)
    for _ in range(iterations):
        f = cdf(x) - target
        done = np.abs(f) <= 1e-13 * total
        if np.all(done):
            break
        lo = np.where(f < 0, x, lo)
        hi = np.where(f > 0, x, hi)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            xn = x - f / pdf(x)
        bad = ~((xn > lo) & (xn < hi))
        xn = np.where(bad, 0.5 * (lo + hi), xn)
        x = np.where(done, x, xn)
    return x


def sample_interval(v, ta, tb, las, lbs, iterations: int = 60):
    """``theta`` in ``[ta, tb]`` with density ``∝ sum_c D_c(theta) cos theta sin theta``,
    each ``D_c`` log-linear from ``exp(las[c])`` to ``exp(lbs[c])``, from the uniform ``v``
    (:func:`invert_cdf` on the closed-form CDF, :func:`interval_integral`)."""
    cdf = lambda x: sum(interval_integral(la, lb, ta, tb, x) for la, lb in zip(las, lbs))   # noqa: E731
    pdf = lambda x: sum(np.exp(la + (x - ta) / (tb - ta) * (lb - la)) for la, lb in zip(las, lbs)) * _cos_sin(x)  # noqa: E731
    return invert_cdf(v, ta, tb, cdf, pdf, iterations)


def exp_mean(b):
    """``int_0^1 e^(w b) dw = expm1(b) / b`` (1 at ``b = 0``)."""
    b = np.asarray(b, dtype=np.float64)
    small = np.abs(b) < 1e-8
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.where(small, 1.0 + 0.5 * b, np.expm1(b) / np.where(small, 1.0, b))


#: azimuthal and elevation refinements of the log table of :class:`TabulatedAnisotropic`
PHI_REFINE = 4
THETA_REFINE = 2


def catmull_rom(padded: np.ndarray, r: int, floor: float = -np.inf) -> np.ndarray:
    """Cubic (Catmull-Rom) interpolation along the last axis of ``padded`` ``(..., m + 3)``
    (the values at nodes ``-1 .. m + 1``) at ``k / r`` for ``k <= (m - 1) r`` (interval
    ``[j, j + 1]`` from the stencil ``j - 1 .. j + 2``), keeping the node values;
    intervals whose stencil touches a value ``<= floor`` (a zero of the table) are
    interpolated linearly instead, so that the cubic cannot overshoot a jump to the floor."""
    t = np.arange(r) / r
    p0, p1, p2, p3 = (padded[..., s:padded.shape[-1] - 3 + s, None] for s in range(4))
    cubic = 0.5 * (2.0 * p1 + (p2 - p0) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t * t
                   + (3.0 * (p1 - p2) + p3 - p0) * t ** 3)
    linear = p1 + (p2 - p1) * t
    floored = np.minimum(np.minimum(p0, p1), np.minimum(p2, p3)) <= floor
    out = np.where(floored, linear, cubic).reshape(padded.shape[:-1] + (-1,))
    return np.concatenate([out, padded[..., -2:-1]], axis=-1)


def refine_periodic(values: np.ndarray, r: int, floor: float = -np.inf) -> np.ndarray:
    """:func:`catmull_rom` along the last axis of ``values`` ``(..., m)``, period ``m``:
    ``m r`` values at ``k / r``."""
    m = values.shape[-1]
    return catmull_rom(values[..., np.arange(-1, m + 2) % m], r, floor)[..., :m * r]


def refine_elevation(log_d: np.ndarray, r: int, floor: float = -np.inf) -> np.ndarray:
    """:func:`catmull_rom` of an anisotropic log table ``(n, m)`` along the elevation
    grid's ``u = sqrt(2 theta / pi)`` (uniform; refined ``r`` times, its nodes are those of
    :func:`theta_grid` ``(r (n - 1) + 1)``): through the pole the row beyond node 0 is
    node 1 at the opposite azimuth (``m`` even; else node 1 itself), beyond grazing the
    linear extrapolation. Returns ``(r (n - 1) + 1, m)``."""
    n, m = log_d.shape
    opposite = log_d[1, (np.arange(m) + m // 2) % m] if m % 2 == 0 else log_d[1]
    padded = np.concatenate([opposite[None], log_d, (2.0 * log_d[-1] - log_d[-2])[None]], axis=0)
    return np.moveaxis(catmull_rom(np.moveaxis(padded, 0, -1), r, floor), -1, 0)


def refine_radial(ndf, r: int) -> np.ndarray:
    """A radial table ``D`` at :func:`theta_grid` ``(n)`` resampled at :func:`theta_grid`
    ``(r (n - 1) + 1)`` (which keeps its nodes): ``ln D`` by :func:`refine_elevation`
    (Catmull-Rom in ``u = sqrt(2 theta / pi)``; beyond the normal, node 1 by symmetry),
    linear next to zeros of the table, which stay zeros. Between the nodes of a lobe a few
    nodes wide this is third-order accurate where the log-linear interpolation of
    :class:`TabulatedIsotropic` is second-order (``ln D = -tan^2 theta / alpha^2`` of a
    Beckmann lobe is quartic in ``u``).

    Parameters
    ----------
    ndf : (n,) array_like
        ``D`` at :func:`theta_grid` ``(n)``.
    r : int
        Refinement factor.

    Returns
    -------
    (r (n - 1) + 1,) ndarray
        The resampled table.

    Examples
    --------
    >>> import numpy as np
    >>> table = np.exp(-np.tan(theta_grid(9)) ** 2 / 0.3**2)
    >>> fine = refine_radial(table, 4)
    >>> fine.shape, bool(np.allclose(fine[::4], table))           # keeps the nodes
    ((33,), True)
    """
    d = _check_ndf(ndf, 1)
    if int(r) < 1:
        raise ValueError(f"r must be an integer >= 1, got {r!r}")
    if not np.max(d) > 0:
        raise ValueError("ndf table is zero")
    log_d = log_table(d)
    floor = np.min(log_d) if np.min(d) == 0 else -np.inf
    fine = refine_elevation(log_d[:, None], int(r), floor)[:, 0]
    return np.where(fine > floor, np.exp(fine), 0.0)


def _normal(theta, phi):
    s = np.sin(theta)
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), np.cos(theta)), axis=-1)


def _check_ndf(values, ndim: int) -> np.ndarray:
    d = np.array(values, dtype=np.float64)
    if d.ndim != ndim or d.shape[0] < 3 or (ndim == 2 and d.shape[1] < 3):
        raise ValueError(f"ndf table must be {ndim}D with >= 3 nodes per axis, got shape {d.shape}")
    if not np.all(np.isfinite(d)) or np.any(d < 0):
        raise ValueError("ndf table must be finite and >= 0")
    return d


def row_masses(xi, y2, w, log_d) -> np.ndarray:
    """``M[k, l] = sum_q w_q P(xi_k, y_q) sec^2 eta_q`` over the 4 quadrature points ``q``
    of each ``eta`` interval ``l`` (``y2 = tan^2 eta``, ``w`` the weights times
    ``sec^2 eta``), with ``P = D(theta) cos^4 theta``, ``tan^2 theta = xi^2 + y^2`` (Eq.
    2.11) and ``D`` log-linear in ``theta`` on the nodes of :func:`theta_grid`
    (``log_d``): the ``y`` masses of the radial ``P`` behind ``P1`` and the conditional
    CDFs."""
    i, t, denominator = _row_geometry(xi, y2, len(log_d))
    vals = np.exp(log_d[i] + t * (log_d[i + 1] - log_d[i])) * w / denominator
    return vals.reshape(len(xi), -1, 4).sum(axis=-1)


#: The last :func:`_row_geometry` as one ``(key, value)`` (read at once: safe for threads);
#: every table of one size shares it.
_ROW_GEOMETRY: list = [None]


def _row_geometry(xi, y2, n: int):
    """``(i, t, (1 + r^2)^2)`` of :func:`row_masses` at ``r^2 = xi^2 + y^2``: the interval and
    weight of ``theta = arctan r`` in :func:`theta_grid` ``(n)`` (:func:`locate`), which
    depend on the grid, not on the table; the last one is kept (a fit with a base builds
    ~17 tables of one size)."""
    xi, y2 = np.asarray(xi, dtype=np.float64), np.asarray(y2, dtype=np.float64)
    key = (int(n), xi.tobytes(), y2.tobytes())
    entry = _ROW_GEOMETRY[0]
    if entry is None or entry[0] != key:
        r2 = xi[:, None] ** 2 + y2
        i, t = locate(np.arctan(np.sqrt(r2)), n)
        entry = (key, (i, t, (1.0 + r2) ** 2))
        for array in entry[1]:
            array.flags.writeable = False
        _ROW_GEOMETRY[0] = entry
    return entry[1]


class _Tabulated(SlopeDistribution):
    """Shared parts: the elevation grid, interval masses and the moment quadrature."""

    def _theta_setup(self, n: int) -> None:
        self.theta = theta_grid(n)
        self.n_theta = n

    def _interval_masses(self, log_d: np.ndarray) -> np.ndarray:
        """``int D cos sin dtheta`` over each elevation interval (per azimuth column)."""
        ta, tb = self.theta[:-1], self.theta[1:]
        if log_d.ndim == 2:
            ta, tb = ta[:, None], tb[:, None]
        return interval_integral(log_d[:-1], log_d[1:], ta, tb, tb)

    def _d_interp(self, theta, phi=None) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    # ------------------------------------------------------------- moments
    def _theta_quadrature(self):
        """Gauss-Legendre nodes and ``dtheta cos sin`` weights, 8 per elevation interval."""
        a, b = self.theta[:-1, None], self.theta[1:, None]
        th = (a + (b - a) * _GL_T).ravel()
        return th, ((b - a) * _GL_W).ravel() * _cos_sin(th)

    def standard_quadrature(self, n_phi: int = 256):
        """Nodes ``(x~, y~)`` of the standard slope plane and weights (summing to 1) for
        ``E[g(h~)] = int g P dh~ = int g(h~(h)) D cos theta dw`` (Gauss-Legendre per
        elevation interval; per azimuth interval for anisotropic tables, periodic
        trapezoid for radial ones).

        Parameters
        ----------
        n_phi : int
            Azimuth nodes for a radial table.

        Returns
        -------
        x, y : (M,) ndarray
            Standard slopes of the nodes.
        w : (M,) ndarray
            Weights, summing to 1.
        """
        th, wt = self._theta_quadrature()
        phi, wp = self._phi_quadrature(n_phi)
        TH, PH = np.meshgrid(th, phi, indexing="ij")
        w = wt[:, None] * wp[None, :] * self._d_interp(TH, PH)
        r = np.tan(TH)
        # slope of the normal (sin t cos p, sin t sin p, cos t) is -tan t (cos p, sin p)
        x, y = -r * np.cos(PH), -r * np.sin(PH)
        w = w / w.sum()
        return x.ravel(), y.ravel(), w.ravel()


class TabulatedIsotropic(_Tabulated):
    """Radial tabulated slope distribution (Eq. 4.12), sampled by visible slopes.

    Parameters
    ----------
    ndf : (n,) array_like
        ``D`` of the standard surface at :func:`theta_grid` ``(n)``, ``>= 0``; it is
        normalized here (Eq. 2.8), so any positive scale may be given.
    alpha, alpha_x, alpha_y, rho, mean_slope
        Roughness map applied to the table (:class:`SlopeDistribution`); 1, 0, 0 keep it.
    oversampling : int
        Refinement of the sampling tables: ``oversampling (n - 1) + 1`` nodes (at least ``n``).

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.distributions import Beckmann
    >>> theta = theta_grid(64)
    >>> h = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    >>> table = TabulatedIsotropic(Beckmann(alpha=0.3).ndf(h))       # a Beckmann lobe, tabulated
    >>> probe = np.array([np.sin(0.4), 0.0, np.cos(0.4)])
    >>> round(float(table.ndf(probe) / Beckmann(alpha=0.3).ndf(probe)), 3)
    0.999
    """

    def __init__(self, ndf, alpha=None, *, alpha_x=None, alpha_y=None, rho=0.0,
                 mean_slope=(0.0, 0.0), oversampling: int = 4):
        if alpha is None and alpha_x is None and alpha_y is None:
            alpha = 1.0
        super().__init__(alpha, alpha_x=alpha_x, alpha_y=alpha_y, rho=rho, mean_slope=mean_slope)
        d = _check_ndf(ndf, 1)
        if not np.max(d) > 0:
            raise ValueError("ndf table is zero")
        self._theta_setup(len(d))
        mass = self._interval_masses(log_table(d))
        self.ndf_table = d / (2.0 * np.pi * mass.sum())
        self.log_ndf = log_table(self.ndf_table)
        self._mass_cdf = np.concatenate([[0.0], np.cumsum(mass / mass.sum())])
        self._build_sampling_tables(max(int(oversampling), 1) * (len(d) - 1) + 1)
        th, w = self._theta_quadrature()
        w = w * self._d_interp(th)
        self.second_moment_std = float(0.5 * np.sum(w * np.tan(th) ** 2) / np.sum(w))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n={self.n_theta}, " + super().__repr__().split("(", 1)[1]

    # -------------------------------------------------------------- the NDF
    def _d_interp(self, theta, phi=None) -> np.ndarray:
        """``D`` interpolated log-linearly in ``theta`` (exact for exponentials in theta,
        second-order accurate for lobes whose logarithm is smooth: Beckmann tails)."""
        i, t = locate(theta, self.n_theta)
        ld = self.log_ndf
        return np.exp(ld[i] + t * (ld[i + 1] - ld[i]))

    def _phi_quadrature(self, n_phi: int):
        return (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi), np.full(n_phi, 2 * np.pi / n_phi)

    def p22_std(self, x, y):
        """``P(x~, y~) = D(theta) cos^4 theta``, ``tan theta = |h~|`` (Eq. 2.11).

        Parameters
        ----------
        x, y : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope area.
        """
        r2 = np.asarray(x, float) ** 2 + np.asarray(y, float) ** 2
        return self._d_interp(np.arctan(np.sqrt(r2))) / (1.0 + r2) ** 2

    def p22_std_over_z4(self, x, y, z):
        r2 = x * x + y * y
        return self._d_interp(np.arctan2(np.sqrt(r2), z)) / (z * z + r2) ** 2

    def p1_std(self, x):
        """Marginal ``P1(x~) = int P(x~, y~) dy~`` (Abel transform, tabulated and
        interpolated linearly on the fine sampling grid).

        Parameters
        ----------
        x : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope.
        """
        xi = np.abs(np.asarray(x, dtype=np.float64))
        return np.interp(self._fine_s(xi), self.s_fine, self.p1_fine)

    # ---------------------------------------------------------- fine tables
    @staticmethod
    def _fine_s(xi):
        """Fine-grid coordinate ``s`` of the slope magnitude ``xi = tan(s^2 theta_cap)``."""
        return np.sqrt(np.minimum(np.arctan(xi), THETA_CAP) / THETA_CAP)

    def _build_sampling_tables(self, m: int) -> None:
        """Marginal ``P1``, tail mass ``L0(xi) = int_xi^inf P1`` and first tail moment
        ``L1(xi) = int_xi^inf (s - xi) P1(s) ds`` on ``xi_k = tan(s_k^2 theta_cap)``, and
        the conditional CDFs of ``|y~| = tan eta`` given ``|x~| = xi_k`` on a refined
        elevation grid, linear in ``eta`` between its nodes (Sec. 4.4, App. A)."""
        self.s_fine = np.linspace(0.0, 1.0, m)
        th = self.s_fine**2 * THETA_CAP
        self.xi = np.tan(th)
        # y = tan(eta) on the elevation grid of the table refined _Y_SPLIT times (dense
        # at y = 0 where sharp lobes live); P(xi, y) sec^2 eta stays smooth up to grazing
        eta = np.minimum(theta_grid(_Y_SPLIT * (self.n_theta - 1) + 1), THETA_CAP)
        ea, eb = eta[:-1, None], eta[1:, None]
        es = (ea + (eb - ea) * GL4_T).ravel()                                        # (q(n-1) 4,)
        mass = row_masses(self.xi, np.tan(es) ** 2, ((eb - ea) * GL4_W).ravel() / np.cos(es) ** 2,
                          self.log_ndf)
        cdf = np.concatenate([np.zeros((m, 1)), np.cumsum(mass, axis=1)], axis=1)
        eta = np.broadcast_to(eta, (m, len(eta)))
        half = cdf[:, -1].copy()
        self.p1_fine = 2.0 * half
        self.eta_nodes = eta
        with np.errstate(invalid="ignore", divide="ignore"):
            self.y_cdf = np.where(half[:, None] > 0, cdf / half[:, None], np.linspace(0, 1, cdf.shape[1]))
        # tails, integrated from xi = inf inward (trapezoid in s; dxi/ds = 2 s cap sec^2)
        dxi_ds = 2.0 * self.s_fine * THETA_CAP / np.cos(th) ** 2
        self.dxi_ds = dxi_ds
        self.L0 = self._tail_integral(self.p1_fine * dxi_ds)
        self.L1 = self._tail_integral(self.L0 * dxi_ds)

    def _tail_integral(self, f_ds):
        h = self.s_fine[1] - self.s_fine[0]
        seg = 0.5 * h * (f_ds[:-1] + f_ds[1:])
        return np.append(np.cumsum(seg[::-1])[::-1], 0.0)

    def _L1(self, xi) -> np.ndarray:
        """``L1`` at any ``xi >= 0``: cubic Hermite in ``s`` with ``dL1/ds = -L0 dxi/ds``."""
        s = self._fine_s(xi)
        m = len(self.s_fine)
        k = np.minimum((s * (m - 1)).astype(np.intp), m - 2)
        h = self.s_fine[1] - self.s_fine[0]
        t = np.clip(s / h - k, 0.0, 1.0)
        y0, y1 = self.L1[k], self.L1[k + 1]
        d0, d1 = -self.L0[k] * self.dxi_ds[k] * h, -self.L0[k + 1] * self.dxi_ds[k + 1] * h
        t2, t3 = t * t, t * t * t
        val = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * d0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * d1
        return np.maximum(val, 0.0)

    # ------------------------------------------------------------- masking
    def lambda_std(self, cot_theta):
        """``Lambda(a) = L1(a) / a``, ``a = cot theta`` (Eq. 2.14 for radial P, Sec. 2.4):
        the projected area of the standard surface toward ``theta`` is
        ``int (a - x~)+ P1(x~) dx~ / a = 1 + L1(a) / a`` (in units of ``cos theta``).

        Parameters
        ----------
        cot_theta : array_like
            ``cot theta`` of the direction; ``<= 0`` gives ``inf``.

        Returns
        -------
        ndarray
            ``Lambda >= 0``.
        """
        a = np.asarray(cot_theta, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = self._L1(np.where(a > 0, a, 0.0)) / a
        return np.where(a > 0, np.where(np.isfinite(a), lam, 0.0), np.inf)

    # ------------------------------------------------------------ sampling
    def sample_p22_std(self, u):
        """Standard normal with slopes distributed as ``P``: ``theta`` from the marginal
        ``2 pi D cos sin`` (interval by its mass, then exact inversion), ``phi = 2 pi u2``.

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
        cdf = self._mass_cdf
        v = np.clip(u[..., 0], _U_MIN, 1.0 - _U_MIN)
        i = np.clip(np.searchsorted(cdf, v, side="right") - 1, 0, self.n_theta - 2)
        mass = cdf[i + 1] - cdf[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.clip(np.where(mass > 0, (v - cdf[i]) / mass, 0.5), 0.0, 1.0)
        ld = self.log_ndf
        th = sample_interval(r, self.theta[i], self.theta[i + 1], (ld[i],), (ld[i + 1],))
        return _normal(th, 2.0 * np.pi * u[..., 1])

    def sample_visible_std(self, u, cos_theta):
        """Standard visible normal for a view at ``theta`` in the xz plane (Sec. 2.2, 4.4).

        ``x~`` inverts ``F(x~) = int_{-inf}^{x~} (a - s) P1(s) ds / (a + L1(a))``, written
        with the tail tables as ``(a + xi) L0(xi) + L1(xi)`` for ``x~ = -xi <= 0`` and
        ``Z - ((a - xi) L0(xi) - L1(xi) + L1(a))`` for ``0 < x~ = xi <= a`` (bisection on
        the fine nodes, linear in ``s`` inside a cell); ``y~`` inverts the conditional CDF
        of ``P(x~, .)`` (tabulated per fine node, rows mixed linearly in ``s``).

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
        c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
        sn = sin_from_cos(c)
        a = np.minimum(c / np.maximum(sn, 1e-300), 1e8)
        a, u1, u2 = np.broadcast_arrays(a, u[..., 0], u[..., 1])
        shape = a.shape
        a, u1, u2 = (np.clip(v.ravel(), 0, None) for v in (a, u1, u2))
        u1 = np.clip(u1, _U_MIN, 1.0 - _U_MIN)
        x = self._visible_x(a, u1)
        y = self._conditional_y(np.abs(x), np.clip(u2, 0.0, 1.0))
        inv = 1.0 / np.sqrt(1.0 + x * x + y * y)
        return np.stack([-x * inv, -y * inv, inv], axis=-1).reshape(shape + (3,))

    def _visible_x(self, a, u1):
        L1a = self._L1(a)
        z = a + L1a
        h0 = 0.5 * a + self.L1[0]                       # F(0) * Z
        target = u1 * z
        left = target <= h0
        x = np.empty_like(a)
        m = len(self.s_fine)
        # x~ = -xi <= 0: H(xi) = (a + xi) L0 + L1 decreases from h0 to 0
        al, tl = a[left], target[left]
        H = lambda k, al=al: (al + self.xi[k]) * self.L0[k] + self.L1[k]   # noqa: E731
        k = self._bisect(H, tl, np.zeros(al.shape, np.intp), np.full(al.shape, m - 1, np.intp))
        k = np.minimum(k, m - 2)
        x[left] = -self._cell_root(k, H(k), H(k + 1), tl, self.s_fine[k + 1])
        # 0 < x~ = xi <= a: R(xi) = (a - xi) L0 - L1 + L1(a) decreases from R(0) to R(a) = 0
        right = ~left
        ar, tr, l1r = a[right], (1.0 - u1[right]) * z[right], L1a[right]
        R = lambda k, ar=ar, l1r=l1r: (ar - self.xi[k]) * self.L0[k] - self.L1[k] + l1r   # noqa: E731
        s_a = self._fine_s(ar)
        kmax = np.minimum((s_a * (m - 1)).astype(np.intp), m - 1)
        kmax = np.where(self.s_fine[kmax] > s_a, kmax - 1, kmax)
        k = self._bisect(R, tr, np.zeros(ar.shape, np.intp), kmax + 1)
        at_end = k + 1 > kmax
        kn = np.minimum(k + 1, m - 1)
        r_end = np.where(at_end, 0.0, R(kn))
        s_end = np.where(at_end, s_a, self.s_fine[kn])
        x[right] = np.minimum(self._cell_root(k, R(k), r_end, tr, s_end), ar)
        return x

    @staticmethod
    def _bisect(f, target, lo, hi):
        """Largest ``k`` in ``[lo, hi)`` with ``f(k) >= target`` for decreasing ``f``
        (``f(lo) >= target`` assumed; ``hi`` is an exclusive sentinel)."""
        for _ in range(64):
            if not np.any(hi - lo > 1):
                break
            mid = (lo + hi) // 2
            fm = f(mid)
            go = (hi - lo > 1) & (fm >= target)
            stay = (hi - lo > 1) & ~(fm >= target)
            lo = np.where(go, mid, lo)
            hi = np.where(stay, mid, hi)
        return lo

    def _cell_root(self, k, f0, f1, target, s_end):
        """Slope magnitude at ``target`` inside the cell ``[s_k, s_end]``, linear in ``s``."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(f0 > f1, (f0 - target) / (f0 - f1), 0.5)
        s = self.s_fine[k] + np.clip(t, 0.0, 1.0) * (s_end - self.s_fine[k])
        return np.tan(s * s * THETA_CAP)

    def _conditional_y(self, xi, u2):
        """``y~`` from the conditional CDF of ``|y~|`` given ``|x~| = xi`` (sign from ``u2``)."""
        sign = np.where(u2 >= 0.5, 1.0, -1.0)
        v = np.clip(np.abs(2.0 * u2 - 1.0), 0.0, 1.0 - _U_MIN)
        m = len(self.s_fine)
        f = self._fine_s(xi) * (m - 1)
        k = np.minimum(f.astype(np.intp), m - 2)
        w = np.clip(f - k, 0.0, 1.0)
        y0 = self._row_quantile(k, v)
        y1 = self._row_quantile(k + 1, v)
        return sign * ((1.0 - w) * y0 + w * y1)

    def _row_quantile(self, k, v):
        cdf, ys = self.y_cdf, self.eta_nodes
        n = cdf.shape[1]
        lo = np.zeros(k.shape, np.intp)
        hi = np.full(k.shape, n - 1, np.intp)
        while np.any(hi - lo > 1):
            mid = (lo + hi) // 2
            le = cdf[k, mid] <= v
            lo = np.where(le, mid, lo)
            hi = np.where(le, hi, mid)
        c0, c1 = cdf[k, lo], cdf[k, lo + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(c1 > c0, (v - c0) / (c1 - c0), 0.0)
        return np.tan(ys[k, lo] + np.clip(t, 0.0, 1.0) * (ys[k, lo + 1] - ys[k, lo]))


class TabulatedAnisotropic(_Tabulated):
    """Tabulated slope distribution over ``(theta, phi)`` of the normal (Eq. 4.5-4.9).

    Parameters
    ----------
    ndf : (n_theta, n_phi) array_like
        ``D`` of the standard surface at ``theta_grid(n_theta)`` x ``2 pi k / n_phi``.
    n_lambda : int, optional
        Elevation resolution of the projected-area table (default ``n_theta``); its nodes
        ``theta = pi/2 sin^2(pi s / 2)`` are dense at the normal and at grazing angles.
    alpha, alpha_x, alpha_y, rho, mean_slope
        Roughness map applied to the table (:class:`SlopeDistribution`); 1, 0, 0 keep it.
    projected_area : (n_lambda, n_phi) array_like, optional
        A precomputed projected-area table on these nodes (e.g. a saved one); None computes it.

    Notes
    -----
    ``ln D`` is first refined :data:`PHI_REFINE` times in azimuth by periodic cubic
    (Catmull-Rom) interpolation of the node values (linear next to zeros of the table),
    then interpolated log-bilinearly on the refined grid: cubic accuracy in ``phi`` with
    the exact masses and sampling of the log-bilinear interpolant.
    ``ndf_table``, ``n_phi`` and the projected-area table stay on the given nodes.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.distributions import GGX
    >>> theta, phi = theta_grid(32), 2 * np.pi * np.arange(16) / 16
    >>> T, P = np.meshgrid(theta, phi, indexing="ij")
    >>> h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    >>> lobe = GGX(alpha_x=0.4, alpha_y=0.2)
    >>> table = TabulatedAnisotropic(lobe.ndf(h))                   # (theta, phi) table
    >>> probe = np.array([np.sin(0.3), 0.0, np.cos(0.3)])
    >>> round(float(table.ndf(probe) / lobe.ndf(probe)), 2)
    1.0
    """

    supports_visible_sampling = False

    def __init__(self, ndf, alpha=None, *, alpha_x=None, alpha_y=None, rho=0.0,
                 mean_slope=(0.0, 0.0), n_lambda: int | None = None, projected_area=None):
        if alpha is None and alpha_x is None and alpha_y is None:
            alpha = 1.0
        super().__init__(alpha, alpha_x=alpha_x, alpha_y=alpha_y, rho=rho, mean_slope=mean_slope)
        d = _check_ndf(ndf, 2)
        self._theta_setup(d.shape[0])
        self.n_phi = d.shape[1]
        self.dphi = 2.0 * np.pi / self.n_phi
        self.phi = np.arange(self.n_phi) * self.dphi
        if not np.max(d) > 0:
            raise ValueError("ndf table is zero")
        self.n_fine = PHI_REFINE * self.n_phi
        self.dphi_fine = 2.0 * np.pi / self.n_fine
        self.n_theta_fine = THETA_REFINE * (self.n_theta - 1) + 1
        self.theta_fine = theta_grid(self.n_theta_fine)
        log_d = log_table(d)
        floor = np.min(log_d) if np.min(d) == 0 else -np.inf
        self.log_ndf = refine_elevation(refine_periodic(log_d, PHI_REFINE, floor), THETA_REFINE, floor)
        cell = self._cell_masses()                             # (n_theta_fine - 1, n_fine)
        total = cell.sum()
        self.ndf_table = d / total
        self.log_ndf = self.log_ndf - np.log(total)
        n_lambda = self.n_theta if n_lambda is None else int(n_lambda)
        s = np.linspace(0.0, 1.0, n_lambda)
        self.theta_k = HALF_PI * np.sin(HALF_PI * s) ** 2
        self.area_table = (self._projected_area_grid(self.theta_k) if projected_area is None
                           else np.asarray(projected_area, float))
        self._cell_cdf = np.concatenate([[0.0], np.cumsum(cell.ravel() / total)])
        x, y, w = self.standard_quadrature()
        self.second_moment_std = float(np.sum(w * x * x))

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n_theta={self.n_theta}, n_phi={self.n_phi}, "
                + super().__repr__().split("(", 1)[1])

    def _phi_quadrature(self, n_phi: int):
        t, w = np.polynomial.legendre.leggauss(4)
        phi = ((np.arange(self.n_phi)[:, None] + 0.5 * (t + 1)) * self.dphi).ravel()
        return phi, np.tile(0.5 * w * self.dphi, self.n_phi)

    # -------------------------------------------------------------- the NDF
    def _d_interp(self, theta, phi=None) -> np.ndarray:
        """``D`` log-bilinear: ``ln D`` linear in ``theta`` along each node azimuth and
        linear in ``phi`` between them (second-order accurate for lobes whose logarithm
        is smooth in both: anisotropic Beckmann tails, where linear interpolation in
        ``phi`` errs by tens of percent between nodes)."""
        i, t = locate(theta, self.n_theta_fine)
        f = np.mod(np.asarray(phi, dtype=np.float64), 2.0 * np.pi) / self.dphi_fine
        j = np.minimum(f.astype(np.intp), self.n_fine - 1)
        w = np.clip(f - j, 0.0, 1.0)
        a = self._log_column(i, j, t)
        return np.exp(a + w * (self._log_column(i, (j + 1) % self.n_fine, t) - a))

    def _log_column(self, i, j, t):
        ld = self.log_ndf
        return ld[i, j] + t * (ld[i + 1, j] - ld[i, j])

    def _cell_marginal(self, theta, i, j):
        """``int D(theta, phi) dphi cos theta sin theta`` over the azimuth interval ``j``
        (closed form in ``phi``: ``D_j^(1-w) D_(j+1)^w`` integrates to ``D_j
        expm1(b) / b``, ``b = ln D_(j+1) - ln D_j``), at ``theta`` in elevation interval ``i``."""
        t = (theta - self.theta_fine[i]) / (self.theta_fine[i + 1] - self.theta_fine[i])
        a = self._log_column(i, j, t)
        b = self._log_column(i, (j + 1) % self.n_fine, t) - a
        return self.dphi_fine * np.exp(a) * exp_mean(b) * _cos_sin(theta)

    def _cell_masses(self) -> np.ndarray:
        """Mass ``int int D cos sin dtheta dphi`` of each cell (elevation x azimuth
        interval) of the log-bilinear interpolant: closed form in ``phi``, 8-point
        Gauss-Legendre in ``theta`` (smooth: exact to rounding on these intervals)."""
        n, m = self.n_theta_fine - 1, self.n_fine
        i = np.arange(n)[:, None, None]
        ta, tb = self.theta_fine[:-1, None, None], self.theta_fine[1:, None, None]
        th = ta + (tb - ta) * _GL_T[None, :, None]
        vals = self._cell_marginal(th, i, np.arange(m)[None, None, :])       # (n, 8, m)
        return np.sum(vals * ((tb - ta) * _GL_W[None, :, None]), axis=1)

    def p22_std(self, x, y):
        """``P(x~, y~) = D(h) cos^4 theta_h`` with ``h ∝ (-x~, -y~, 1)`` (Eq. 2.11).

        Parameters
        ----------
        x, y : array_like
            Standard slopes.

        Returns
        -------
        ndarray
            Density per unit slope area.
        """
        x, y = np.asarray(x, float), np.asarray(y, float)
        r2 = x * x + y * y
        return self._d_interp(np.arctan(np.sqrt(r2)), np.arctan2(-y, -x)) / (1.0 + r2) ** 2

    def p22_std_over_z4(self, x, y, z):
        r2 = x * x + y * y
        return self._d_interp(np.arctan2(np.sqrt(r2), z), np.arctan2(-y, -x)) / (z * z + r2) ** 2

    def p1_std(self, x):
        raise NotImplementedError("the marginal of an anisotropic table is not tabulated")

    # ------------------------------------------------------------- masking
    def projected_area_nodes(self, k, chunk: int = 2048) -> np.ndarray:
        """``A(k) = int <k,h>+ D(h) dw_h`` (Eq. 2.14) by the node rule of the table:
        ``sum_n w_n <k, h_n>+ D_n`` with ``w_n ∝ int int hat_n sin theta dtheta dphi``,
        scaled so that ``A(z) = 1`` (Eq. 2.8).

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions.
        chunk : int
            Directions per batch (bounds the memory).

        Returns
        -------
        (...) ndarray
            ``A(k)``.
        """
        k = np.asarray(k, dtype=np.float64)
        h = _normal(self.theta[:, None], self.phi[None, :]).reshape(-1, 3)
        # rescaled so that A(z) = int cos D dw = 1 holds as for the exactly normalized
        # interpolant: removes the rule's leading (lobe-wide) error
        wd = self._node_area_weights().ravel()
        flat = k.reshape(-1, 3)
        out = np.empty(len(flat))
        for s in range(0, len(flat), chunk):
            dots = flat[s:s + chunk] @ h.T
            np.maximum(dots, 0.0, out=dots)
            out[s:s + chunk] = dots @ wd
        return out.reshape(k.shape[:-1])

    def _node_area_weights(self) -> np.ndarray:
        """``w_n D_n`` of the node rule of :meth:`projected_area_nodes`, ``(n_theta, n_phi)``,
        scaled so that ``A(z) = sum w_n D_n cos theta_n = 1``."""
        wd = hat_weights(self.theta, np.sin)[:, None] * self.dphi * self.ndf_table
        return wd / np.sum(wd * np.cos(self.theta)[:, None])

    def _projected_area_grid(self, theta_k) -> np.ndarray:
        """:meth:`projected_area_nodes` at ``theta_k x self.phi`` by the DFT in azimuth
        (:func:`circular_projection`; the same rule, exact to rounding)."""
        return circular_projection(azimuthal_cosine_spectrum(theta_k, self.theta, self.n_phi),
                                   self._node_area_weights())

    def lambda_warped(self, a, b, c):
        """``Lambda = A(k') / cos theta_k' - 1`` from the bilinear projected-area table.

        Parameters
        ----------
        a, b, c : array_like
            Components of the warped direction ``k'`` (need not be unit).

        Returns
        -------
        ndarray
            ``Lambda >= 0`` (``inf`` where ``c <= 0``).
        """
        a, b, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (a, b, c)))
        r = np.hypot(a, b)
        th = np.arctan2(r, np.maximum(c, 0.0))
        ph = np.arctan2(b, a)
        area = self._area_interp(th, ph)
        norm = np.hypot(r, c)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.maximum(area * norm / c - 1.0, 0.0)
        return np.where(c > 0, lam, np.inf)

    def _area_interp(self, theta, phi):
        n = len(self.theta_k)
        s = np.arcsin(np.sqrt(np.clip(theta, 0.0, HALF_PI) / HALF_PI)) / HALF_PI * (n - 1)
        i = np.minimum(s.astype(np.intp), n - 2)
        t = np.clip((theta - self.theta_k[i]) / (self.theta_k[i + 1] - self.theta_k[i]), 0.0, 1.0)
        f = np.mod(phi, 2.0 * np.pi) / self.dphi
        j = np.minimum(f.astype(np.intp), self.n_phi - 1)
        w = np.clip(f - j, 0.0, 1.0)
        j1 = (j + 1) % self.n_phi
        A = self.area_table
        return (1 - t) * ((1 - w) * A[i, j] + w * A[i, j1]) + t * ((1 - w) * A[i + 1, j] + w * A[i + 1, j1])

    # ------------------------------------------------------------ sampling
    def sample_p22_std(self, u):
        """Normal whose slope is distributed as the interpolated ``P`` (App. A): a cell by
        its mass, ``theta`` from the cell's marginal (:meth:`_cell_marginal`, Newton on
        its CDF by 8-point Gauss-Legendre from the cell's edge), then ``phi`` from the
        log-linear ``D(theta, .)`` in closed form (``w = log1p(v expm1(b)) / b``).

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
        cdf = self._cell_cdf
        v = np.clip(u[..., 0], _U_MIN, 1.0 - _U_MIN) * cdf[-1]
        c = np.clip(np.searchsorted(cdf, v, side="right") - 1, 0, len(cdf) - 2)
        mass = cdf[c + 1] - cdf[c]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.clip(np.where(mass > 0, (v - cdf[c]) / mass, 0.5), 0.0, 1.0)
        i, j = np.divmod(c, self.n_fine)
        ta, tb = self.theta_fine[i], self.theta_fine[i + 1]

        def partial(x):
            nodes = ta[..., None] + (x - ta)[..., None] * _GL_T
            return (x - ta) * np.sum(_GL_W * self._cell_marginal(nodes, i[..., None], j[..., None]), axis=-1)

        th = invert_cdf(r, ta, tb, partial, lambda x: self._cell_marginal(x, i, j))
        t = np.clip((th - ta) / (tb - ta), 0.0, 1.0)
        b = self._log_column(i, (j + 1) % self.n_fine, t) - self._log_column(i, j, t)
        q = np.clip(u[..., 1], 0.0, 1.0)
        small = np.abs(b) < 1e-8
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            w = np.where(small, q, np.log1p(q * np.expm1(b)) / np.where(small, 1.0, b))
        return _normal(th, (j + np.clip(np.nan_to_num(w, nan=q), 0.0, 1.0)) * self.dphi_fine)

    def sample_visible_std(self, u, cos_theta):  # pragma: no cover - not supported
        raise NotImplementedError("anisotropic tables sample slopes of P (supports_visible_sampling = False)")
