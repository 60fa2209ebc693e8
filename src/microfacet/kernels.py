"""Single-pass compiled kernels (Numba) for the hot path of the Smith microfacet BRDF.

The NumPy code of :mod:`microfacet.distributions` and :mod:`microfacet.brdf` is the
reference; these kernels fuse the same equations into one loop over directions (the
NumPy version makes ~40 passes over memory) and are tested against it. They cover
``gaf="smith"`` with scalar Beckmann or GGX parameters; everything else takes the NumPy
path. Set ``MICROFACET_NUMBA=0`` to disable them.

Numba is imported, and each kernel compiled (or loaded from Numba's on-disk cache,
``cache=True``), on first use, not when :mod:`microfacet` is imported: the kernels live
in :mod:`microfacet._numba_kernels`, and :func:`compiled` compiles functions on demand.
"""
from __future__ import annotations

import functools
import importlib.util
import os

import numpy as np

__all__ = ["AVAILABLE", "compiled", "smith_projected", "unit_deviation"]

#: Numba is installed and not disabled by ``MICROFACET_NUMBA=0`` (checked without importing it).
AVAILABLE = os.environ.get("MICROFACET_NUMBA", "1") != "0" and importlib.util.find_spec("numba") is not None


@functools.cache
def _kernels():
    """The compiled kernels' module (imports Numba)."""
    from . import _numba_kernels
    return _numba_kernels


def compiled(function):
    """``numba.njit(cache=True)(function)``: the same source compiled (NumPy array
    expressions fused into one loop), so the NumPy function stays the reference; ``None``
    without Numba. Callers build it on first use and keep it (a dispatcher loads from
    Numba's cache in milliseconds, a ``numba.vectorize`` ufunc takes ~0.5 s to build)."""
    if not AVAILABLE:
        return None
    import numba
    return numba.njit(cache=True, nogil=True)(function)


def smith_projected(distribution, shadowing: bool, wi, wo, divide_cos_i: bool):
    """``(o.h, D G / (4 z_o) [/ z_i])`` by the compiled kernel, or ``None`` when it does
    not apply (no Numba, array parameters, another distribution)."""
    from .distributions import GGX as _GGX, Beckmann as _Beckmann
    d = distribution
    if not AVAILABLE or type(d) not in (_Beckmann, _GGX) \
            or any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        return None
    k = _kernels()
    kind = k.GGX if type(d) is _GGX else k.BECKMANN
    wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
    shape = wi.shape[:-1]
    wi2 = np.ascontiguousarray(wi.reshape(-1, 3))
    wo2 = np.ascontiguousarray(wo.reshape(-1, 3))
    oh, s = np.empty(len(wi2)), np.empty(len(wi2))
    k._smith_projected(wi2, wo2, kind, float(d.alpha_x), float(d.alpha_y), float(d.rho), float(d.xn),
                       float(d.yn), bool(shadowing), bool(divide_cos_i), oh, s)
    return oh.reshape(shape), s.reshape(shape)


def unit_deviation(w: np.ndarray) -> float:
    """:func:`microfacet.geometry.unit_deviation` (``max | |w|^2 - 1 |``, ``inf`` on NaN/inf)
    in one compiled pass over a C-contiguous float64 ``w (..., 3)``; the NumPy reference
    for other arrays or without Numba."""
    from .geometry import unit_deviation as reference
    if not AVAILABLE or w.dtype != np.float64 or not w.flags.c_contiguous or w.size == 0:
        return reference(w)
    return float(_kernels()._unit_deviation(w.reshape(-1, 3)))
