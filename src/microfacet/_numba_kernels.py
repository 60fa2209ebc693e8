"""The Numba kernels of :mod:`microfacet.kernels` (imported, and compiled or loaded from
Numba's on-disk cache, on first use; see that module).

Each public kernel is one parallel loop over directions that writes its outputs in place
(no temporaries), with the Fresnel term inside; the per-element helpers are the NumPy
reference's equations, evaluated with selects instead of early exits where that is
possible. ``error_model="numpy"``: a division by zero gives inf/NaN (then masked), as in
NumPy, instead of raising; fastmath is off (the kernels equal the reference to 1e-12)."""
from __future__ import annotations

import math

import numba
import numpy as np

BECKMANN, GGX = 0, 1
IDEAL, SCHLICK, DIELECTRIC, CONDUCTOR, TABULATED = range(5)
_SQRT_PI = math.sqrt(math.pi)
_U_MIN = 2.0**-53
#: The quantile solves ``(1 - u) - (1 - F)`` above this ``u`` (``F - u`` below; the
#: reference switches at 1/2): between, ``F - u`` has an absolute error ~1e-16 and the
#: density is >= ~1e-2, so ``x~`` moves by < 1e-13, and the 12 exps of the complementary
#: CDF near ``cot theta`` are skipped.
_UPPER = 0.99
_GL_T, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_T, _GL_W = 0.5 * (_GL_T + 1.0), 0.5 * _GL_W      # on [0, 1], as in distributions.beckmann

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
_pjit = numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)


# ------------------------------------------------------------------------ helpers
@_jit
def _lambda(kind, r2, c):
    """Smith Lambda of the warped direction ``(a, b, c)``, ``r2 = a^2 + b^2``, ``c > 0``
    (Table 2.III; see ``lambda_warped``; Beckmann at ``v = c / sqrt(r2)``, 0 for ``r2 = 0``)."""
    if kind == GGX:
        return r2 / (2.0 * c * (math.sqrt(r2 + c * c) + c))
    v = c / math.sqrt(r2)
    return max(0.5 * (math.exp(-v * v) / (v * _SQRT_PI) - math.erfc(v)), 0.0)


@_jit
def _ndf_std(kind, x, y, z):
    """``P_std(x / z, y / z) / z^4`` for ``z > 0`` (Eq. 2.11, Table 2.II, division-free form)."""
    if kind == GGX:
        r = z * z + x * x + y * y
        return 1.0 / (math.pi * r * r)
    return math.exp(-(x * x + y * y) / (z * z) - 4.0 * math.log(z)) / math.pi


@_jit
def _ndf(kind, ax, ay, rho, s1, xn, yn, hx, hy, hz):
    """``D(h)`` (Eq. 2.11, 3.2) for ``hz > 0``: the standard NDF at the unsheared slope."""
    x = (-hx - xn * hz) / ax
    y = (ax * (-hy - yn * hz) - rho * ay * (-hx - xn * hz)) / (ax * ay * s1)
    return _ndf_std(kind, x, y, hz) / (ax * ay * s1)


@_jit
def _lambda_c(kind, ax, ay, rho, s1, xn, yn, kx, ky, kz):
    """``(Lambda(k), c_k)`` of the warped direction ``k' = (a, b, c)`` (Eq. 3.3); Lambda is
    computed at ``c = 1`` where ``c_k <= 0`` (callers mask those)."""
    a = ax * kx + rho * ay * ky
    b = ay * s1 * ky
    c = kz - kx * xn - ky * yn
    return _lambda(kind, a * a + b * b, c if c > 0.0 else 1.0), c


