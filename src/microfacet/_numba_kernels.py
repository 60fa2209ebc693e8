"""The Numba kernels of :mod:`microfacet.kernels` (imported, and compiled or loaded from
Numba's on-disk cache, on first use; see that module)."""
from __future__ import annotations

import math

import numba

BECKMANN, GGX = 0, 1
_SQRT_PI = math.sqrt(math.pi)


@numba.njit(cache=True, fastmath=False, nogil=True)
def _lambda(kind, r2, c):
    """Smith Lambda of the warped direction ``(a, b, c)``, ``r2 = a^2 + b^2``, ``c > 0``
    (Table 2.III; see ``lambda_warped``)."""
    if kind == GGX:
        return r2 / (2.0 * c * (math.sqrt(r2 + c * c) + c))
    if r2 == 0.0:
        return 0.0
    v = c / math.sqrt(r2)
    return max(0.5 * (math.exp(-v * v) / (v * _SQRT_PI) - math.erfc(v)), 0.0)


@numba.njit(cache=True, nogil=True)
def _unit_deviation(w):
    """``max | |w|^2 - 1 |`` over the rows of ``w (n, 3)``; ``inf`` at the first NaN/inf."""
    m = 0.0
    for j in range(w.shape[0]):
        e = abs(w[j, 0] * w[j, 0] + w[j, 1] * w[j, 1] + w[j, 2] * w[j, 2] - 1.0)
        if not e < math.inf:                  # NaN or inf
            return math.inf
        m = max(m, e)
    return m


@numba.njit(cache=True, parallel=True, nogil=True)
def _smith_projected(wi, wo, kind, ax, ay, rho, xn, yn, shadowing, divide_cos_i, oh_out, s_out):
    """``o.h`` and ``D G / (4 z_o) [/ z_i]`` per pair into ``oh_out``, ``s_out`` (Eq. 2.1 with
    F = 1; NDF Eq. 3.2, height-correlated Smith G with the warped directions of Eq. 3.3)."""
    s1 = math.sqrt(1.0 - rho * rho)
    det = ax * ay * s1
    for j in numba.prange(wi.shape[0]):
        ix, iy, iz = wi[j, 0], wi[j, 1], wi[j, 2]
        ox, oy, oz = wo[j, 0], wo[j, 1], wo[j, 2]
        hx, hy, hz = ix + ox, iy + oy, iz + oz
        n2 = hx * hx + hy * hy + hz * hz
        inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
        hx, hy, hz = hx * inv, hy * inv, hz * inv
        oh = ox * hx + oy * hy + oz * hz
        oh_out[j] = oh
        s_out[j] = 0.0
        if iz <= 0.0 or oz <= 0.0 or oh <= 0.0 or hz <= 0.0:
            continue
        # masking (and shadowing) of the warped directions, Eq. 3.3
        a = ax * ox + rho * ay * oy
        b = ay * s1 * oy
        co = oz - ox * xn - oy * yn
        if co <= 0.0:
            continue
        lam = _lambda(kind, a * a + b * b, co)
        if shadowing:
            a = ax * ix + rho * ay * iy
            b = ay * s1 * iy
            ci = iz - ix * xn - iy * yn
            if ci <= 0.0:
                continue
            lam += _lambda(kind, a * a + b * b, ci)
        g = oz / (co * (1.0 + lam))
        # NDF, Eq. 3.2, division-free: P_std(X/z, Y/z) / z^4
        x = (-hx - xn * hz) / ax
        y = (ax * (-hy - yn * hz) - rho * ay * (-hx - xn * hz)) / (ax * ay * s1)
        if kind == GGX:
            r = hz * hz + x * x + y * y
            d = 1.0 / (math.pi * r * r)
        else:
            d = math.exp(-(x * x + y * y) / (hz * hz) - 4.0 * math.log(hz)) / math.pi
        s = d / det * g / (4.0 * oz)
        s_out[j] = s / iz if divide_cos_i else s
