"""Numba kernels of the measured-BRDF readers (imported, and compiled or loaded from
Numba's on-disk cache, on first use: see :func:`microfacet.measured.base.compiled_kernels`).

Each format has one parallel loop for ``eval`` / ``eval_cos`` and one for ``sample``
(cosine warp, density and value fused), writing their outputs in place; the per-element
helpers repeat the NumPy reference's equations in the same order (the NumPy code of
:mod:`.rgl`, :mod:`.merl`, :mod:`.utia` and :mod:`.marginal2d` is the tested oracle).
Below either horizon the value is 0. ``error_model="numpy"``: a division by zero gives
inf/NaN, as in the reference, instead of raising.

Loop signatures: ``eval_*(wi, wo, cosine, out, *tables)`` writes ``f_r cos theta_i`` if
``cosine`` else ``f_r``; ``sample_*(u, wo, wi, weight, pdf, *tables)``; directions
``(N, 3)``, uniforms ``(N, 2)``, RGB ``(N, 3)``, all float64 C-contiguous.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from . import merl, utia

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
_pjit = numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)

_HALF_PI = math.pi / 2
_TWO_OVER_PI = 2.0 / math.pi
_TWO_PI = 2.0 * math.pi
_NH, _ND, _NP = merl.SHAPE
_NT, _NF = utia.SHAPE[1:3]                              # UTIA theta and phi nodes
_THETA_STEP, _PHI_STEP = float(utia.THETA_STEP), float(utia.PHI_STEP)
_UTIA_STRIDES = (_NF * _NT * _NF, _NT * _NF, _NF, 1)


# ----------------------------------------------------------------- shared helpers
@_jit
def _cosine_warp(u0, u1):
    """Malley's method on the Shirley-Chiu concentric disk (``square_to_cosine_hemisphere``)."""
    a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0, 1.0
    if abs(a) > abs(b):
        r, phi = a, (math.pi / 4) * (b / a)
    else:
        r, phi = b, math.pi / 2 - (math.pi / 4) * (a / b)
    x, y = r * math.cos(phi), r * math.sin(phi)
    return x, y, math.sqrt(max(0.0, 1.0 - (x * x + y * y)))


# ------------------------------------------------------------------- RGL (Marginal2D)
@_jit
def _lerp(a, b, t):
    return a + (b - a) * t


@_jit
def _elevation(x, y, z):
    """``2 asin(|w - z| / 2)`` (:func:`.rgl.elevation`)."""
    return 2.0 * math.asin(min(0.5 * math.sqrt(x * x + y * y + (z - 1.0) ** 2), 1.0))


@_jit
def _theta2u(theta):
    return math.sqrt(max(theta, 0.0) * _TWO_OVER_PI)


@_jit
def _phi2u(phi):
    return (phi + math.pi) / _TWO_PI


@_jit
def _node(nodes, p):
    """``(i0, i1, t)`` of one parameter (``Marginal2D._slices``): the last node below ``p``
    (``searchsorted`` left, minus 1, clipped) and ``clip((p - p0) / (p1 - p0), 0, 1)``."""
    n = len(nodes)
    if n == 1:
        return 0, 0, 0.0
    i0 = min(max(np.searchsorted(nodes, p) - 1, 0), n - 2)
    t = min(max((p - nodes[i0]) / (nodes[i0 + 1] - nodes[i0]), 0.0), 1.0)
    return i0, i0 + 1, t


@_jit
def _cell(u, n):
    """``Marginal2D._cell``: patch index and local coordinate of ``u`` (NaN as 0, clamped)."""
    if u != u:
        u = 0.0
    s = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(s), n - 2)
    return i, s - i


@_jit
def _corners(phi_nodes, theta_nodes, phi, theta):
    """Slices, weights and count of the parameter corners of ``Marginal2D._slices``:
    ``(s, w, nc)``, the ``nc`` (2 or 4) corners of nonzero weight first (a file with
    one ``phi_i`` node has 2: skipping the zero terms of the reference's sum is exact)."""
    p0, p1, tp = _node(phi_nodes, phi)
    q0, q1, tq = _node(theta_nodes, theta)
    n = len(theta_nodes)
    if len(phi_nodes) == 1:
        return (q0, q1, q0, q1), (1.0 - tq, tq, 0.0, 0.0), 2
    return ((p0 * n + q0, p1 * n + q0, p0 * n + q1, p1 * n + q1),
            ((1.0 - tp) * (1.0 - tq), tp * (1.0 - tq), (1.0 - tp) * tq, tp * tq), 4)


