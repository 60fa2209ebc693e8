"""Height maps, normal maps and LEAN/LEADR moment maps (thesis Sec. 3.4, Listings 3.6-3.7).

Conventions (Listing 3.6): a ``W x H`` map covers the unit uv square; ``i`` is the column
and ``j`` the row, row 0 at the top, and ``y`` points to the top row. Slopes of the unit
uv square are central differences in texel units scaled by the resolution,

    x~ = W scale (xi(i+1, j) - xi(i-1, j)) / 2,    y~ = H scale (xi(i, j-1) - xi(i, j+1)) / 2,

with the map wrapped (``border="wrap"``, tileable maps) or clamped to its edge
(``"clamp"``, where the outer texels see a one-sided half difference). A normal is
``(-x~, -y~, 1) / sqrt(1 + x~^2 + y~^2)``. Normal maps are written as ``(n + 1) / 2`` per
channel in 8 or 16 bits (rounded), or ``n`` itself as floats (:func:`encode_normal_map`), and
read by the library's one decoder, :mod:`microfacet.io.normalmap` (encodings by content or
given, ``z`` stored or rebuilt, per-texel repair of unusable texels).

Examples
--------
>>> BORDERS
('wrap', 'clamp')
"""
from __future__ import annotations

import numba
import numpy as np

from ..distributions import Beckmann
from ..io.normalmap import normals_to_slopes, read_slopes
from ..kernels import launch_ranges
from .mip import mip_pyramid, mip_sizes
from .moments import convolve, to_moments

__all__ = ["height_to_slopes", "slopes_to_normals", "normals_to_slopes", "encode_normal_map",
           "decode_normal_map", "slopes_to_moments", "normal_map_to_moments", "base_moments",
           "bake", "bake_reference", "BORDERS"]

BORDERS = ("wrap", "clamp")
#: The error of a bake whose moments do not fit in float32.
OVERFLOW = "the slope moments overflow float32 (too large a scale or roughness)"


def _check_height(height) -> np.ndarray:
    h = np.asarray(height)
    if h.ndim != 2 or 0 in h.shape:
        raise ValueError(f"a height map must be a non-empty (H, W) array, got shape {h.shape}")
    if not np.issubdtype(h.dtype, np.number) or np.issubdtype(h.dtype, np.complexfloating):
        raise ValueError(f"a height map must be real, got dtype {h.dtype}")
    if h.dtype.kind == "f" and not np.all(np.isfinite(h)):
        raise ValueError("a height map must be finite (found NaN or inf)")
    return h


def _check_border(border: str) -> None:
    if border not in BORDERS:
        raise ValueError(f"border must be one of {BORDERS}, got {border!r}")


def height_to_slopes(height, scale: float = 1.0, border: str = "wrap") -> np.ndarray:
    """Slopes ``(H, W, 2)`` (float64) of a height map ``(H, W)`` in units of the unit uv
    square (module docstring; Sec. 3.4 central differences, Listing 3.6).

    Parameters
    ----------
    height : ndarray, (H, W)
        Heights in units of the map's width (times ``scale``).
    scale : float
        Height scale.
    border : {"wrap", "clamp"}
        Central differences across the edges (a tileable map) or one-sided at them.

    Returns
    -------
    ndarray, (H, W, 2) float64
        The slopes ``(x~, y~)``.

    Raises
    ------
    ValueError
        An unknown ``border``.

    References
    ----------
    Dupuy 2015, thesis, Sec. 3.4, Listing 3.6.

    Examples
    --------
    >>> import numpy as np
    >>> ramp = np.tile(np.arange(4.0) / 4, (4, 1))     # height rises along x (columns)
    >>> height_to_slopes(ramp, border="clamp")[1, 1]   # dh/du in uv units
    array([1., 0.])
    >>> height_to_slopes(ramp, border="mirror")
    Traceback (most recent call last):
        ...
    ValueError: border must be one of ('wrap', 'clamp'), got 'mirror'
    """
    xi = _check_height(height).astype(np.float64)
    _check_border(border)
    h, w = xi.shape
    mode = "wrap" if border == "wrap" else "edge"
    p = np.pad(xi, 1, mode=mode)
    sx = 0.5 * w * scale * (p[1:-1, 2:] - p[1:-1, :-2])
    sy = 0.5 * h * scale * (p[:-2, 1:-1] - p[2:, 1:-1])
    return np.stack([sx, sy], axis=-1)


