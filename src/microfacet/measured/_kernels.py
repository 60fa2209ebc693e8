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

The loops run over blocks of :data:`BLOCK` pairs, in passes through 1-D scratch rows:
first the coordinates of every pair of the block, then the table lookups, so that the
cache misses of many pairs overlap (the MERL table is 46 MB, RGL's VNDF and CDF 2 MB).
Arrays are read through flat 1-D views of the block (``w[3 k + c]``): loops that index
2-D arrays with runtime strides, or at offsets ``3 (k0 + k)``, do not vectorize. The
coordinate passes call no libm function (:func:`_atan2`, a Cephes polynomial within 2 ulp
of libm, stands for ``atan2`` and ``asin``), so LLVM vectorizes them (AVX2 / AVX-512).

Loop signatures: ``eval_*(wi, wo, cosine, out, tables)`` writes ``f_r cos theta_i`` if
``cosine`` else ``f_r``; ``sample_*(u, wo, wi, weight, pdf, tables)``, ``tables`` the reader's
record, passed whole (:class:`microfacet.measured.rgl.RGLTables`; ``(kind, table)`` for MERL
and UTIA); directions
``(N, 3)``, uniforms ``(N, 2)``, RGB ``(N, 3)``, all float64 C-contiguous (read through
their flat views).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .grids import MERL_SHAPE, UTIA_PHI_STEP, UTIA_SHAPE, UTIA_THETA_STEP

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
_pjit = numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")

_HALF_PI = math.pi / 2
_TWO_OVER_PI = 2.0 / math.pi
_TWO_PI = 2.0 * math.pi
BLOCK = 256                              # pairs per block of the loops
_NH, _ND, _NP = MERL_SHAPE
_NT, _NF = UTIA_SHAPE[1:3]                              # UTIA theta and phi nodes
_THETA_STEP, _PHI_STEP = UTIA_THETA_STEP, UTIA_PHI_STEP
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


@_inline
def _warp_block(u, wo, wi, pdf):
    """Cosine-weighted ``wi`` (:func:`_cosine_warp`) and ``pdf = cos theta_i / pi`` (0 if
    ``wo`` is below the horizon) of a block, flat."""
    for k in range(len(pdf)):
        wi[3 * k], wi[3 * k + 1], wi[3 * k + 2] = _cosine_warp(u[2 * k], u[2 * k + 1])
        pdf[k] = max(0.0, wi[3 * k + 2]) / math.pi if wo[3 * k + 2] > 0.0 else 0.0


@_inline
def _divide_by_pdf(weight, pdf):
    """``weight = eval_cos / pdf`` in place (0 where ``pdf`` is 0), flat RGB."""
    for j in range(len(weight)):
        p = pdf[j // 3]
        weight[j] = weight[j] / p if p > 0.0 else 0.0


# Cephes atan.c (S. Moshier): tan(3 pi / 8), the low bits of pi / 2, and the rational
# approximation atan(t) = t + t z P(z) / Q(z), z = t^2, |t| <= 0.66.
_TAN_3PI_8 = 2.41421356237309504880
_PI_2_LOW = 6.123233995736765886130e-17
_ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
           -1.228866684490136173410e2, -6.485021904942025371773e1)
_ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
           4.853903996359136964868e2, 1.945506571482613964425e2)


@_inline
def _atan(x):
    """``atan(x)`` for ``x >= 0`` (Cephes ``atan``: ``x`` reduced to ``|t| <= 0.66`` by
    ``atan(x) = pi/2 + atan(-1/x)`` above ``tan(3 pi / 8)`` and ``pi/4 + atan((x-1)/(x+1))``
    above 0.66; within 2 ulp of libm). Selects, no calls: loops that use it vectorize."""
    big, mid = x > _TAN_3PI_8, x > 0.66
    t = -1.0 / x if big else ((x - 1.0) / (x + 1.0) if mid else x)
    base = (math.pi / 2 if big else math.pi / 4) if mid else 0.0
    low = (_PI_2_LOW if big else 0.5 * _PI_2_LOW) if mid else 0.0
    z = t * t
    p = (((_ATAN_P[0] * z + _ATAN_P[1]) * z + _ATAN_P[2]) * z + _ATAN_P[3]) * z + _ATAN_P[4]
    q = ((((z + _ATAN_Q[0]) * z + _ATAN_Q[1]) * z + _ATAN_Q[2]) * z + _ATAN_Q[3]) * z + _ATAN_Q[4]
    return base + ((t * (z * p / q) + t) + low)