@_jit
def _fresnel(fk, p0, p1, c):
    """One channel of an analytic Fresnel term at ``c = cos theta_d`` (Table 2.I; the formulas
    of :mod:`microfacet.fresnel`): ``p0`` is ``f0`` (Schlick) or ``eta``, ``p1`` ``k`` (conductor)."""
    if fk == IDEAL:
        return 1.0
    c = min(max(c, 0.0), 1.0)
    if fk == SCHLICK:
        m = 1.0 - c
        m2 = m * m
        return p0 + (1.0 - p0) * (m2 * m2 * m)
    c2 = c * c
    if fk == DIELECTRIC:
        g2 = p0 * p0 + c2 - 1.0
        g = math.sqrt(max(g2, 0.0))
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
        return 1.0 if (g2 < 0.0 or not abs(f) < math.inf) else f
    s2 = 1.0 - c2                                    # CONDUCTOR: conductor_reflectance
    t1 = p0 * p0 - p1 * p1 - s2
    a2b2 = math.sqrt(t1 * t1 + 4.0 * p0 * p0 * p1 * p1)
    ac2 = 2.0 * c * math.sqrt(max(0.5 * (a2b2 + t1), 0.0))
    rs = (a2b2 + c2 - ac2) / (a2b2 + c2 + ac2)
    t3, t4 = a2b2 * c2 + s2 * s2, ac2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _fresnel_rgb(fk, fp, tx, tv, c, out, j, scale):
    """``out[j] = F(c) * scale`` per RGB channel: :func:`_fresnel`, or ``np.interp`` of the
    :class:`~microfacet.fresnel.Tabulated` grid ``tx`` and values ``tv`` (clamped at the ends).
    Inlined (Numba IR), so that the arrays are not passed, and reference-counted, per element."""
    if fk == TABULATED:
        n = tx.shape[0]
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if tx[mid] <= c:
                lo = mid
            else:
                hi = mid
        for ch in range(3):
            if c <= tx[0]:
                f = tv[0, ch]
            elif c >= tx[n - 1]:
                f = tv[n - 1, ch]
            else:
                f = (tv[hi, ch] - tv[lo, ch]) / (tx[hi] - tx[lo]) * (c - tx[lo]) + tv[lo, ch]
            out[j, ch] = f * scale
    else:
        for ch in range(3):
            out[j, ch] = _fresnel(fk, fp[0, ch], fp[1, ch], c) * scale


@_jit
def _smith(kind, ax, ay, rho, s1, xn, yn, shadowing, ix, iy, iz, ox, oy, oz):
    """``(o.h, D G / (4 z_o))`` of one pair (Eq. 2.1 with F = 1; NDF Eq. 3.2, height-correlated
    Smith G with the warped directions of Eq. 3.3), 0 where invalid (see ``_projected_numpy``)."""
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    n2 = hx * hx + hy * hy + hz * hz
    inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    oh = ox * hx + oy * hy + oz * hz
    lam, co = _lambda_c(kind, ax, ay, rho, s1, xn, yn, ox, oy, oz)
    ok = (iz > 0.0) & (oz > 0.0) & (oh > 0.0) & (hz > 0.0) & (co > 0.0)
    if shadowing:
        lam_i, ci = _lambda_c(kind, ax, ay, rho, s1, xn, yn, ix, iy, iz)
        lam += lam_i
        ok &= ci > 0.0
    g = oz / (co * (1.0 + lam))
    d = _ndf(kind, ax, ay, rho, s1, xn, yn, hx, hy, hz if hz > 0.0 else 1.0)
    s = d * g / (4.0 * oz)
    return oh, (s if ok else 0.0)