def slopes_to_normals(slopes) -> np.ndarray:
    """Unit normals ``(..., 3)`` ``(-x~, -y~, 1) / sqrt(1 + x~^2 + y~^2)``.

    Parameters
    ----------
    slopes : array-like, shape (..., 2)
        Slopes ``(x~, y~)``.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        Unit normals.

    Examples
    --------
    >>> import numpy as np
    >>> slopes_to_normals(np.array([[0.0, 0.0], [0.75, 0.0]])).round(4)
    array([[-0. , -0. ,  1. ],
           [-0.6, -0. ,  0.8]])
    """
    s = np.asarray(slopes, dtype=np.float64)
    inv = 1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
    return np.stack([-s[..., 0] * inv, -s[..., 1] * inv, inv], axis=-1)


def encode_normal_map(slopes, dtype=np.uint8) -> np.ndarray:
    """Normal map ``(H, W, 3)`` of slopes: ``round((n + 1) / 2 * max)`` for ``uint8`` and
    ``uint16``, ``n`` itself for float dtypes.

    Parameters
    ----------
    slopes : array-like, shape (H, W, 2)
        Slopes ``(x~, y~)`` per texel.
    dtype : dtype, optional
        ``uint8`` (default), ``uint16`` or a float dtype.

    Returns
    -------
    numpy.ndarray, shape (H, W, 3)
        The normal map in ``dtype``.

    Examples
    --------
    >>> import numpy as np
    >>> encode_normal_map(np.zeros((1, 2, 2)))                  # flat: (128, 128, 255)
    array([[[128, 128, 255],
            [128, 128, 255]]], dtype=uint8)
    >>> encode_normal_map(np.zeros((1, 1, 2)), np.uint16)
    array([[[32768, 32768, 65535]]], dtype=uint16)
    """
    n = slopes_to_normals(slopes)
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return n.astype(dtype)
    if dtype not in (np.uint8, np.uint16):
        raise ValueError(f"normal maps are uint8, uint16 or float, got {dtype}")
    top = np.iinfo(dtype).max
    return np.rint((0.5 * n + 0.5) * top).astype(dtype)


def decode_normal_map(nmap, encoding: str = "auto", z: str = "auto") -> np.ndarray:
    """Slopes ``(H, W, 2)`` float64 of a normal map, an array ``(H, W, 2|3|4)`` (``uint8``,
    ``uint16`` or float) or a PNG/EXR file: the inverse of :func:`encode_normal_map`
    (Listing 3.7), through :func:`microfacet.io.normalmap.read_slopes` (``encoding``, ``z``,
    repairs and warnings as documented there).

    Parameters
    ----------
    nmap : ndarray or path
        The normal map, ``(H, W, 2|3|4)``, or a PNG/EXR file.
    encoding : {"auto", "biased", "signed", "offset"}
        How the components are stored (:data:`microfacet.io.normalmap.ENCODINGS`).
    z : {"auto", "stored", "reconstruct"}
        Use the stored ``n_z`` or rebuild it from ``n_x, n_y``.

    Returns
    -------
    ndarray, (H, W, 2) float64
        The slopes ``(x~, y~) = (-n_x / n_z, -n_y / n_z)``.

    References
    ----------
    Dupuy 2015, thesis, Listing 3.7.

    Examples
    --------
    >>> import numpy as np
    >>> slopes = np.array([[[0.5, -0.25], [0.0, 0.0]]])
    >>> decode_normal_map(encode_normal_map(slopes, np.uint16)).round(3)     # 16-bit round trip
    array([[[ 0.5 , -0.25],
            [-0.  , -0.  ]]])
    """
    return read_slopes(nmap, encoding, z)[0]


