"""MIP pyramids of moment maps by exact averaging, and filtered lookups.

Sizes and weights (any size, not only powers of two): level ``k + 1`` has
``max(1, floor(n_k / 2))`` texels along an axis of ``n_k`` texels, and each of its texels
is the box average of level ``k`` over the same uv interval ``[o / n_{k+1}, (o + 1) /
n_{k+1})``. When ``n_k`` is odd the interval covers ``n_k / n_{k+1}`` (a non-integer
number of) texels, and the texels cut by its ends get fractional weights equal to the
covered fraction (the polyphase box filter for non-power-of-two MIP maps). Every level
therefore tiles the unit uv square uniformly, each level-``k`` texel contributes exactly
its area to the next level, and the mean of every level equals the mean of level 0: the
single texel of the top level is the global mean (up to floating-point rounding). For
power-of-two sizes this is the usual 2x2 average and each texel is the exact mean of
the level-0 texels it covers. Moments are linear in the slopes, so this averaging is the
exact LEAN filtering of Eq. 3.10-3.14.
"""
from __future__ import annotations

import numba
import numpy as np

from ..kernels import launch_ranges

__all__ = ["mip_pyramid", "mip_sizes", "downsample_weights", "lookup", "MAX_ANISOTROPY"]

#: Most samples along the major axis of an anisotropic footprint (as GPUs' 16x).
MAX_ANISOTROPY = 16