@_jit
def _erfinv(y):
    """``erfinv(y)`` for ``|y| < 1``: Giles' single-precision approximation ("Approximating
    the erfinv function", GPU Computing Gems 2011) and Halley steps on ``erf(x) = y`` (two,
    more where ``1 - |y| < 2^-24``, outside the approximation's range)
    (on ``erfc(|x|) = 1 - |y|`` for ``|y| > 1/2``, exact there, so the tails keep precision)."""
    w = -math.log((1.0 - y) * (1.0 + y))
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        for q in (3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087,
                  -0.00125372503, -0.00417768164, 0.246640727, 1.50140941):
            p = q + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        for q in (0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773,
                  -0.0076224613, 0.00943887047, 1.00167406, 2.83297682):
            p = q + p * w
    x = p * y
    sign = 1.0 if y >= 0.0 else -1.0
    for _ in range(6):                                # 2 steps, more beyond float32's range
        ax = abs(x)
        if abs(y) > 0.5:                              # f = (1 - |y|) - erfc(|x|), increasing in |x|
            f = (1.0 - abs(y)) - math.erfc(ax)
        else:
            f = math.erf(ax) - abs(y)
        d = f * (0.5 * _SQRT_PI) * math.exp(ax * ax)   # f / f'
        x = sign * (ax - d / (1.0 + ax * d))          # Halley: f'' / f' = -2 |x|
        if abs(d) <= 1e-9 * ax:                       # the next step would be below 1e-27
            break
    return x


@_jit
def _cdf(x, t):
    """Unnormalized visible-slope CDF (``distributions.beckmann._cdf``)."""
    return math.erfc(-x) + t * math.exp(-x * x) / _SQRT_PI


@_jit
def _ccdf(x, t, a, erfc_a, exp_a):
    """Unnormalized complementary CDF (``distributions.beckmann._ccdf``: closed form, or the
    12-point Gauss-Legendre rule where ``a - x < 1``)."""
    if a - x < 1.0:
        dn = a - x
        acc = 0.0
        for j in range(_GL_T.shape[0]):
            s = dn * _GL_T[j]
            acc += _GL_W[j] * s * math.exp(-(a - s) ** 2)
        return 2.0 * t / _SQRT_PI * dn * acc
    return math.erfc(x) - erfc_a + t * (exp_a - math.exp(-x * x)) / _SQRT_PI


@_jit
def _visible_slope_quantile(u, cos_theta):
    """``Q2(u)`` of the standard Beckmann visible x-slope (Table 2.V): the safeguarded
    Newton-bisection of ``distributions.beckmann.visible_slope_quantile``, per element (no
    compaction), from Mitsuba's fitted initial guess in the erf domain,
    ``erf(x0) = erf(a) - (1 + erf(a)) (1 - u)^(1 - 0.876 th + 0.4265 th^2 - 0.0594 th^3)``."""
    u = min(max(u, _U_MIN), 1.0 - _U_MIN)
    c = min(max(cos_theta, 1e-12), 1.0)
    s = math.sqrt(max(0.0, 1.0 - c * c))
    a = c / s
    t = s / c
    erfc_a, exp_a = math.erfc(a), math.exp(-a * a)
    z = math.erfc(-a) + t * exp_a / _SQRT_PI
    upper = u >= _UPPER                              # the upper tail: residual of 1 - F
    target = ((1.0 - u) if upper else u) * z
    lo, hi = -8.0, min(a, 8.0)
    th = math.acos(c)
    b_max = 1.0 - erfc_a
    b = b_max - (1.0 + b_max) * (1.0 - u) ** (1.0 + th * (-0.876 + th * (0.4265 - 0.0594 * th)))
    x = min(max(_erfinv(min(max(b, -1.0 + 2.0**-52), 1.0 - 2.0**-52)), lo), hi)
    for _ in range(64):
        r = target - _ccdf(x, t, a, erfc_a, exp_a) if upper else _cdf(x, t) - target
        if r < 0.0:
            lo = x
        if r > 0.0:
            hi = x
        step = r / (2.0 * math.exp(-x * x) * (1.0 - x * t) / _SQRT_PI)
        xn = x - step
        converged = (abs(step) <= 1e-12 * max(1.0, abs(x))) or r == 0.0
        if not converged and not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        done = converged or hi - lo <= 4e-16 * max(1.0, abs(x))
        x = xn
        if done:
            break
    return x