def slopes_to_moments(slopes, base=None) -> np.ndarray:
    """Level-0 moments ``(H, W, 5)`` (float64) of slope texels (Listing 3.7): each texel is a
    single facet ``(x~, y~, x~^2, y~^2, x~ y~)``, convolved with the base lobe's moments
    ``base (5,)`` when given (Listing 5.1).

    Parameters
    ----------
    slopes : array-like, shape (H, W, 2)
        Slopes ``(x~, y~)`` per texel.
    base : array-like, shape (5,), optional
        Moments of the base lobe (:func:`base_moments`); ``None``: none.

    Returns
    -------
    numpy.ndarray, shape (H, W, 5)
        The moments (float64).

    References
    ----------
    Dupuy 2015, thesis, Listing 3.7, Listing 5.1.

    Examples
    --------
    >>> import numpy as np
    >>> slopes_to_moments(np.array([[[0.5, -0.25]]]))[0, 0]        # a mirror facet: E3 = E1^2 ...
    array([ 0.5   , -0.25  ,  0.25  ,  0.0625, -0.125 ])
    >>> slopes_to_moments(np.array([[[0.5, -0.25]]]), base=base_moments(0.2))[0, 0].round(4)   # + alpha^2 / 2
    array([ 0.5   , -0.25  ,  0.27  ,  0.0825, -0.125 ])
    """
    s = np.asarray(slopes, dtype=np.float64)
    x, y = s[..., 0], s[..., 1]
    E = np.stack([x, y, x * x, y * y, x * y], axis=-1)
    return E if base is None else convolve(E, base)


def base_moments(roughness) -> np.ndarray | None:
    """Moments ``(5,)`` of a base roughness: ``None``, an isotropic ``alpha``, ``(alpha_x,
    alpha_y)``, a :class:`~microfacet.Beckmann` or a BRDF whose ``distribution`` is one.

    Parameters
    ----------
    roughness : None, float, (float, float), Beckmann or BRDF
        The base roughness.

    Returns
    -------
    numpy.ndarray, shape (5,), or None
        Its moments ``E1..E5``; ``None`` for ``None``.

    Examples
    --------
    >>> base_moments(None) is None
    True
    >>> base_moments(0.2)
    array([0.  , 0.  , 0.02, 0.02, 0.  ])
    >>> base_moments((0.2, 0.4)).round(4)
    array([0.  , 0.  , 0.02, 0.08, 0.  ])
    """
    if roughness is None:
        return None
    d = getattr(roughness, "distribution", roughness)
    if isinstance(d, Beckmann):
        E = np.stack(np.broadcast_arrays(*d.moments()), axis=-1)
        if E.shape != (5,):
            raise ValueError("the base roughness must be a single Beckmann lobe")
        return E
    if hasattr(d, "moments"):
        raise ValueError(f"the base roughness must be Beckmann (LEAN moments), got {type(d).__name__}")
    a = np.asarray(roughness, dtype=np.float64)
    if a.shape not in ((), (2,)) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"roughness must be alpha >= 0 or (alpha_x, alpha_y), got {roughness!r}")
    ax, ay = (a, a) if a.shape == () else a
    return to_moments(ax, ay)


def normal_map_to_moments(nmap, roughness=None, scale: float = 1.0, *, encoding: str = "auto",
                          z: str = "auto") -> np.ndarray:
    """Level-0 LEAN moments ``(H, W, 5)`` float32 of a normal map (array or file, decoded by
    :func:`decode_normal_map` with ``encoding`` and ``z``) with a base roughness
    (Listing 3.7; ``roughness`` as in :func:`base_moments`). ``scale`` multiplies the
    map's slopes before the base lobe is added (height scaling ``beta``, Sec. 3.4).

    Parameters
    ----------
    nmap : ndarray or path
        A normal map ``(H, W, 2|3|4)`` (``uint8``, ``uint16`` or float) or a PNG/EXR file of one.
    roughness : None, float, (float, float) or Beckmann, optional
        The base lobe (:func:`base_moments`).
    scale : float
        Factor of the map's slopes (height scaling).
    encoding, z : str
        How the map is decoded (:func:`decode_normal_map`).

    Returns
    -------
    ndarray, (H, W, 5) float32
        The level-0 moments ``E1..E5``.

    References
    ----------
    Dupuy 2015, thesis, Sec. 3.4, Listing 3.7; Olano & Baker 2010.

    Examples
    --------
    >>> import numpy as np
    >>> nmap = encode_normal_map(np.zeros((16, 16, 2)))          # a flat 16 x 16 normal map
    >>> normal_map_to_moments(nmap, roughness=0.3)[0, 0]
    array([-3.921569e-03, -3.921569e-03,  4.501538e-02,  4.501538e-02,
            1.537870e-05], dtype=float32)
    """
    if not np.isfinite(scale):
        raise ValueError(f"scale must be finite, got {scale!r}")
    slopes = decode_normal_map(nmap, encoding, z) * float(scale)
    with np.errstate(over="ignore", invalid="ignore"):
        E = slopes_to_moments(slopes, base_moments(roughness)).astype(np.float32)
    if not (np.isfinite(E.min()) and np.isfinite(E.max())):        # NaN propagates
        raise ValueError(OVERFLOW)
    return E