def mip_sizes(height: int, width: int) -> list[tuple[int, int]]:
    """``[(H_0, W_0), (H_1, W_1), ...]`` down to ``(1, 1)``: ``n_{k+1} = max(1, n_k // 2)``.

    Parameters
    ----------
    height, width : int
        Size of level 0 in texels.

    Returns
    -------
    list of (int, int)
        ``(H_k, W_k)`` of each level, level 0 first.

    Examples
    --------
    >>> mip_sizes(16, 4)
    [(16, 4), (8, 2), (4, 1), (2, 1), (1, 1)]
    """
    sizes = [(int(height), int(width))]
    while sizes[-1] != (1, 1):
        h, w = sizes[-1]
        sizes.append((max(1, h // 2), max(1, w // 2)))
    return sizes


def downsample_weights(n_in: int, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """Box-filter taps from ``n_in`` to ``n_out`` texels over the same interval.

    Returns ``(index, weight)``, both ``(n_out, T)``: output texel ``o`` is
    ``sum_t weight[o, t] * input[index[o, t]]``, with weights equal to the overlap of input
    texel ``[i, i + 1)`` with ``[o r, (o + 1) r)``, ``r = n_in / n_out``, divided by ``r``
    (so each row sums to 1 and each input texel's weights sum to ``1 / r``). Computed in
    exact integer arithmetic (units of ``1 / n_out`` input texels).

    Parameters
    ----------
    n_in : int
        Input texels along the axis.
    n_out : int
        Output texels along the axis.

    Returns
    -------
    index : numpy.ndarray of int, shape (n_out, T)
        Input texel of each tap.
    weight : numpy.ndarray of float, shape (n_out, T)
        Weight of each tap; each row sums to 1.

    Examples
    --------
    >>> downsample_weights(4, 2)
    (array([[0, 1, 2],
           [2, 3, 3]]), array([[0.5, 0.5, 0. ],
           [0.5, 0.5, 0. ]]))
    """
    if n_out < 1 or n_in < n_out:
        raise ValueError(f"cannot downsample {n_in} texels to {n_out}")
    taps = -(-n_in // n_out) + 1
    index = np.zeros((n_out, taps), dtype=np.int64)
    weight = np.zeros((n_out, taps), dtype=np.float64)
    for o in range(n_out):
        lo, hi = o * n_in, (o + 1) * n_in            # cell in units of 1/n_out input texels
        i0 = lo // n_out
        for t in range(taps):
            i = min(i0 + t, n_in - 1)
            a, b = max(lo, i * n_out), min(hi, (i + 1) * n_out)
            index[o, t] = i
            weight[o, t] = max(b - a, 0) / n_in if i0 + t < n_in else 0.0
    return index, weight


@numba.njit(cache=True, nogil=True)
def _downsample(start, stop, src, iy, wy, ix, wx, out):  # pragma: no cover - compiled
    """Box filter of channels-first ``src (C, H, W)`` into rows ``start:stop`` of ``out (C,
    H_o, W_o)`` seen as ``C H_o`` rows (plane by plane), by the taps of
    :func:`downsample_weights` (zero weights skipped), summed in float64."""
    nc, ho, wo = out.shape
    ty, tx = iy.shape[1], ix.shape[1]
    for q in range(start, stop):
        c, oy = q // ho, q % ho
        for ox in range(wo):
            acc = 0.0
            for a in range(ty):
                w_a = wy[oy, a]
                if w_a == 0.0:
                    continue
                row = iy[oy, a]
                for b in range(tx):
                    w = w_a * wx[ox, b]
                    if w != 0.0:
                        acc += w * src[c, row, ix[ox, b]]
            out[c, oy, ox] = acc


@numba.njit(cache=True, nogil=True)
def _downsample_2x2(start, stop, src, out):  # pragma: no cover - compiled
    """2x2 average of channels-first ``src (C, 2 H_o, 2 W_o)`` into rows ``start:stop`` of
    ``out (C, H_o, W_o)`` seen as ``C H_o`` rows, summed in float64, through 1-D row views
    (the loop over columns vectorizes)."""
    nc, ho, wo = out.shape
    for q in range(start, stop):
        c, oy = q // ho, q % ho
        top, bottom, o = src[c, 2 * oy], src[c, 2 * oy + 1], out[c, oy]
        for ox in range(wo):
            s = (np.float64(top[2 * ox]) + np.float64(top[2 * ox + 1])
                 + np.float64(bottom[2 * ox]) + np.float64(bottom[2 * ox + 1]))
            o[ox] = 0.25 * s


def _channels_first(a: np.ndarray) -> bool:
    """Whether ``(H, W, C)`` ``a`` is a view of C-contiguous ``(C, H, W)`` storage."""
    return np.moveaxis(a, -1, 0).flags.c_contiguous


def downsample(level: np.ndarray, size: tuple[int, int] | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """Next MIP level of an ``(H, W, C)`` map (see the module docstring for the weights),
    in the layout of ``level``: channels last (C-contiguous), or channels first (a view of
    C-contiguous ``(C, H, W)`` storage, :func:`microfacet.leadr.bake`'s), or into ``out``."""
    a = np.asarray(level)
    if a.ndim != 3:
        raise ValueError(f"a MIP level must be (H, W, C), got shape {a.shape}")
    planar = _channels_first(a)
    if not (planar or a.flags.c_contiguous or out is not None):
        a = np.ascontiguousarray(a)
    h, w, nc = a.shape
    ho, wo = size if size is not None else (max(1, h // 2), max(1, w // 2))
    if out is None:
        out = np.empty((nc, ho, wo), a.dtype).transpose(1, 2, 0) if planar else np.empty((ho, wo, nc), a.dtype)
    elif out.shape != (ho, wo, nc):
        raise ValueError(f"out must have shape {(ho, wo, nc)}, got {out.shape}")
    src, dst = np.moveaxis(a, -1, 0), np.moveaxis(out, -1, 0)        # (C, H, W) views
    if (h, w) == (2 * ho, 2 * wo):                      # even sizes: the plain 2x2 average
        launch_ranges(_downsample_2x2, nc * ho, src, dst, cost=4 * wo)
        return out
    iy, wy = downsample_weights(h, ho)
    ix, wx = downsample_weights(w, wo)
    launch_ranges(_downsample, nc * ho, src, iy, wy, ix, wx, dst, cost=iy.shape[1] * ix.shape[1] * wo)
    return out


def mip_pyramid(moments, out: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """MIP pyramid ``[level 0, level 1, ..., 1 x 1]`` of an ``(H, W, C)`` map (C = 5 for
    LEAN moments) by exact averaging; level 0 is the input (as a contiguous array, or the
    input itself if it is a channels-first view, see :func:`downsample`, whose layout the
    levels keep). The dtype (float32 or float64) is kept; sums are accumulated in float64.
    With ``out`` (levels of the pyramid's sizes, e.g. :func:`microfacet.leadr.pyramid_file`'s,
    ``out[0]`` holding the moments) the levels above 0 are written into it, and it is returned.

    Parameters
    ----------
    moments : array-like, shape (H, W, C)
        The level-0 map (float32 or float64).
    out : list of numpy.ndarray, optional
        Preallocated levels of the pyramid's sizes (:func:`mip_sizes`), ``out[0]``
        holding ``moments``; default: new arrays.

    Returns
    -------
    list of numpy.ndarray
        The levels ``(H_k, W_k, C)``, level 0 first, down to ``1 x 1`` (``out`` when given).

    Examples
    --------
    >>> import numpy as np
    >>> levels = mip_pyramid(np.arange(16.0).reshape(4, 4, 1))
    >>> [level.shape for level in levels], float(levels[-1][0, 0, 0])     # the mean at the top
    ([(4, 4, 1), (2, 2, 1), (1, 1, 1)], 7.5)
    """
    if out is not None:
        for k in range(1, len(out)):
            downsample(out[k - 1], out[k].shape[:2], out=out[k])
        return out
    a = np.asarray(moments)
    if a.ndim != 3 or 0 in a.shape:
        raise ValueError(f"moments must be a non-empty (H, W, C) array, got shape {a.shape}")
    if a.dtype not in (np.float32, np.float64):
        a = a.astype(np.float64)
    levels = [a if _channels_first(a) else np.ascontiguousarray(a)]
    for size in mip_sizes(*a.shape[:2])[1:]:
        levels.append(downsample(levels[-1], size))
    return levels


# --------------------------------------------------------------------------- lookup
def _bilinear(level: np.ndarray, u, v, wrap: bool) -> np.ndarray:
    """Bilinear sample of ``level (H, W, C)`` at uv (texel centres at ``(i + 1/2) / W``;
    v = 0 is the top row, as rows of the map)."""
    h, w = level.shape[:2]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    if wrap:
        xs, ys = (x0 % w, (x0 + 1) % w), (y0 % h, (y0 + 1) % h)
    else:
        xs = (np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1))
        ys = (np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1))
    px = [[level[y, x].astype(np.float64) for x in xs] for y in ys]   # gather, then widen
    top = px[0][0] * (1 - fx) + px[0][1] * fx
    bottom = px[1][0] * (1 - fx) + px[1][1] * fx
    return top * (1 - fy) + bottom * fy


def _trilinear(pyramid, u, v, lod, wrap: bool) -> np.ndarray:
    """Linear blend of bilinear samples of levels ``floor(lod)`` and ``floor(lod) + 1``."""
    top = len(pyramid) - 1
    lod = np.clip(lod, 0.0, top)
    k0 = np.minimum(np.floor(lod).astype(np.int64), top)
    t = (lod - k0)[..., None]
    out = np.zeros(u.shape + (pyramid[0].shape[2],), dtype=np.float64)
    for k in np.unique(k0):
        m = k0 == k
        s = _bilinear(pyramid[k], u[m], v[m], wrap)
        if k < top:
            s = s * (1 - t[m]) + _bilinear(pyramid[k + 1], u[m], v[m], wrap) * t[m]
        out[m] = s
    return out


def _footprint_axes(footprint, shape) -> tuple[np.ndarray, np.ndarray]:
    """Two footprint axes ``(..., 2)`` in uv units from the accepted footprint forms."""
    f = np.asarray(footprint, dtype=np.float64)
    widths = f.shape == shape or f.ndim == 0 or (f.shape[-1:] == (2,) and f.shape[:-1] in (shape, ()))
    if widths and np.any(f < 0):                              # axes (2 x 2) may point anywhere
        raise ValueError(f"footprint widths must be >= 0, got {float(np.min(f))!r}")
    if f.shape == shape or f.ndim == 0:                       # isotropic width
        f = np.broadcast_to(f, shape)
        z = np.zeros(shape)
        return np.stack([f, z], -1), np.stack([z, f], -1)
    if f.shape[-1:] == (2,) and f.shape[:-1] in (shape, ()):  # axis-aligned widths (du, dv)
        f = np.broadcast_to(f, shape + (2,))
        z = np.zeros(shape)
        return np.stack([f[..., 0], z], -1), np.stack([z, f[..., 1]], -1)
    if f.shape[-2:] == (2, 2) and f.shape[:-2] in (shape, ()):
        f = np.broadcast_to(f, shape + (2, 2))
        return f[..., 0, :], f[..., 1, :]
    raise ValueError(f"footprint must be a width, (..., 2) widths or (..., 2, 2) axes "
                     f"matching uv's leading shape {shape}, got shape {f.shape}")


def lookup(pyramid, uv, footprint=0.0, *, wrap: bool = True,
           max_anisotropy: int = MAX_ANISOTROPY) -> np.ndarray:
    """Filtered moments ``(..., C)`` (float64) of a MIP pyramid at texture coordinates ``uv``.

    Parameters
    ----------
    pyramid : list of (H_k, W_k, C) arrays
        From :func:`mip_pyramid` or :func:`microfacet.leadr.bake`.
    uv : (..., 2)
        Texture coordinates; the map covers the unit square, ``u`` along columns and
        ``v`` along rows (``v = 0`` is row 0, the top row).
    footprint : float, (...,), (..., 2) or (..., 2, 2)
        The pixel footprint in uv units: a width (square footprint), axis-aligned widths
        ``(du, dv)``, or two axes ``[[du/dx, dv/dx], [du/dy, dv/dy]]`` (the uv derivatives
        across one pixel, spanning the parallelogram ``uv + s a + t b``, ``|s|, |t| <= 1/2``).
        0 gives a bilinear lookup of level 0.
    wrap : bool
        Repeat the texture (default) or clamp to its border.
    max_anisotropy : int
        Most trilinear probes along the major axis.

    Returns
    -------
    numpy.ndarray, shape (..., C)
        The filtered moments (float64), one per texture coordinate.

    Notes
    -----
    Trilinear filtering with GPU-style anisotropy: the axes are measured in level-0
    texels, ``N = min(ceil(major / minor), max_anisotropy)`` probes are spread evenly over
    the major axis, each a trilinear lookup at ``lod = log2(major / N)`` (so a probe's
    texel is about the size of the footprint's minor axis), and the probes are averaged.
    Moments are linear, so every blend and average is a valid LEAN filter.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import bake, gaussian_heightfield
    >>> pyramid = bake(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> lookup(pyramid, np.array([0.5, 0.5]), footprint=1.0).round(4)     # the whole map: the top level
    array([ 0.    ,  0.    ,  0.1136,  0.0649, -0.0005])
    >>> np.allclose(lookup(pyramid, np.array([0.5, 0.5]), 1.0), pyramid[-1][0, 0], atol=1e-6)
    True
    >>> MAX_ANISOTROPY
    16
    """
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape[-1:] != (2,):
        raise ValueError(f"uv must have a last axis of size 2, got shape {uv.shape}")
    if not pyramid:
        raise ValueError("empty pyramid")
    shape = uv.shape[:-1]
    a, b = _footprint_axes(footprint, shape)
    for name, x in (("uv", uv), ("footprint", a), ("footprint", b)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} must be finite, got NaN or infinite values")
    h0, w0 = pyramid[0].shape[:2]
    texels = np.array([w0, h0], dtype=np.float64)
    la, lb = np.linalg.norm(a * texels, axis=-1), np.linalg.norm(b * texels, axis=-1)
    major_is_a = la >= lb
    major = np.where(major_is_a, la, lb)
    minor = np.where(major_is_a, lb, la)
    axis = np.where(major_is_a[..., None], a, b)
    n = np.clip(np.ceil(major / np.maximum(minor, 1e-12)), 1, max(1, int(max_anisotropy)))
    n = np.where(major > 1.0, n, 1).astype(np.int64)          # below a texel: one probe
    lod = np.log2(np.maximum(major / n, 1.0))
    u, v = uv[..., 0].ravel(), uv[..., 1].ravel()
    n, lod, axis = n.ravel(), lod.ravel(), axis.reshape(-1, 2)
    out = np.zeros((u.size, pyramid[0].shape[2]))
    for j in range(int(n.max(initial=1))):
        m = j < n
        s = ((j + 0.5) / n[m] - 0.5)[:, None]
        p = np.stack([u[m], v[m]], -1) + s * axis[m]
        out[m] += _trilinear(pyramid, p[:, 0], p[:, 1], lod[m], wrap)
    return (out / n[:, None]).reshape(shape + (pyramid[0].shape[2],))