@_inline
def _atan2(y, x):
    """``math.atan2(y, x)`` of finite ``y``, ``x`` (signed zeros included) by :func:`_atan`
    of ``|y| / |x|`` (within 2 ulp of libm)."""
    ay, ax = abs(y), abs(x)
    r = _atan(ay / ax) if ax > 0.0 else (_HALF_PI if ay > 0.0 else 0.0)
    return math.copysign(math.pi - r if math.copysign(1.0, x) < 0.0 else r, y)


# ------------------------------------------------------------------- RGL (Marginal2D)
@_jit
def _lerp(a, b, t):
    """``a + (b - a) t`` (``marginal2d._lerp``)."""
    return a + (b - a) * t


@_inline
def _elevation(x, y, z):
    """``2 asin(a)``, ``a = min(|w - z| / 2, 1)`` (:func:`.rgl.elevation`), as
    ``2 atan2(a, sqrt((1 - a)(1 + a)))``."""
    a = min(0.5 * math.sqrt(x * x + y * y + (z - 1.0) ** 2), 1.0)
    return 2.0 * _atan2(a, math.sqrt((1.0 - a) * (1.0 + a)))


@_inline
def _theta2u(theta):
    """``sqrt(2 theta / pi)`` (:func:`.rgl.theta2u`)."""
    return math.sqrt(max(theta, 0.0) * _TWO_OVER_PI)


@_inline
def _phi2u(phi):
    """``(phi + pi) / (2 pi)`` (:func:`.rgl.phi2u`)."""
    return (phi + math.pi) / _TWO_PI


@_inline
def _node(nodes, p):
    """``(i0, t)`` of one (finite) parameter (``Marginal2D._slices``): the last node
    below ``p`` (``searchsorted`` left, i.e. the count of nodes below ``p``, minus 1,
    clipped) and ``clip((p - p0) / (p1 - p0), 0, 1)``."""
    n = len(nodes)
    if n == 1:
        return 0, 0.0
    below = 0
    for node in nodes:
        below += node < p
    i0 = min(max(below - 1, 0), n - 2)
    t = min(max((p - nodes[i0]) / (nodes[i0 + 1] - nodes[i0]), 0.0), 1.0)
    return i0, t


@_jit
def _cell(u, n):
    """``Marginal2D._cell``: patch index and local coordinate of ``u`` (NaN as 0, clamped)."""
    if u != u:
        u = 0.0
    s = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(s), n - 2)
    return i, s - i


@_inline
def _param_corners(phi, theta, nodes, corners, o):
    """Slices ``s[o:o + 4]`` and weights ``w[o:o + 4]`` (``corners = (s, w)``) of the parameter
    corners of ``Marginal2D._slices`` from the nodes and weights ``phi = (p0, tp)``, ``theta =
    (q0, tq)`` of ``phi_v``, ``theta_v`` (:func:`_node`), ``nodes = (n_theta, one_phi)``: the
    number of theta nodes and whether the file has one ``phi_i`` node; the corners of nonzero
    weight first: 4, or 2 for one ``phi_i`` node (skipping the zero terms of the reference's
    sum is exact)."""
    s, w = corners
    p0, tp = phi
    q0, tq = theta
    n_theta, one_phi = nodes
    if one_phi:
        s[o], s[o + 1], s[o + 2], s[o + 3] = q0, q0 + 1, q0, q0 + 1
        w[o], w[o + 1], w[o + 2], w[o + 3] = 1.0 - tq, tq, 0.0, 0.0
    else:
        s[o], s[o + 1] = p0 * n_theta + q0, (p0 + 1) * n_theta + q0
        s[o + 2], s[o + 3] = p0 * n_theta + q0 + 1, (p0 + 1) * n_theta + q0 + 1
        w[o], w[o + 1] = (1.0 - tp) * (1.0 - tq), tp * (1.0 - tq)
        w[o + 2], w[o + 3] = (1.0 - tp) * tq, tp * tq