@_jit
def _visible_std(kind, u0, u1, cos_t):
    """Standard visible normal for a view at ``theta`` in the xz plane (``sample_visible_std``:
    Heitz's closed form for GGX; ``x~ = Q2(u0)``, ``y~ = erfinv(2 u1 - 1)`` for Beckmann)."""
    if kind == GGX:
        c = min(max(cos_t, 0.0), 1.0)
        s = math.sqrt(1.0 - c * c)
        a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0      # concentric disk (geometry)
        if abs(a) > abs(b):
            r, phi = a, (math.pi / 4) * (b / a)
        elif a == 0.0 and b == 0.0:
            r, phi = b, 0.0
        else:
            r, phi = b, math.pi / 2 - (math.pi / 4) * (a / b)
        t1, t2 = r * math.cos(phi), r * math.sin(phi)
        w = 0.5 * (1.0 + c)
        t2 = (1.0 - w) * math.sqrt(max(0.0, 1.0 - t1 * t1)) + w * t2
        tz = math.sqrt(max(0.0, 1.0 - t1 * t1 - t2 * t2))
        return s * tz - c * t2, t1, c * tz + s * t2
    x = _visible_slope_quantile(u0, cos_t)
    y = _erfinv(2.0 * min(max(u1, _U_MIN), 1.0 - _U_MIN) - 1.0)
    inv = 1.0 / math.sqrt(1.0 + x * x + y * y)
    return -x * inv, -y * inv, inv


# ------------------------------------------------------------------------ kernels
@_jit
def _unit_deviation(w):
    """``max | |w|^2 - 1 |`` over the rows of ``w (n, 3)``; ``inf`` at the first NaN/inf."""
    m = 0.0
    for j in range(w.shape[0]):
        e = abs(w[j, 0] * w[j, 0] + w[j, 1] * w[j, 1] + w[j, 2] * w[j, 2] - 1.0)
        if not e < math.inf:                  # NaN or inf
            return math.inf
        m = max(m, e)
    return m


@_pjit
def _smith_projected(wi, wo, kind, ax, ay, rho, xn, yn, shadowing, divide_cos_i, oh_out, s_out):
    """``o.h`` and ``D G / (4 z_o) [/ z_i]`` per pair into ``oh_out``, ``s_out`` (Eq. 2.1 with F = 1)."""
    s1 = math.sqrt(1.0 - rho * rho)
    for j in numba.prange(wi.shape[0]):
        oh, s = _smith(kind, ax, ay, rho, s1, xn, yn, shadowing,
                       wi[j, 0], wi[j, 1], wi[j, 2], wo[j, 0], wo[j, 1], wo[j, 2])
        oh_out[j] = oh
        s_out[j] = s / wi[j, 2] if (divide_cos_i and s > 0.0) else s


@_pjit
def _smith_eval(wi, wo, kind, ax, ay, rho, xn, yn, shadowing, divide_cos_i, fk, fp, tx, tv, out):
    """``F D G / (4 z_o) [/ z_i]`` RGB per pair into ``out (n, 3)`` (Eq. 2.1, Listing 2.2)."""
    s1 = math.sqrt(1.0 - rho * rho)
    for j in numba.prange(wi.shape[0]):
        oh, s = _smith(kind, ax, ay, rho, s1, xn, yn, shadowing,
                       wi[j, 0], wi[j, 1], wi[j, 2], wo[j, 0], wo[j, 1], wo[j, 2])
        if divide_cos_i and s > 0.0:
            s = s / wi[j, 2]
        _fresnel_rgb(fk, fp, tx, tv, oh, out, j, s)