@_jit
def _look(table, s, w, nc, j, i):
    """Blend of ``table[s[c], j, i]`` over the parameter corners (``Marginal2D._lookup``)."""
    v = w[0] * table[s[0], j, i]
    for c in range(1, nc):
        v += w[c] * table[s[c], j, i]
    return v


@_jit
def _look_row(table, s, w, nc, j):
    v = w[0] * table[s[0], j]
    for c in range(1, nc):
        v += w[c] * table[s[c], j]
    return v


@_jit
def _invert(data, cond, marg, normalized, s, w, nc, x, y):
    """``Marginal2D.invert`` (u1, u2) at ``(x, y)``: the conditional and marginal CDFs of
    the bilinear patch, blended over the parameter corners."""
    H, W = data.shape[1], data.shape[2]
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    c0 = _lerp(_look(data, s, w, nc, j, i), _look(data, s, w, nc, j + 1, i), fy)
    c1 = _lerp(_look(data, s, w, nc, j, i + 1), _look(data, s, w, nc, j + 1, i + 1), fy)
    u1 = fx * _lerp(c0, c1, 0.5 * fx) / (W - 1)
    u1 = u1 + _lerp(_look(cond, s, w, nc, j, i), _look(cond, s, w, nc, j + 1, i), fy)
    r0, r1 = _look(cond, s, w, nc, j, W - 1), _look(cond, s, w, nc, j + 1, W - 1)
    u1 = u1 / _lerp(r0, r1, fy)
    u2 = fy * _lerp(r0, r1, 0.5 * fy) / (H - 1) + _look_row(marg, s, w, nc, j)
    if not normalized:
        u2 = u2 / _look_row(marg, s, w, nc, H - 1)
    return u1, u2


@_jit
def _bilinear(table, x, y):
    """``Marginal2D.eval`` of a table without parameters or channels, ``(H, W)``."""
    H, W = table.shape
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    return _lerp(_lerp(table[j, i], table[j, i + 1], fx), _lerp(table[j + 1, i], table[j + 1, i + 1], fx), fy)


@_jit
def _rgl_eval_cos(wi, wo, out, phi_nodes, theta_nodes, vndf, cond, marg, normalized, rgb, ndf, sigma,
                  isotropic, reduction, jacobian, clip_negative):
    """``RGLBRDF.eval_cos`` of one pair into ``out[0:3]`` (Dupuy & Jakob 2018: ``rgb(s)
    D(u_m) / (4 sigma(u_v))`` at the VNDF-warped half vector ``s``)."""
    ix, iy, iz, ox, oy, oz = wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]
    if not (iz > 0.0 and oz > 0.0):
        out[0] = out[1] = out[2] = 0.0
        return
    if reduction >= 2:                                   # RGLBRDF._mirror
        sy = oy
        sx = ox if reduction == 4 else sy
        fx = 1.0 if math.copysign(1.0, sx) < 0.0 else -1.0
        fy = 1.0 if math.copysign(1.0, sy) < 0.0 else -1.0
        ix, iy, ox, oy = ix * fx, iy * fy, ox * fx, oy * fy
    mx, my, mz = ix + ox, iy + oy, iz + oz
    norm = max(math.sqrt(mx * mx + my * my + mz * mz), 1e-300)
    mx, my, mz = mx / norm, my / norm, mz / norm
    theta_v, phi_v = _elevation(ox, oy, oz), math.atan2(oy, ox)
    theta_m, phi_m = _elevation(mx, my, mz), math.atan2(my, mx)
    um_x = _theta2u(theta_m)
    um_y = _phi2u(phi_m - phi_v if isotropic else phi_m)
    um_y = um_y - math.floor(um_y)
    s, w, nc = _corners(phi_nodes, theta_nodes, phi_v, theta_v)
    s1, s2 = _invert(vndf, cond, marg, normalized, s, w, nc, um_x, um_y)
    H, W = rgb.shape[2], rgb.shape[3]
    i, fx = _cell(s1, W)
    j, fy = _cell(s2, H)
    scale = 1.0
    if jacobian:
        scale = _bilinear(ndf, um_x, um_y) / (4.0 * _bilinear(sigma, _theta2u(theta_v), _phi2u(phi_v)))
    for c in range(3):
        t = rgb[c]
        v00, v10 = _look(t, s, w, nc, j, i), _look(t, s, w, nc, j, i + 1)
        v01, v11 = _look(t, s, w, nc, j + 1, i), _look(t, s, w, nc, j + 1, i + 1)
        v = _lerp(_lerp(v00, v10, fx), _lerp(v01, v11, fx), fy)
        if clip_negative:
            v = max(v, 0.0)
        out[c] = v * scale if jacobian else v