@_inline
def _invert(t, corners, sel, x, y):
    """``Marginal2D.invert`` (u1, u2) at ``(x, y)``: the conditional and marginal CDFs of
    the bilinear patch, of the tables ``t`` (:class:`~microfacet.measured.rgl.RGLTables`):
    ``vc[s, j, i] = (value, conditional CDF)``, ``rows[s, j]`` the row integrals (the CDF's
    last column), ``marg[s, j]`` the marginal CDF; each lookup is the blend over the parameter
    corners ``s[o:o + nc], w[o:o + nc]`` (``corners = (s, w)``, ``sel = (o, nc)``;
    ``Marginal2D._lookup``), summed in the same order."""
    vc, rows, marg = t.vc, t.rows, t.marg
    s, w = corners
    o, nc = sel
    H, W = vc.shape[1], vc.shape[2]
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    d00 = d01 = d10 = d11 = q0 = q1 = r0 = r1 = m = m_end = 0.0
    for c in range(o, o + nc):
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
    return u1, (u2 if t.normalized else u2 / m_end)


@_inline
def _rgb_channel(rgb, corners, sel, cell, ch):
    """Channel ``ch`` of ``Marginal2D.eval`` of the RGB table ``rgb[s, j, i, channel]``
    in cell ``cell = (j, i, fx, fy)`` (local coordinates ``fx``, ``fy``), blended over the
    parameter corners ``corners``, ``sel`` (:func:`_invert`)."""
    s, w = corners
    o, nc = sel
    j, i, fx, fy = cell
    v00 = v01 = v10 = v11 = 0.0
    for c in range(o, o + nc):
        sc, wc = s[c], w[c]
        v00 += wc * rgb[sc, j, i, ch]
        v10 += wc * rgb[sc, j, i + 1, ch]
        v01 += wc * rgb[sc, j + 1, i, ch]
        v11 += wc * rgb[sc, j + 1, i + 1, ch]
    return _lerp(_lerp(v00, v10, fx), _lerp(v01, v11, fx), fy)


@_inline
def _rgb_eval(rgb, corners, sel, x, y):
    """``Marginal2D.eval`` of the RGB table at ``(x, y)`` (corners as :func:`_invert`)."""
    i, fx = _cell(x, rgb.shape[2])
    j, fy = _cell(y, rgb.shape[1])
    cell = (j, i, fx, fy)
    return (_rgb_channel(rgb, corners, sel, cell, 0), _rgb_channel(rgb, corners, sel, cell, 1),
            _rgb_channel(rgb, corners, sel, cell, 2))


@_inline
def _bilinear(table, x, y):
    """``Marginal2D.eval`` of a table without parameters or channels, ``(H, W)``."""
    H, W = table.shape
    i, fx = _cell(x, W)
    j, fy = _cell(y, H)
    return _lerp(_lerp(table[j, i], table[j, i + 1], fx), _lerp(table[j + 1, i], table[j + 1, i + 1], fx), fy)


@_inline
def _rgl_coordinates(wi, wo, j, t):
    """``(u_m, theta_v, phi_v)`` of ``RGLBRDF._eval_cos_numpy`` for the pair at element ``j`` of the
    flat ``wi``, ``wo``: the directions mirrored into the stored azimuths (``RGLBRDF._mirror``,
    ``t.reduction``), the unit coordinates ``u_m`` of the half vector (relative to ``phi_v`` if
    ``t.isotropic``) and the view's angles (``t``: :class:`~microfacet.measured.rgl.RGLTables`)."""
    ix, iy, iz, ox, oy, oz = wi[j], wi[j + 1], wi[j + 2], wo[j], wo[j + 1], wo[j + 2]
    isotropic, reduction = t.isotropic, t.reduction
    if reduction >= 2:
        sy = oy
        sx = ox if reduction == 4 else sy
        fx = 1.0 if math.copysign(1.0, sx) < 0.0 else -1.0
        fy = 1.0 if math.copysign(1.0, sy) < 0.0 else -1.0
        ix, iy, ox, oy = ix * fx, iy * fy, ox * fx, oy * fy
    mx, my, mz = ix + ox, iy + oy, iz + oz
    norm = max(math.sqrt(mx * mx + my * my + mz * mz), 1e-300)
    mx, my, mz = mx / norm, my / norm, mz / norm
    theta_v, phi_v = _elevation(ox, oy, oz), _atan2(oy, ox)
    theta_m, phi_m = _elevation(mx, my, mz), _atan2(my, mx)
    um_y = _phi2u(phi_m - phi_v if isotropic else phi_m)
    return _theta2u(theta_m), um_y - math.floor(um_y), theta_v, phi_v


