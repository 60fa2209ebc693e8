"""Single-pass compiled kernels (Numba) for the hot path of the Smith microfacet BRDF.

The NumPy code of :mod:`microfacet.distributions` and :mod:`microfacet.brdf` is the
reference; these kernels fuse the same equations into one pass over directions (the
NumPy version makes ~40 passes over memory) and are tested against it. They cover
``gaf="smith"`` with scalar Beckmann or GGX parameters and every :mod:`microfacet.fresnel`
term; everything else takes the NumPy path. Set ``MICROFACET_NUMBA=0`` to disable them.

A batch runs as a few tasks on a thread pool of :func:`threads` threads (the kernels
release the GIL), each working through its range in cache-sized blocks, so the only
memory a call allocates is its outputs (broadcast inputs are copied a block at a time).
The arithmetic and outputs are float64, or float32 for ``MicrofacetBRDF(...,
dtype=np.float32)`` (kernels compiled per dtype; float32 inputs are read as they are).
The eval, pdf and sample kernels also measure their inputs' checks as they read them (the
unit-length deviations of ``wi``, ``wo``, the uniforms ``u`` outside ``[0, 1]``) and
return them per task (:func:`_checks`), so that ``MicrofacetBRDF`` raises its ``ValueError``
without a pass of its own over the inputs.

Numba is imported, and each kernel compiled (or loaded from Numba's on-disk cache,
``cache=True``), on first use, not when :mod:`microfacet` is imported: the kernels live
in :mod:`microfacet._numba_kernels`, and :func:`compiled` compiles functions on demand.
"""
from __future__ import annotations

import functools
import importlib.util
import itertools
import math
import os

import numpy as np

from . import _buffers

__all__ = ["AVAILABLE", "compiled", "release_outputs", "smith_projected", "smith_eval", "smith_pdf", "smith_sample",
           "unit_deviation"]

#: Give the memory that the cache of freed output arrays holds back to the system; returns its bytes
#: (see :mod:`microfacet._buffers`: outputs of 1 MiB and more, ``MICROFACET_OUTPUT_CACHE_MB``).
release_outputs = _buffers.release

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


def _smith_params(distribution):
    """``(kind, alpha_x, alpha_y, rho, x~n, y~n)`` of a scalar Beckmann or GGX, else ``None``."""
    from .distributions import GGX as _GGX, Beckmann as _Beckmann
    d = distribution
    if not AVAILABLE or type(d) not in (_Beckmann, _GGX) \
            or any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        return None
    k = _kernels()
    return (k.GGX if type(d) is _GGX else k.BECKMANN, float(d.alpha_x), float(d.alpha_y), float(d.rho),
            float(d.xn), float(d.yn))


_NO_TABLE = (np.zeros(2), np.zeros((2, 3)))

#: Batches smaller than this run on the calling thread only: waking worker threads costs
#: 4-8 ms on a loaded machine (measured: eval of 1e4 directions 0.27 ms on one thread,
#: 4-7 ms on two, 2 cores at load 4-5), more than the work.
PARALLEL_MIN = 1 << 16
#: Pairs per task of :func:`_launch_ranges` (at least).
TASK_MIN = 1 << 15


def threads() -> int:
    """Threads the kernels use: Numba's (``NUMBA_NUM_THREADS``, default: the CPU count)."""
    import numba
    return numba.get_num_threads()


def _launch(kernel, n: int, *args) -> None:
    """``kernel(*args)`` of a Numba ``parallel=True`` (``prange``) kernel over ``n`` elements,
    on one thread below :data:`PARALLEL_MIN` (for kernels that are not range kernels)."""
    if n >= PARALLEL_MIN:
        kernel(*args)
        return
    import numba
    t = numba.get_num_threads()
    numba.set_num_threads(1)            # per calling thread
    try:
        kernel(*args)
    finally:
        numba.set_num_threads(t)


@functools.cache
def _pool(n: int):
    from concurrent.futures import ThreadPoolExecutor
    return ThreadPoolExecutor(n, thread_name_prefix="microfacet")


