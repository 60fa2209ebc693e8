"""Single-pass compiled kernels (Numba) for the hot path of the Smith microfacet BRDF.

The NumPy code of :mod:`microfacet.distributions` and :mod:`microfacet.brdf` is the
reference; these kernels fuse the same equations into one loop over directions (the
NumPy version makes ~40 passes over memory) and are tested against it. They cover
``gaf="smith"`` with scalar Beckmann or GGX parameters; everything else takes the NumPy
path. Set ``MICROFACET_NUMBA=0`` to disable them.
"""
from __future__ import annotations

import math
import os

import numpy as np

try:
    if os.environ.get("MICROFACET_NUMBA", "1") == "0":
        raise ImportError("disabled by MICROFACET_NUMBA=0")
    import numba
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None

__all__ = ["AVAILABLE", "smith_projected", "unit_deviation"]

AVAILABLE = numba is not None
BECKMANN, GGX = 0, 1
_SQRT_PI = math.sqrt(math.pi)

if AVAILABLE:
    _jit = numba.njit(cache=True, fastmath=False, nogil=True)

    @_jit
    def _lambda(kind, r2, c):
        """Smith Lambda of the warped direction ``(a, b, c)``, ``r2 = a^2 + b^2``, ``c > 0``
        (Table 2.III; see ``lambda_warped``)."""
        if kind == GGX:
            return r2 / (2.0 * c * (math.sqrt(r2 + c * c) + c))
        if r2 == 0.0:
            return 0.0
        v = c / math.sqrt(r2)
        return max(0.5 * (math.exp(-v * v) / (v * _SQRT_PI) - math.erfc(v)), 0.0)

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

    @numba.njit(cache=True, parallel=True, nogil=True)
    def _smith_projected(wi, wo, kind, ax, ay, rho, xn, yn, shadowing, divide_cos_i, oh_out, s_out):
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


def smith_projected(distribution, shadowing: bool, wi, wo, divide_cos_i: bool):
    """``(o.h, D G / (4 z_o) [/ z_i])`` by the compiled kernel, or ``None`` when it does
    not apply (no Numba, array parameters, another distribution)."""
    from .distributions import GGX as _GGX, Beckmann as _Beckmann
    d = distribution
    kind = {_Beckmann: BECKMANN, _GGX: GGX}.get(type(d))
    if not AVAILABLE or kind is None or any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        return None
    wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
    shape = wi.shape[:-1]
    wi2 = np.ascontiguousarray(wi.reshape(-1, 3))
    wo2 = np.ascontiguousarray(wo.reshape(-1, 3))
    oh, s = np.empty(len(wi2)), np.empty(len(wi2))
    _smith_projected(wi2, wo2, kind, float(d.alpha_x), float(d.alpha_y), float(d.rho), float(d.xn),
                     float(d.yn), bool(shadowing), bool(divide_cos_i), oh, s)
    return oh.reshape(shape), s.reshape(shape)


def unit_deviation(w: np.ndarray) -> float:
    """:func:`microfacet.geometry.unit_deviation` (``max | |w|^2 - 1 |``, ``inf`` on NaN/inf)
    in one compiled pass over a C-contiguous float64 ``w (..., 3)``; the NumPy reference
    for other arrays or without Numba."""
    from .geometry import unit_deviation as reference
    if not AVAILABLE or w.dtype != np.float64 or not w.flags.c_contiguous or w.size == 0:
        return reference(w)
    return float(_unit_deviation(w.reshape(-1, 3)))