@numba.njit(inline="always")
def _neighbours(i, n, wrap):  # pragma: no cover - compiled
    """The texels before and after ``i`` of ``n`` for the central differences (wrapped or clamped)."""
    return (i - 1 if i > 0 else (n - 1 if wrap else 0)), (i + 1 if i < n - 1 else (0 if wrap else n - 1))


@numba.njit(inline="always")
def _texel_moments(rows, cols, scale, b, e):  # pragma: no cover - compiled
    """Moments ``e[c][i]`` (the slopes' E1..E5 convolved with the base moments ``b``,
    Listing 5.1) of the central-difference slopes ``x~ = sx_scale (row[ir] - row[il])``,
    ``y~ = sy_scale (up[i] - down[i])``, computed in float64 (``rows = (row, up, down)``,
    ``cols = (il, i, ir)``, ``scale = (sx_scale, sy_scale)``)."""
    row, up, down = rows
    il, i, ir = cols
    sx_scale, sy_scale = scale
    x = sx_scale * (np.float64(row[ir]) - np.float64(row[il]))
    y = sy_scale * (np.float64(up[i]) - np.float64(down[i]))
    e[0][i] = x + b[0]
    e[1][i] = y + b[1]
    e[2][i] = x * x + b[2] + 2.0 * x * b[0]
    e[3][i] = y * y + b[3] + 2.0 * y * b[1]
    e[4][i] = x * y + b[4] + x * b[1] + y * b[0]


#: Bits of float32's exponent field: all ones for inf and NaN.
_EXPONENT32 = np.uint32(0x7F800000)


@numba.njit(cache=True, nogil=True)
def _height_moments(start, stop, xi, diff, base, out):  # pragma: no cover - compiled
    """Level-0 moments of rows ``start:stop`` of the heights ``xi`` into the planar float32
    ``out (5, H, W)``, row by row through 1-D row views: the two border texels, then the inner
    ones (no index select: that loop vectorizes); ``diff = (sx_scale, sy_scale, wrap)``: the
    central differences' scales and border, ``base`` the base moments. Returns how many stored
    moments are not finite (overflow of float32)."""
    sx_scale, sy_scale, wrap = diff
    scale = (sx_scale, sy_scale)
    h, w = xi.shape
    b = (base[0], base[1], base[2], base[3], base[4])
    bad = 0
    for j in range(start, stop):
        jt, jb = _neighbours(j, h, wrap)
        rows = (xi[j], xi[jt], xi[jb])
        e = (out[0, j], out[1, j], out[2, j], out[3, j], out[4, j])
        for i in (0, w - 1):
            il, ir = _neighbours(i, w, wrap)
            _texel_moments(rows, (il, i, ir), scale, b, e)
        for i in range(1, w - 1):
            _texel_moments(rows, (i - 1, i, i + 1), scale, b, e)
        for c in range(5):                           # inf and NaN: exponent bits all ones
            bits = e[c].view(np.uint32)
            for i in range(w):
                bad += (bits[i] & _EXPONENT32) == _EXPONENT32
    return bad