@_jit
def _rgl_block(wi, wo, out, t):
    """``RGLBRDF.eval_cos`` (Dupuy & Jakob 2018: ``rgb(s) D(u_m) / (4 sigma(u_v))`` at the
    VNDF-warped half vector ``s``) of the flat pairs ``wi``, ``wo`` (one block) into the
    flat ``out``, for the tables ``t`` (:class:`~microfacet.measured.rgl.RGLTables`), in passes over the block through 1-D scratch rows: coordinates and
    parameter nodes (vectorized), parameter corners, VNDF inversion, RGB lookup (so that
    the table lookups of different pairs overlap); 0 below either horizon."""
    phi_nodes, theta_nodes = t.phi_nodes, t.theta_nodes
    n = len(out) // 3
    scratch = np.empty((8, n))
    um_x, um_y, theta_v, phi_v, t_theta, t_phi, s1, s2 = (scratch[0], scratch[1], scratch[2], scratch[3],
                                                          scratch[4], scratch[5], scratch[6], scratch[7])
    nodes, cs, cw = np.empty(2 * n, np.int64), np.empty(4 * n, np.int64), np.empty(4 * n)
    for k in range(n):
        j = 3 * k
        um_x[k], um_y[k], theta_v[k], phi_v[k] = _rgl_coordinates(wi, wo, j, t)
    for k in range(n):
        nodes[k], t_theta[k] = _node(theta_nodes, theta_v[k])
    for k in range(n):
        nodes[n + k], t_phi[k] = _node(phi_nodes, phi_v[k])
    one_phi, n_theta = len(phi_nodes) == 1, len(theta_nodes)
    corners = (cs, cw)
    for k in range(n):
        _param_corners((nodes[n + k], t_phi[k]), (nodes[k], t_theta[k]), (n_theta, one_phi), corners, 4 * k)
    nc = 2 if one_phi else 4
    for k in range(n):
        s1[k], s2[k] = _invert(t, corners, (4 * k, nc), um_x[k], um_y[k])
    for k in range(n):
        j = 3 * k
        if not (wi[j + 2] > 0.0 and wo[j + 2] > 0.0):
            out[j] = out[j + 1] = out[j + 2] = 0.0
            continue
        r, g, b = _rgb_eval(t.rgb, corners, (4 * k, nc), s1[k], s2[k])
        if t.clip_negative:
            r, g, b = max(r, 0.0), max(g, 0.0), max(b, 0.0)
        if t.jacobian:
            scale = _bilinear(t.ndf, um_x[k], um_y[k]) / (4.0 * _bilinear(t.sigma, _theta2u(theta_v[k]),
                                                                           _phi2u(phi_v[k])))
            r, g, b = r * scale, g * scale, b * scale
        out[j], out[j + 1], out[j + 2] = r, g, b


@_pjit
def eval_rgl(wi, wo, cosine, out, tables):
    """``f_r cos theta_i`` (or ``f_r``) of an RGL BRDF (``tables``: its
    :class:`~microfacet.measured.rgl.RGLTables`) for each pair."""
    n = len(out)
    wi, wo, out = wi.reshape(-1), wo.reshape(-1), out.reshape(-1)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        a, o = wi[3 * k0:3 * k1], out[3 * k0:3 * k1]
        _rgl_block(a, wo[3 * k0:3 * k1], o, tables)
        if not cosine:
            for j in range(len(o)):
                z = a[j - j % 3 + 2]
                o[j] = o[j] / z if z > 0.0 else 0.0


@_pjit
def sample_rgl(u, wo, wi, weight, pdf, tables):
    """Cosine-weighted ``wi``, ``weight = eval_cos / pdf`` and ``pdf`` (``MeasuredBRDF.sample``)."""
    n = len(wo)
    u, wo, wi, weight = u.reshape(-1), wo.reshape(-1), wi.reshape(-1), weight.reshape(-1)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        a, b, f, p = wi[3 * k0:3 * k1], wo[3 * k0:3 * k1], weight[3 * k0:3 * k1], pdf[k0:k1]
        _warp_block(u[2 * k0:2 * k1], b, a, p)
        _rgl_block(a, b, f, tables)
        _divide_by_pdf(f, p)


# --------------------------------------------- MERL and UTIA: corners of one table, blended
# Each pair gives the nodes and weights of 3 (MERL) or 4 (UTIA) axes: the 8 or 16 corners
# of its cell in a table (rows, channels).
MERL, UTIA = 0, 1
_MERL_STRIDES = (_NP * _ND, _NP, 1)                     # (theta_h, theta_d, phi_d)