def _launch_ranges(kernel, n: int, *args, cost: int = 1) -> list:
    """``kernel(start, stop, *args)`` over ``0:n`` (the Smith kernels, which work through a
    range; ``cost`` elements per index, e.g. a row's texels): on the calling thread below
    :data:`PARALLEL_MIN` elements, else as up to 4 tasks of at least :data:`TASK_MIN` elements
    per thread, which the calling thread and :func:`threads` ``- 1`` pool threads take in turn
    until none is left (the kernels release the GIL): the caller starts at once, without
    waiting for a pool thread to wake (~0.1 ms), and a thread slowed by the machine's load
    takes fewer. Returns the tasks' return values."""
    t = threads()
    tasks = min(4 * t, n * cost // TASK_MIN, n)
    if t < 2 or n * cost < PARALLEL_MIN:
        return [kernel(0, n, *args)]
    bounds = [n * i // tasks for i in range(tasks + 1)]
    results = [None] * tasks
    claim = itertools.count()                # next() is atomic under the GIL

    def work():
        for i in claim:
            if i >= tasks:
                return
            results[i] = kernel(bounds[i], bounds[i + 1], *args)
    helpers = [_pool(t - 1).submit(work) for _ in range(t - 1)]
    work()
    for f in helpers:                        # one still queued (the pool busy with another call) has nothing left
        if not f.cancel():
            f.result()
    return results


def _checks(names, results) -> dict:
    """``{name: measure}`` of the input checks that the eval, pdf and sample kernels make while
    they read their inputs, over their tasks' ``results`` (per task, one measure per name):
    for directions the largest ``| |w|^2 - 1 |`` (``inf`` on NaN/inf, as :func:`unit_deviation`),
    for ``u`` a count of values outside ``[0, 1]`` (nonzero if one is). The float32 kernels
    measure the deviation in float32 and return an upper bound of it (``_numba_kernels._SLACK32``
    above: float64 arithmetic in their loops halved their SIMD width, and the separate pass
    cost 2 x 0.2 ms per 10^6 pairs on one core), so that a measure that fails the check is
    measured again exactly before it raises (``brdf._check_unit``)."""
    return dict(zip(names, map(max, zip(*results))))


def _fresnel_params(fresnel):
    """``(kind, fp (2, 3), table x, table values)`` of a :mod:`microfacet.fresnel` term for
    the kernels' ``_fresnel``, or ``None`` for another class (and a Schlick term with ``f90 != 1``)."""
    from . import fresnel as fr
    k = _kernels()
    fp = np.zeros((2, 3))
    t = type(fresnel)
    if t is fr.Ideal:
        return k.IDEAL, fp, *_NO_TABLE
    if t is fr.Schlick and np.all(fresnel.f90 == 1.0):      # F90 != 1: the NumPy Fresnel path
        fp[0] = fresnel.f0
        return k.SCHLICK, fp, *_NO_TABLE
    if t is fr.Dielectric:
        fp[0] = fresnel.eta
        return k.DIELECTRIC, fp, *_NO_TABLE
    if t is fr.Conductor:
        fp[0], fp[1] = fresnel.eta, fresnel.k
        return k.CONDUCTOR, fp, *_NO_TABLE
    if t is fr.Tabulated:
        return (k.TABULATED, fp, np.ascontiguousarray(fresnel.cos_theta_d),
                np.ascontiguousarray(fresnel.values))
    return None


def _rows(a, shape):
    """``a`` broadcast to ``shape + (last,)`` as ``(n, last)`` rows (a view where possible)."""
    if a.ndim == 2 and a.shape[:1] == shape:
        return a
    return np.broadcast_to(a, shape + a.shape[-1:]).reshape(-1, a.shape[-1])


def _brdf_params(brdf):
    """Kernel parameters of a Smith :class:`~microfacet.brdf.MicrofacetBRDF`, or ``None``."""
    if brdf.gaf_model != "smith":
        return None
    d = _smith_params(brdf.distribution)          # None without Numba: do not import it
    f = None if d is None else _fresnel_params(brdf.fresnel)
    return None if f is None else (d, f)


def _shape_n(a, b):
    shape = a.shape[:-1] if a.shape[:-1] == b.shape[:-1] else np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    return shape, math.prod(shape)


def smith_projected(distribution, shadowing: bool, wi, wo, divide_cos_i: bool):
    """``(o.h, D G / (4 z_o) [/ z_i])`` by the compiled kernel, or ``None`` when it does
    not apply (no Numba, array parameters, another distribution)."""
    d = _smith_params(distribution)
    if d is None:
        return None
    shape, n = _shape_n(wi, wo)
    oh, s = np.empty(n), np.empty(n)
    _launch_ranges(_kernels().projected_kernel(d[0]), n, _rows(wi, shape), _rows(wo, shape), *d[1:],
                   bool(shadowing), bool(divide_cos_i), oh, s)
    return oh.reshape(shape), s.reshape(shape)


def _typed(dtype, params):
    """``params`` as scalars of ``dtype``, the kernels' arithmetic type (float64 arguments
    would promote float32 arithmetic)."""
    F = np.dtype(dtype).type
    return [F(p) for p in params]


def output(out, shape, dtype, name="out", inputs=()):
    """``out`` (an output array a caller passes to be written, as NumPy's ``out=``), or a new
    array if it is ``None``: ``ValueError`` naming ``name`` unless it is a writeable
    C-contiguous ndarray of ``shape`` and ``dtype`` that shares no memory with ``inputs``. New
    arrays come from the cache of freed outputs (:mod:`microfacet._buffers`, :func:`release_outputs`)."""
    if out is None:
        return _buffers.empty(shape, dtype)
    if not (isinstance(out, np.ndarray) and out.shape == shape and out.dtype == dtype
            and out.flags.c_contiguous and out.flags.writeable):
        got = (("read-only " if not out.flags.writeable else "") + ("non-contiguous " if not out.flags.c_contiguous else "")
               + f"{out.dtype} array of shape {out.shape}") if isinstance(out, np.ndarray) else type(out).__name__
        raise ValueError(f"{name} must be a writeable C-contiguous {np.dtype(dtype)} array of shape {shape}, got {got}")
    if any(np.may_share_memory(out, a) for a in inputs):
        raise ValueError(f"{name} must not share memory with the inputs")
    return out


def smith_eval(brdf, wi, wo, divide_cos_i: bool, dtype=np.float64, out=None):
    """``(f, checks)``: ``f = F D G / (4 z_o) [/ z_i]`` RGB ``(..., 3)`` of a Smith ``brdf``
    (Eq. 2.1) by one compiled pass with the Fresnel term inside, computed and written as
    ``dtype`` (into ``out`` if given: :func:`output`), and the unit-length deviations of ``wi``
    and ``wo`` measured in that pass (:func:`_checks`; ``f`` is meaningless if they fail), or
    ``None`` when the kernel does not apply (no Numba, array parameters, another distribution,
    GAF or Fresnel class)."""
    p = _brdf_params(brdf)
    if p is None:
        return None
    (kind, *d), (fk, *f) = p
    shape, n = _shape_n(wi, wo)
    out = output(out, shape + (3,), dtype, "out", (wi, wo))
    r = _launch_ranges(_kernels().eval_kernel(kind, np.dtype(dtype)), n, _rows(wi, shape), _rows(wo, shape),
                       *_typed(dtype, d), brdf.shadowing, bool(divide_cos_i), fk, f[0].astype(dtype), *f[1:],
                       out.reshape(-1, 3))
    return out, _checks(("wi", "wo"), r)


def smith_pdf(brdf, wi, wo, dtype=np.float64, out=None):
    """``(pdf, checks)``: the visible-normal sampling density ``D(h) / (4 A(o))`` (Eq. 2.17) of
    a Smith ``brdf`` by one compiled pass, computed and written as ``dtype`` (into ``out``), and
    the checks of ``wi`` and ``wo`` (as :func:`smith_eval`), or ``None`` when the kernel does not apply."""
    p = _brdf_params(brdf)
    if p is None or not brdf._samples_visible:
        return None
    shape, n = _shape_n(wi, wo)
    out = output(out, shape, dtype, "out", (wi, wo))
    r = _launch_ranges(_kernels().pdf_kernel(p[0][0], np.dtype(dtype)), n, _rows(wi, shape), _rows(wo, shape),
                       *_typed(dtype, p[0][1:]), out.reshape(-1))
    return out, _checks(("wi", "wo"), r)


def sample_outputs(out, shape, dtype, inputs=()):
    """``(wi, weight, pdf)`` of a sample of ``shape``: ``out``'s three arrays (:func:`output`,
    named ``out[0]`` ... ``out[2]``, distinct), or new ones if it is ``None``."""
    if out is None:
        out = (None,) * 3
    elif not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError(f"out must be a tuple of three arrays (wi, weight, pdf), got {type(out).__name__}")
    arrays = [output(o, shape + last, dtype, f"out[{j}]", inputs)
              for j, (o, last) in enumerate(zip(out, ((3,), (3,), ())))]
    if any(np.may_share_memory(a, b) for j, a in enumerate(arrays) for b in arrays[j + 1:]):
        raise ValueError("out's three arrays must not share memory")
    return tuple(arrays)


def smith_sample(brdf, u, wo, dtype=np.float64, out=None):
    """``((wi, weight, pdf), checks)``: visible-normal sampling (Sec. 2.2, 3.2, Eq. 2.23) of a
    Smith ``brdf`` by one compiled pass, computed and written as ``dtype`` (into ``out``'s
    arrays: :func:`sample_outputs`), and the checks of ``u`` (values outside ``[0, 1]``) and
    ``wo`` (:func:`_checks`) made in that pass, or ``None`` when the kernel does not apply."""
    p = _brdf_params(brdf)
    if p is None or not brdf._samples_visible:
        return None
    (kind, *d), (fk, *f) = p
    shape, n = _shape_n(u, wo)
    wi, weight, pdf = sample_outputs(out, shape, dtype, (u, wo))
    r = _launch_ranges(_kernels().sample_kernel(kind, np.dtype(dtype)), n, _rows(u, shape), _rows(wo, shape),
                       *_typed(dtype, d), brdf.shadowing, fk, f[0].astype(dtype), *f[1:],
                       wi.reshape(-1, 3), weight.reshape(-1, 3), pdf.reshape(-1))
    return (wi, weight, pdf), _checks(("u", "wo"), r)


def unit_deviation(w: np.ndarray) -> float:
    """:func:`microfacet.geometry.unit_deviation` (``max | |w|^2 - 1 |``, ``inf`` on NaN/inf)
    in one compiled pass over a C-contiguous float64 or float32 ``w (..., 3)``; the NumPy reference
    for other arrays or without Numba."""
    from .geometry import unit_deviation as reference
    if not AVAILABLE or w.dtype not in (np.float64, np.float32) or not w.flags.c_contiguous or w.size == 0:
        return reference(w)
    return float(_kernels()._unit_deviation(w.reshape(-1, 3)))