def bake(height, scale: float = 1.0, roughness=None, *, border: str = "wrap",
         out: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """LEAN/LEADR MIP pyramid of a height map: a list of ``(H_k, W_k, 5)`` float32 moment
    maps ``E1..E5``, level 0 first, down to ``1 x 1``.

    Level 0 holds the moments of the central-difference slopes of ``scale * height`` in
    units of the unit uv square (Sec. 3.4, Listing 3.6), convolved with the base
    ``roughness`` (Listing 5.1; ``None``, ``alpha``, ``(alpha_x, alpha_y)`` or a Beckmann
    lobe); the other levels are exact averages (:func:`microfacet.leadr.mip_pyramid`).
    One fused compiled pass builds level 0 (float64 arithmetic, float32 storage) from the
    heights as they are stored (``uint8``, ``uint16``, ``uint32``, float32 or float64). The
    levels are ``(H_k, W_k, 5)`` views of channels-first storage: each ``level[..., c]``
    is contiguous, as the EXR writer stores it (:func:`~microfacet.leadr.mip_pyramid`).
    ``out``: the levels to fill instead (float32 ``(H_k, W_k, 5)`` of the pyramid's sizes, e.g.
    :func:`microfacet.leadr.pyramid_file`'s, whose file they are). Raises ``ValueError`` if a
    moment overflows float32 (too large a ``scale`` or roughness).

    Parameters
    ----------
    height : ndarray, (H, W)
        Heights, ``uint8``, ``uint16``, ``uint32``, float32 or float64, in units of the map's width
        once multiplied by ``scale``.
    scale : float
        Height scale: the slopes are those of ``scale * height`` over the unit uv square.
    roughness : None, float, (float, float) or Beckmann, optional
        The base material's lobe merged into every texel (:func:`base_moments`).
    border : {"wrap", "clamp"}
        Central differences at the map's edges: periodic (a tileable map) or one-sided.
    out : list of ndarray, optional
        Float32 levels ``(H_k, W_k, 5)`` of the pyramid's sizes to fill instead of new ones.

    Returns
    -------
    list of ndarray
        The levels ``(H_k, W_k, 5)`` float32, level 0 first, down to ``1 x 1``.

    Raises
    ------
    ValueError
        A moment overflows float32, an unknown ``border``, or ``out`` of the wrong sizes.

    References
    ----------
    Dupuy 2015, thesis, Sec. 3.4, Listings 3.6, 5.1; Dupuy et al. 2013; Olano & Baker 2010.

    Examples
    --------
    >>> from microfacet.leadr import gaussian_heightfield
    >>> height = gaussian_heightfield((16, 16), 0.3, seed=0)        # 16 x 16 texels, slopes alpha 0.3
    >>> pyramid = bake(height, roughness=0.1)
    >>> [level.shape for level in pyramid], pyramid[0].dtype
    ([(16, 16, 5), (8, 8, 5), (4, 4, 5), (2, 2, 5), (1, 1, 5)], dtype('float32'))
    >>> import numpy as np       # moments are linear: the top texel is the mean of level 0
    >>> bool(np.allclose(pyramid[-1][0, 0], pyramid[0].mean(axis=(0, 1)), atol=1e-6))
    True
    """
    xi = _check_height(height)
    _check_border(border)
    if not np.isfinite(scale):
        raise ValueError(f"scale must be finite, got {scale!r}")
    if xi.dtype not in (np.uint8, np.uint16, np.uint32, np.float32, np.float64):
        xi = xi.astype(np.float64)
    base = base_moments(roughness)
    base = np.zeros(5) if base is None else base
    h, w = xi.shape
    if out is not None and (len(out) != len(mip_sizes(h, w)) or out[0].shape != (h, w, 5)
                            or out[0].dtype != np.float32):
        raise ValueError(f"out must be the float32 levels of a {h} x {w} map's pyramid")
    planar = np.empty((5, h, w), dtype=np.float32) if out is None else np.moveaxis(out[0], -1, 0)
    with np.errstate(over="ignore", invalid="ignore"):
        bad = launch_ranges(_height_moments, h, np.ascontiguousarray(xi),
                             (0.5 * w * float(scale), 0.5 * h * float(scale), border == "wrap"), base, planar, cost=w)
    if sum(bad):
        raise ValueError(OVERFLOW)
    return mip_pyramid(planar.transpose(1, 2, 0), out)


def bake_reference(height, scale: float = 1.0, roughness=None, *, border: str = "wrap") -> list[np.ndarray]:
    """:func:`bake` written with plain NumPy (float64 throughout): the reference it is
    tested against.

    Parameters
    ----------
    height : ndarray, shape (H, W)
        Heights, as for :func:`bake`.
    scale : float, optional
        Height scale (default 1).
    roughness : None, float, (float, float) or Beckmann, optional
        The base lobe merged into every texel (:func:`base_moments`).
    border : {"wrap", "clamp"}, optional
        Central differences at the edges: periodic (default) or one-sided.

    Returns
    -------
    list of numpy.ndarray
        The float64 levels ``(H_k, W_k, 5)``, level 0 first.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import gaussian_heightfield
    >>> height = gaussian_heightfield((16, 16), 0.3, seed=0)
    >>> all(np.allclose(a, b, atol=1e-6) for a, b in zip(bake(height), bake_reference(height)))
    True
    """
    E = slopes_to_moments(height_to_slopes(height, scale, border), base_moments(roughness))
    return mip_pyramid(E)