@_pjit
def _smith_pdf(wi, wo, kind, ax, ay, rho, xn, yn, out):
    """Density of visible-normal sampling, ``D_o(h) / (4 o.h) = D(h) / (4 A(o))`` (Eq. 2.17,
    ``A(o) = c_o (1 + Lambda(o))``), per pair into ``out``."""
    s1 = math.sqrt(1.0 - rho * rho)
    for j in numba.prange(wi.shape[0]):
        ix, iy, iz = wi[j, 0], wi[j, 1], wi[j, 2]
        ox, oy, oz = wo[j, 0], wo[j, 1], wo[j, 2]
        hx, hy, hz = ix + ox, iy + oy, iz + oz
        n2 = hx * hx + hy * hy + hz * hz
        inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
        hx, hy, hz = hx * inv, hy * inv, hz * inv
        oh = ox * hx + oy * hy + oz * hz
        lam, co = _lambda_c(kind, ax, ay, rho, s1, xn, yn, ox, oy, oz)
        ok = (iz > 0.0) & (oz > 0.0) & (oh > 0.0) & (hz > 0.0) & (co > 0.0)
        d = _ndf(kind, ax, ay, rho, s1, xn, yn, hx, hy, hz if hz > 0.0 else 1.0)
        p = d / (4.0 * co * (1.0 + lam))
        out[j] = p if ok else 0.0


@_pjit
def _smith_sample(u, wo, kind, ax, ay, rho, xn, yn, shadowing, fk, fp, tx, tv, wi_out, weight_out, pdf_out):
    """Visible-normal sampling of ``f_r cos theta_i`` (Sec. 2.2, 3.2; ``MicrofacetBRDF.sample``):
    ``wi`` reflected about ``h ~ D_o``, weight ``F G / G1(o)`` (Eq. 2.23), pdf ``D(h) / (4 A(o))``."""
    s1 = math.sqrt(1.0 - rho * rho)
    for j in numba.prange(wo.shape[0]):
        ox, oy, oz = wo[j, 0], wo[j, 1], wo[j, 2]
        # warped view k' = (a, b, c) (Eq. 3.3) and its polar angle / azimuth
        a = ax * ox + rho * ay * oy
        b = ay * s1 * oy
        c = max(oz - ox * xn - oy * yn, 0.0)
        r2 = a * a + b * b
        if r2 > 0.0:
            inv_r = 1.0 / math.sqrt(r2)
            cos_t, cp, sp = c / math.sqrt(r2 + c * c), a * inv_r, b * inv_r
        else:
            cos_t, cp, sp = 1.0, 1.0, 0.0
        mx, my, mz = _visible_std(kind, u[j, 0], u[j, 1], cos_t)
        mx, my = cp * mx - sp * my, sp * mx + cp * my
        # slope map of Eq. 3.4 on the normal, then normalize
        hx = ax * mx - xn * mz
        hy = ay * (rho * mx + s1 * my) - yn * mz
        hz = mz
        n2 = hx * hx + hy * hy + hz * hz
        inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
        hx, hy, hz = hx * inv, hy * inv, hz * inv
        oh = ox * hx + oy * hy + oz * hz
        ix, iy, iz = 2.0 * oh * hx - ox, 2.0 * oh * hy - oy, 2.0 * oh * hz - oz
        wi_out[j, 0], wi_out[j, 1], wi_out[j, 2] = ix, iy, iz
        lam_o, co = _lambda_c(kind, ax, ay, rho, s1, xn, yn, ox, oy, oz)
        ok = (iz > 0.0) & (oz > 0.0) & (oh > 0.0) & (hz > 0.0) & (co > 0.0)
        area = co * (1.0 + lam_o)                    # A(o) = z_o / G1(o)
        d = _ndf(kind, ax, ay, rho, s1, xn, yn, hx, hy, hz if hz > 0.0 else 1.0)
        p = d / (4.0 * area)
        ok &= p > 0.0
        lam = lam_o
        visible = ok                                 # G > 0: wi is not shadowed below its horizon
        if shadowing:
            lam_i, ci = _lambda_c(kind, ax, ay, rho, s1, xn, yn, ix, iy, iz)
            lam += lam_i
            visible &= ci > 0.0
        ratio = area / (co * (1.0 + lam))            # G / G1(o)
        pdf_out[j] = p if ok else 0.0
        _fresnel_rgb(fk, fp, tx, tv, oh, weight_out, j, ratio if visible else 0.0)