@_inline
def _clamped(u, n):
    """Nodes and upper weight on ``0..n-1``, clamped (``merl._axis_clamped``, ``utia._theta_axis``)."""
    u = min(max(u, 0.0), n - 1.0)
    i0 = min(int(math.floor(u)), n - 2)
    return i0, i0 + 1, u - i0


@_inline
def _periodic(u, n):
    """Nodes and upper weight on a periodic axis of ``n`` nodes, ``u`` in ``[0, n]`` (``n``
    is node 0 with weight 0, as ``np.mod(u, n) = 0``)."""
    fl = math.floor(u)
    i0 = int(fl) % n
    return i0, (i0 + 1) % n, u - fl


@_inline
def _merl_axes(ix, iy, iz, ox, oy, oz):
    """The axes of the trilinear cell of ``MERLBRDF._corners``: Rusinkiewicz coordinates
    (``merl.hd_coordinates``), then the nodes and weights of ``(u_h, u_d, u_phi)``."""
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    n2 = hx * hx + hy * hy + hz * hz
    inv = 1.0 / math.sqrt(n2) if n2 > 0.0 else 0.0
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    r = math.sqrt(hx * hx + hy * hy)                 # hypot of unit vectors (to an ulp)
    cos_ph, sin_ph = (1.0, 0.0) if r == 0.0 else (hx / r, hy / r)
    a = cos_ph * ix + sin_ph * iy
    b = cos_ph * iy - sin_ph * ix
    dx, dz = hz * a - r * iz, r * a + hz * iz
    theta_h = _atan2(r, hz)
    theta_d = _atan2(math.sqrt(dx * dx + b * b), dz)
    phi_d = _atan2(b, dx)
    phi_d = phi_d + math.pi if phi_d < 0.0 else phi_d   # np.mod(phi_d, pi), up to pi itself
    return (_clamped(_NH * math.sqrt(max(theta_h, 0.0) / _HALF_PI), _NH), _clamped(_ND * (theta_d / _HALF_PI), _ND),
            _periodic(_NP * (phi_d / math.pi), _NP))


@_inline
def _phi_unit(phi):
    """``np.mod(phi / PHI_STEP, 48)`` for ``phi`` in ``[-pi, pi]`` (up to 48 itself)."""
    u = phi / _PHI_STEP
    return u + _NF if u < 0.0 else u


@_inline
def _utia_axes(ix, iy, iz, ox, oy, oz):
    """The axes of the quadrilinear cell of ``UTIABRDF.eval``: ``(theta_i, phi_i, theta_v, phi_v)``."""
    return (_clamped(_atan2(math.sqrt(ix * ix + iy * iy), iz) / _THETA_STEP, _NT),
            _periodic(_phi_unit(_atan2(iy, ix)), _NF),
            _clamped(_atan2(math.sqrt(ox * ox + oy * oy), oz) / _THETA_STEP, _NT),
            _periodic(_phi_unit(_atan2(oy, ox)), _NF))


