"""Numba kernels of the measured-BRDF readers (imported, and compiled or loaded from
Numba's on-disk cache, on first use: see :func:`microfacet.measured.base.compiled_kernels`).

RGL (``eval_rgl``, ``sample_rgl``) and MERL / UTIA (``eval_table``, ``sample_table``) each
have one parallel loop for ``eval`` / ``eval_cos`` and one for ``sample`` (cosine warp,
density and value fused), writing their outputs in place. The per-element helpers repeat
the NumPy reference's equations in its order (the NumPy code of :mod:`.rgl`,
:mod:`.merl`, :mod:`.utia` and :mod:`.marginal2d` is the tested oracle); where a cheaper
form gives the same value on unit vectors it says so (``sqrt`` for ``hypot``, one
comparison for ``np.mod`` of an ``atan2``). Below either horizon the value is 0.
``error_model="numpy"``: a division by zero gives inf/NaN, as in the reference.

The loops run over blocks of :data:`BLOCK` pairs: first the coordinates of every pair of
the block, then the table lookups, so that the cache misses of many pairs overlap (the
MERL table is 46 MB, RGL's VNDF and CDF 2 MB; measured 1.5-1.8x less CPU time than one
pair at a time).

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
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")

_HALF_PI = math.pi / 2
_TWO_OVER_PI = 2.0 / math.pi
_TWO_PI = 2.0 * math.pi
BLOCK = 64                               # pairs per block of the loops
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
    """``a + (b - a) t`` (``marginal2d._lerp``)."""
    return a + (b - a) * t


@_jit
def _elevation(x, y, z):
    """``2 asin(|w - z| / 2)`` (:func:`.rgl.elevation`)."""
    return 2.0 * math.asin(min(0.5 * math.sqrt(x * x + y * y + (z - 1.0) ** 2), 1.0))


@_jit
def _theta2u(theta):
    """``sqrt(2 theta / pi)`` (:func:`.rgl.theta2u`)."""
    return math.sqrt(max(theta, 0.0) * _TWO_OVER_PI)


@_jit
def _phi2u(phi):
    """``(phi + pi) / (2 pi)`` (:func:`.rgl.phi2u`)."""
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
def _param_corners(phi_nodes, theta_nodes, phi, theta):
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


@_inline
def _invert(vc, rows, marg, normalized, s, w, nc, x, y):
    """``Marginal2D.invert`` (u1, u2) at ``(x, y)``: the conditional and marginal CDFs of
    the bilinear patch. ``vc[s, j, i] = (value, conditional CDF)``, ``rows[s, j]`` the row
    integrals (the CDF's last column), ``marg[s, j]`` the marginal CDF; each lookup is the
    blend over the parameter corners (``Marginal2D._lookup``), summed in the same order."""
    H, W = vc.shape[1], vc.shape[2]
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    d00 = d01 = d10 = d11 = q0 = q1 = r0 = r1 = m = m_end = 0.0
    for c in range(nc):
        sc, wc = s[c], w[c]
        d00 += wc * vc[sc, j, i, 0]
        d01 += wc * vc[sc, j + 1, i, 0]
        d10 += wc * vc[sc, j, i + 1, 0]
        d11 += wc * vc[sc, j + 1, i + 1, 0]
        q0 += wc * vc[sc, j, i, 1]
        q1 += wc * vc[sc, j + 1, i, 1]
        r0 += wc * rows[sc, j]
        r1 += wc * rows[sc, j + 1]
        m += wc * marg[sc, j]
        m_end += wc * marg[sc, H - 1]
    c0, c1 = _lerp(d00, d01, fy), _lerp(d10, d11, fy)
    u1 = fx * _lerp(c0, c1, 0.5 * fx) / (W - 1)
    u1 = (u1 + _lerp(q0, q1, fy)) / _lerp(r0, r1, fy)
    u2 = fy * _lerp(r0, r1, 0.5 * fy) / (H - 1) + m
    return u1, (u2 if normalized else u2 / m_end)


@_inline
def _rgb_channel(rgb, s, w, nc, j, i, fx, fy, ch):
    """Channel ``ch`` of ``Marginal2D.eval`` of the RGB table ``rgb[s, j, i, channel]``
    in cell ``(j, i)`` at local coordinates ``(fx, fy)``."""
    v00 = v01 = v10 = v11 = 0.0
    for c in range(nc):
        sc, wc = s[c], w[c]
        v00 += wc * rgb[sc, j, i, ch]
        v10 += wc * rgb[sc, j, i + 1, ch]
        v01 += wc * rgb[sc, j + 1, i, ch]
        v11 += wc * rgb[sc, j + 1, i + 1, ch]
    return _lerp(_lerp(v00, v10, fx), _lerp(v01, v11, fx), fy)


@_inline
def _rgb_eval(rgb, s, w, nc, x, y):
    """``Marginal2D.eval`` of the RGB table at ``(x, y)``."""
    i, fx = _cell(x, rgb.shape[2])
    j, fy = _cell(y, rgb.shape[1])
    return (_rgb_channel(rgb, s, w, nc, j, i, fx, fy, 0), _rgb_channel(rgb, s, w, nc, j, i, fx, fy, 1),
            _rgb_channel(rgb, s, w, nc, j, i, fx, fy, 2))


@_jit
def _bilinear(table, x, y):
    """``Marginal2D.eval`` of a table without parameters or channels, ``(H, W)``."""
    H, W = table.shape
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    return _lerp(_lerp(table[j, i], table[j, i + 1], fx), _lerp(table[j + 1, i], table[j + 1, i + 1], fx), fy)


@_inline
def _rgl_coordinates(ix, iy, iz, ox, oy, oz, isotropic, reduction):
    """``(u_m, theta_v, phi_v)`` of ``RGLBRDF._eval_cos_numpy``: the directions mirrored
    into the stored azimuths (``RGLBRDF._mirror``), the unit coordinates ``u_m`` of the
    half vector (relative to ``phi_v`` if isotropic) and the view's angles."""
    if reduction >= 2:
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
    um_y = _phi2u(phi_m - phi_v if isotropic else phi_m)
    return _theta2u(theta_m), um_y - math.floor(um_y), theta_v, phi_v


@_jit
def _rgl_block(wi, wo, k0, k1, out, phi_nodes, theta_nodes, vc, rows, marg, normalized, rgb, ndf, sigma,
               isotropic, reduction, jacobian, clip_negative):
    """``RGLBRDF.eval_cos`` (Dupuy & Jakob 2018: ``rgb(s) D(u_m) / (4 sigma(u_v))`` at the
    VNDF-warped half vector ``s``) of pairs ``k0 .. k1 - 1`` into ``out``, in three passes
    over the block (coordinates, VNDF inversion, RGB lookup) so that the table lookups of
    different pairs overlap; 0 below either horizon."""
    n = k1 - k0
    geo, st = np.empty((n, 4)), np.empty((n, 2))
    cs, cw = np.empty((n, 4), np.int64), np.empty((n, 4))
    up = np.empty(n, np.bool_)
    for k in range(n):
        ix, iy, iz, ox, oy, oz = wi[k0 + k, 0], wi[k0 + k, 1], wi[k0 + k, 2], wo[k0 + k, 0], wo[k0 + k, 1], wo[k0 + k, 2]
        up[k] = iz > 0.0 and oz > 0.0
        geo[k, 0], geo[k, 1], geo[k, 2], geo[k, 3] = _rgl_coordinates(ix, iy, iz, ox, oy, oz, isotropic, reduction)
        s, w, nc = _param_corners(phi_nodes, theta_nodes, geo[k, 3], geo[k, 2])
        for c in range(4):
            cs[k, c], cw[k, c] = s[c], w[c]
    nc = 2 if len(phi_nodes) == 1 else 4
    for k in range(n):
        st[k, 0], st[k, 1] = _invert(vc, rows, marg, normalized, cs[k], cw[k], nc, geo[k, 0], geo[k, 1])
    for k in range(n):
        if not up[k]:
            out[k0 + k, 0] = out[k0 + k, 1] = out[k0 + k, 2] = 0.0
            continue
        r, g, b = _rgb_eval(rgb, cs[k], cw[k], nc, st[k, 0], st[k, 1])
        if clip_negative:
            r, g, b = max(r, 0.0), max(g, 0.0), max(b, 0.0)
        if jacobian:
            um_x, um_y, theta_v, phi_v = geo[k, 0], geo[k, 1], geo[k, 2], geo[k, 3]
            scale = _bilinear(ndf, um_x, um_y) / (4.0 * _bilinear(sigma, _theta2u(theta_v), _phi2u(phi_v)))
            r, g, b = r * scale, g * scale, b * scale
        out[k0 + k, 0], out[k0 + k, 1], out[k0 + k, 2] = r, g, b


@_pjit
def eval_rgl(wi, wo, cosine, out, *tables):
    """``f_r cos theta_i`` (or ``f_r``) of an RGL BRDF for each pair."""
    n = len(out)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        _rgl_block(wi, wo, k0, k1, out, *tables)
        if not cosine:
            for k in range(k0, k1):
                z = wi[k, 2]
                for c in range(3):
                    out[k, c] = out[k, c] / z if z > 0.0 else 0.0


@_pjit
def sample_rgl(u, wo, wi, weight, pdf, *tables):
    """Cosine-weighted ``wi``, ``weight = eval_cos / pdf`` and ``pdf`` (``MeasuredBRDF.sample``)."""
    n = len(wo)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        for k in range(k0, k1):
            wi[k, 0], wi[k, 1], wi[k, 2] = _cosine_warp(u[k, 0], u[k, 1])
            pdf[k] = max(0.0, wi[k, 2]) / math.pi if wo[k, 2] > 0.0 else 0.0
        _rgl_block(wi, wo, k0, k1, weight, *tables)
        for k in range(k0, k1):
            p = pdf[k]
            for c in range(3):
                weight[k, c] = weight[k, c] / p if p > 0.0 else 0.0


# --------------------------------------------- MERL and UTIA: corners of one table, blended
# Each pair gives 8 (MERL) or 16 (UTIA) (row, weight) corners of a table (rows, channels).
MERL, UTIA = 0, 1


@_jit
def _clamped(u, n):
    """Nodes and upper weight on ``0..n-1``, clamped (``merl._axis_clamped``, ``utia._theta_axis``)."""
    u = min(max(u, 0.0), n - 1.0)
    i0 = min(int(math.floor(u)), n - 2)
    return i0, i0 + 1, u - i0


@_jit
def _periodic(u, n):
    """Nodes and upper weight on a periodic axis of ``n`` nodes, ``u`` in ``[0, n]`` (``n``
    is node 0 with weight 0, as ``np.mod(u, n) = 0``)."""
    fl = math.floor(u)
    i0 = int(fl) % n
    return i0, (i0 + 1) % n, u - fl


@_inline
def _merl_corners(ix, iy, iz, ox, oy, oz, rows, weights, k):
    """The 8 trilinear corners of ``MERLBRDF._corners``: Rusinkiewicz coordinates
    (``merl.hd_coordinates``), bin coordinates, flat rows and weights."""
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    n2 = hx * hx + hy * hy + hz * hz
    inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    r = math.sqrt(hx * hx + hy * hy)                 # hypot of unit vectors (to an ulp)
    cos_ph, sin_ph = (1.0, 0.0) if r == 0.0 else (hx / r, hy / r)
    a = cos_ph * ix + sin_ph * iy
    b = cos_ph * iy - sin_ph * ix
    dx, dz = hz * a - r * iz, r * a + hz * iz
    theta_h = math.atan2(r, hz)
    theta_d = math.atan2(math.sqrt(dx * dx + b * b), dz)
    phi_d = math.atan2(b, dx)
    phi_d = phi_d + math.pi if phi_d < 0.0 else phi_d   # np.mod(phi_d, pi), up to pi itself
    h0, h1, th = _clamped(_NH * math.sqrt(max(theta_h, 0.0) / _HALF_PI), _NH)
    d0, d1, td = _clamped(_ND * (theta_d / _HALF_PI), _ND)
    p0, p1, tp = _periodic(_NP * (phi_d / math.pi), _NP)
    q = 0
    for ih, wh in ((h0, 1 - th), (h1, th)):
        for jd, wd in ((d0, 1 - td), (d1, td)):
            for kp, wp in ((p0, 1 - tp), (p1, tp)):
                rows[k, q], weights[k, q] = kp + _NP * (jd + _ND * ih), wh * wd * wp
                q += 1


@_jit
def _phi_unit(phi):
    """``np.mod(phi / PHI_STEP, 48)`` for ``phi`` in ``[-pi, pi]`` (up to 48 itself)."""
    u = phi / _PHI_STEP
    return u + _NF if u < 0.0 else u


@_jit
def _utia_corners(ix, iy, iz, ox, oy, oz, rows, weights, k):
    """The 16 quadrilinear corners of ``UTIABRDF.eval`` in ``(theta_i, phi_i, theta_v, phi_v)``."""
    lo0, hi0, t0 = _clamped(math.atan2(math.sqrt(ix * ix + iy * iy), iz) / _THETA_STEP, _NT)
    lo1, hi1, t1 = _periodic(_phi_unit(math.atan2(iy, ix)), _NF)
    lo2, hi2, t2 = _clamped(math.atan2(math.sqrt(ox * ox + oy * oy), oz) / _THETA_STEP, _NT)
    lo3, hi3, t3 = _periodic(_phi_unit(math.atan2(oy, ox)), _NF)
    lo, hi, t = (lo0, lo1, lo2, lo3), (hi0, hi1, hi2, hi3), (t0, t1, t2, t3)
    for corner in range(16):                        # axis bits as in UTIABRDF.eval
        idx, w = 0, 1.0
        for axis in range(4):
            if (corner >> axis) & 1:
                idx, w = idx + _UTIA_STRIDES[axis] * hi[axis], w * t[axis]
            else:
                idx, w = idx + _UTIA_STRIDES[axis] * lo[axis], w * (1.0 - t[axis])
        rows[k, corner], weights[k, corner] = idx, w


@_inline
def _corners(kind, ix, iy, iz, ox, oy, oz, rows, weights, k):
    """Corners of a pair into ``rows[k], weights[k]``; all weights 0 below either horizon
    (then the value is 0)."""
    if not (iz > 0.0 and oz > 0.0):
        for c in range(16):
            rows[k, c], weights[k, c] = 0, 0.0
    elif kind == MERL:
        _merl_corners(ix, iy, iz, ox, oy, oz, rows, weights, k)
    else:
        _utia_corners(ix, iy, iz, ox, oy, oz, rows, weights, k)


@_inline
def _blend(kind, table, rows, weights, k):
    """``sum_c w_c table[row_c]``, RGB, over the corners ``rows[k], weights[k]``; MERL
    divides by the weight on measured samples (its table's 4th column, 0 on unmeasured
    ones) and is 0 where there is none."""
    if kind != MERL:
        f0 = f1 = f2 = 0.0
        for c in range(16):
            row, w = rows[k, c], weights[k, c]
            f0 += w * table[row, 0]
            f1 += w * table[row, 1]
            f2 += w * table[row, 2]
        return f0, f1, f2
    f0 = f1 = f2 = cover = 0.0
    for c in range(8):
        row, w = rows[k, c], weights[k, c]
        f0 += w * table[row, 0]
        f1 += w * table[row, 1]
        f2 += w * table[row, 2]
        cover += w * table[row, 3]
    return (f0 / cover, f1 / cover, f2 / cover) if cover > 0.0 else (0.0, 0.0, 0.0)


@_pjit
def eval_table(wi, wo, cosine, out, kind, table):
    """``f_r`` (or ``f_r cos theta_i``) of a MERL or UTIA BRDF (``kind``) for each pair."""
    n = len(out)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        rows, weights = np.empty((BLOCK, 16), np.int64), np.empty((BLOCK, 16))
        for k in range(k0, k1):
            _corners(kind, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2], rows, weights, k - k0)
        for k in range(k0, k1):
            r, g, b = _blend(kind, table, rows, weights, k - k0)
            if cosine:
                z = max(wi[k, 2], 0.0)
                r, g, b = r * z, g * z, b * z
            out[k, 0], out[k, 1], out[k, 2] = r, g, b


@_pjit
def sample_table(u, wo, wi, weight, pdf, kind, table):
    """Cosine-weighted ``wi``, ``weight = f_r cos theta_i / pdf`` and ``pdf``."""
    n = len(wo)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        rows, weights = np.empty((BLOCK, 16), np.int64), np.empty((BLOCK, 16))
        for k in range(k0, k1):
            x, y, z = _cosine_warp(u[k, 0], u[k, 1])
            wi[k, 0], wi[k, 1], wi[k, 2] = x, y, z
            pdf[k] = max(0.0, z) / math.pi if wo[k, 2] > 0.0 else 0.0
            _corners(kind, x, y, z, wo[k, 0], wo[k, 1], wo[k, 2], rows, weights, k - k0)
        for k in range(k0, k1):
            r, g, b = _blend(kind, table, rows, weights, k - k0)
            cos_i, p = max(0.0, wi[k, 2]), pdf[k]
            weight[k, 0], weight[k, 1], weight[k, 2] = \
                (r * cos_i / p, g * cos_i / p, b * cos_i / p) if p > 0.0 else (0.0, 0.0, 0.0)