@_pjit
def eval_rgl(wi, wo, cosine, out, *tables):
    """``f_r cos theta_i`` (or ``f_r``) of an RGL BRDF for each pair."""
    for k in numba.prange(len(out)):
        _rgl_eval_cos(wi[k], wo[k], out[k], *tables)
        if not cosine:
            z = wi[k, 2]
            for c in range(3):
                out[k, c] = out[k, c] / z if z > 0.0 else 0.0


@_pjit
def sample_rgl(u, wo, wi, weight, pdf, *tables):
    """Cosine-weighted ``wi``, ``weight = eval_cos / pdf`` and ``pdf`` (``MeasuredBRDF.sample``)."""
    for k in numba.prange(len(wo)):
        wi[k, 0], wi[k, 1], wi[k, 2] = _cosine_warp(u[k, 0], u[k, 1])
        p = max(0.0, wi[k, 2]) / math.pi if wo[k, 2] > 0.0 else 0.0
        pdf[k] = p
        _rgl_eval_cos(wi[k], wo[k], weight[k], *tables)
        for c in range(3):
            weight[k, c] = weight[k, c] / p if p > 0.0 else 0.0


# --------------------------------------------------------------------------- MERL
@_jit
def _merl_axis_clamped(u, n):
    u = min(max(u, 0.0), n - 1.0)
    i0 = min(int(math.floor(u)), n - 2)
    return i0, i0 + 1, u - i0


@_jit
def _merl_eval(wi, wo, out, table):
    """``MERLBRDF.eval`` of one pair into ``out[0:3]``: Rusinkiewicz coordinates
    (``merl.hd_coordinates``), bin coordinates, validity-weighted trilinear interpolation."""
    ix, iy, iz = wi[0], wi[1], wi[2]
    if not (iz > 0.0 and wo[2] > 0.0):
        out[0] = out[1] = out[2] = 0.0
        return
    hx, hy, hz = ix + wo[0], iy + wo[1], iz + wo[2]
    n2 = hx * hx + hy * hy + hz * hz
    inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    r = math.hypot(hx, hy)
    cos_ph, sin_ph = (1.0, 0.0) if r == 0.0 else (hx / r, hy / r)
    a = cos_ph * ix + sin_ph * iy
    b = cos_ph * iy - sin_ph * ix
    dx, dz = hz * a - r * iz, r * a + hz * iz
    theta_h = math.atan2(r, hz)
    theta_d = math.atan2(math.hypot(dx, b), dz)
    phi_d = math.atan2(b, dx) % math.pi              # Python's % is np.mod
    h0, h1, th = _merl_axis_clamped(_NH * math.sqrt(max(theta_h, 0.0) / _HALF_PI), _NH)
    d0, d1, td = _merl_axis_clamped(_ND * (theta_d / _HALF_PI), _ND)
    up = (_NP * ((phi_d % math.pi) / math.pi)) % _NP
    fl = math.floor(up)
    p0 = int(fl) % _NP
    p1, tp = (p0 + 1) % _NP, up - fl
    f0 = f1 = f2 = cover = 0.0
    for ih, wh in ((h0, 1 - th), (h1, th)):
        for jd, wd in ((d0, 1 - td), (d1, td)):
            for kp, wp in ((p0, 1 - tp), (p1, tp)):
                w = wh * wd * wp
                row = kp + _NP * (jd + _ND * ih)
                f0 += w * table[row, 0]
                f1 += w * table[row, 1]
                f2 += w * table[row, 2]
                cover += w * table[row, 3]
    if cover > 0.0:
        out[0], out[1], out[2] = f0 / cover, f1 / cover, f2 / cover
    else:
        out[0] = out[1] = out[2] = 0.0