@_inline
def _table_axes(kind, wi, wo, lo, hi, t):
    """Nodes ``lo[a, k]``, ``hi[a, k]`` and upper weights ``t[a, k]`` of the axes ``a`` of
    each pair ``k`` of the flat block ``wi``, ``wo`` (vectorized)."""
    for k in range(len(wi) // 3):
        j = 3 * k
        if kind == MERL:
            (lo[0, k], hi[0, k], t[0, k]), (lo[1, k], hi[1, k], t[1, k]), (lo[2, k], hi[2, k], t[2, k]) = \
                _merl_axes(wi[j], wi[j + 1], wi[j + 2], wo[j], wo[j + 1], wo[j + 2])
        else:
            ((lo[0, k], hi[0, k], t[0, k]), (lo[1, k], hi[1, k], t[1, k]), (lo[2, k], hi[2, k], t[2, k]),
             (lo[3, k], hi[3, k], t[3, k])) = _utia_axes(wi[j], wi[j + 1], wi[j + 2], wo[j], wo[j + 1], wo[j + 2])


@_inline
def _cell_corners(n_axes, strides, lo, hi, t, rows, weights):
    """Rows ``rows[m k + c] = sum_a stride_a node_a`` and weights ``weights[m k + c] =
    prod_a (t_a or 1 - t_a)`` of the ``m = 2^n_axes`` corners ``c`` of the cell of each
    pair ``k`` (axis ``a`` is bit ``a`` of ``c``, as in ``UTIABRDF.eval``)."""
    m = 1 << n_axes
    for k in range(lo.shape[1]):
        for c in range(m):
            row, w = 0, 1.0
            for a in range(n_axes):
                if (c >> a) & 1:
                    row, w = row + strides[a] * hi[a, k], w * t[a, k]
                else:
                    row, w = row + strides[a] * lo[a, k], w * (1.0 - t[a, k])
            rows[m * k + c], weights[m * k + c] = row, w


@_inline
def _blend(kind, table, rows, weights, o):
    """``sum_c w_c table[row_c]``, RGB, over the corners ``rows[o:o + m], weights[o:o + m]``
    (``m`` = 8 for MERL, 16 for UTIA); MERL divides by the weight on measured samples (its
    table's 4th column, 0 on unmeasured ones) and is 0 where there is none."""
    if kind != MERL:
        f0 = f1 = f2 = 0.0
        for c in range(o, o + 16):
            row, w = rows[c], weights[c]
            f0 += w * table[row, 0]
            f1 += w * table[row, 1]
            f2 += w * table[row, 2]
        return f0, f1, f2
    f0 = f1 = f2 = cover = 0.0
    for c in range(o, o + 8):
        row, w = rows[c], weights[c]
        f0 += w * table[row, 0]
        f1 += w * table[row, 1]
        f2 += w * table[row, 2]
        cover += w * table[row, 3]
    return (f0 / cover, f1 / cover, f2 / cover) if cover > 0.0 else (0.0, 0.0, 0.0)


@_jit
def _table_block(kind, table, wi, wo, cosine, out):
    """``f_r`` (or ``f_r cos theta_i``) of a MERL or UTIA BRDF (``kind``) of the flat pairs
    ``wi``, ``wo`` of one block into the flat ``out``: the axes of every pair, the corners
    of their cells, then the table lookups; 0 below either horizon."""
    n = len(out) // 3
    lo, hi, t = np.empty((4, n), np.int64), np.empty((4, n), np.int64), np.empty((4, n))
    rows, weights = np.empty(16 * n, np.int64), np.empty(16 * n)
    _table_axes(kind, wi, wo, lo, hi, t)
    if kind == MERL:
        _cell_corners(3, _MERL_STRIDES, lo, hi, t, rows, weights)
    else:
        _cell_corners(4, _UTIA_STRIDES, lo, hi, t, rows, weights)
    m = 8 if kind == MERL else 16
    for k in range(n):
        j = 3 * k
        if not (wi[j + 2] > 0.0 and wo[j + 2] > 0.0):
            out[j] = out[j + 1] = out[j + 2] = 0.0
            continue
        r, g, b = _blend(kind, table, rows, weights, m * k)
        z = wi[j + 2] if cosine else 1.0
        out[j], out[j + 1], out[j + 2] = r * z, g * z, b * z


@_pjit
def eval_table(wi, wo, cosine, out, tables):
    """``f_r`` (or ``f_r cos theta_i``) of a MERL or UTIA BRDF (``tables = (kind, table)``) for each pair."""
    kind, table = tables
    n = len(out)
    wi, wo, out = wi.reshape(-1), wo.reshape(-1), out.reshape(-1)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        _table_block(kind, table, wi[3 * k0:3 * k1], wo[3 * k0:3 * k1], cosine, out[3 * k0:3 * k1])


@_pjit
def sample_table(u, wo, wi, weight, pdf, tables):
    """Cosine-weighted ``wi``, ``weight = f_r cos theta_i / pdf`` and ``pdf`` of a MERL or UTIA BRDF
    (``tables = (kind, table)``)."""
    kind, table = tables
    n = len(wo)
    u, wo, wi, weight = u.reshape(-1), wo.reshape(-1), wi.reshape(-1), weight.reshape(-1)
    for block in numba.prange((n + BLOCK - 1) // BLOCK):
        k0, k1 = block * BLOCK, min(block * BLOCK + BLOCK, n)
        a, f, p = wi[3 * k0:3 * k1], weight[3 * k0:3 * k1], pdf[k0:k1]
        _warp_block(u[2 * k0:2 * k1], wo[3 * k0:3 * k1], a, p)
        _table_block(kind, table, a, wo[3 * k0:3 * k1], True, f)
        _divide_by_pdf(f, p)