# --------------------------------------------------------------------------- UTIA
@_jit
def _utia_theta(theta):
    u = min(max(theta / _THETA_STEP, 0.0), _NT - 1.0)
    i0 = min(int(math.floor(u)), _NT - 2)
    return i0, i0 + 1, u - i0


@_jit
def _utia_phi(phi):
    u = (phi / _PHI_STEP) % _NF
    fl = math.floor(u)
    i0 = int(fl)
    return i0 % _NF, (i0 + 1) % _NF, u - fl


@_jit
def _utia_eval(wi, wo, out, flat):
    """``UTIABRDF.eval`` of one pair into ``out[0:3]``: quadrilinear in
    ``(theta_i, phi_i, theta_v, phi_v)``."""
    if not (wi[2] > 0.0 and wo[2] > 0.0):
        out[0] = out[1] = out[2] = 0.0
        return
    a0, a1, at = _utia_theta(math.atan2(math.hypot(wi[0], wi[1]), wi[2]))
    b0, b1, bt = _utia_phi(math.atan2(wi[1], wi[0]))
    c0, c1, ct = _utia_theta(math.atan2(math.hypot(wo[0], wo[1]), wo[2]))
    d0, d1, dt = _utia_phi(math.atan2(wo[1], wo[0]))
    lo, hi, t = (a0, b0, c0, d0), (a1, b1, c1, d1), (at, bt, ct, dt)
    f0 = f1 = f2 = 0.0
    for corner in range(16):                        # axis bits as in UTIABRDF.eval
        idx, w = 0, 1.0
        for axis in range(4):
            if (corner >> axis) & 1:
                idx, w = idx + _UTIA_STRIDES[axis] * hi[axis], w * t[axis]
            else:
                idx, w = idx + _UTIA_STRIDES[axis] * lo[axis], w * (1.0 - t[axis])
        f0 += w * flat[idx, 0]
        f1 += w * flat[idx, 1]
        f2 += w * flat[idx, 2]
    out[0], out[1], out[2] = f0, f1, f2


# ------------------------------------------------- MERL and UTIA: one table (rows x channels)
MERL, UTIA = 0, 1


@_jit
def _table_eval(kind, wi, wo, out, table):
    if kind == MERL:
        _merl_eval(wi, wo, out, table)
    else:
        _utia_eval(wi, wo, out, table)


@_pjit
def eval_table(wi, wo, cosine, out, kind, table):
    """``f_r`` (or ``f_r cos theta_i``) of a MERL or UTIA BRDF (``kind``) for each pair."""
    for k in numba.prange(len(out)):
        _table_eval(kind, wi[k], wo[k], out[k], table)
        if cosine:
            z = max(wi[k, 2], 0.0)
            for c in range(3):
                out[k, c] *= z


@_pjit
def sample_table(u, wo, wi, weight, pdf, kind, table):
    """Cosine-weighted ``wi``, ``weight = f_r cos theta_i / pdf`` and ``pdf``."""
    for k in numba.prange(len(wo)):
        wi[k, 0], wi[k, 1], wi[k, 2] = _cosine_warp(u[k, 0], u[k, 1])
        cos_i = max(0.0, wi[k, 2])
        p = cos_i / math.pi if wo[k, 2] > 0.0 else 0.0
        pdf[k] = p
        _table_eval(kind, wi[k], wo[k], weight[k], table)
        for c in range(3):
            weight[k, c] = weight[k, c] * cos_i / p if p > 0.0 else 0.0
