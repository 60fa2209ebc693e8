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

Cold start (``MICROFACET_COMPILE``, :data:`COMPILE`): a kernel compiles in ~5-20 s (once per
install and signature; Numba's cache then loads it in milliseconds). By default
(``background``) the BRDF methods (``MicrofacetBRDF.eval`` ...) and the functions of
:func:`compiled` do not wait for it: a call whose kernel is not ready in this process queues
its compilation (or its load from the cache) on one background thread and runs the NumPy
reference, batches of up to :data:`BACKGROUND_MAX` pairs; larger batches, and every call once
the kernel is ready, run the kernel (a larger batch waits for it). The two paths agree to
1e-12 (float64; ``tests/test_kernels.py``) and to the float32 kernels' accuracy (1e-5) for
float32 BRDFs, so a result may move by that much between a call made while its kernel
compiles and one made after. ``wait`` compiles the kernel at the first call, before running
it, as the public functions of this module (``smith_eval`` ...) always do. :func:`precompile`
(``python -m microfacet.kernels --precompile``, run by ``make setup``) fills Numba's cache
ahead of time; see ``docs/performance.md``.

Examples
--------
>>> AVAILABLE in (True, False), COMPILE in ("background", "wait"), BACKGROUND_MAX
(True, True, 1048576)
"""
from __future__ import annotations

import functools
import importlib.util
import itertools
import math
import os
import queue
import threading

import numpy as np

from . import _background, _buffers, params

__all__ = ["AVAILABLE", "BACKGROUND_MAX", "COMPILE", "Compiled", "compiled", "covers", "launch", "launch_ranges", "ready", "release_outputs",
           "smith_projected", "smith_eval", "smith_pdf", "smith_sample", "unit_deviation", "precompile_calls"]

#: Give the memory that the cache of freed output arrays holds back to the system; returns its bytes
#: (see :mod:`microfacet._buffers`: outputs of 1 MiB and more, ``MICROFACET_OUTPUT_CACHE_MB``).
release_outputs = _buffers.release

#: Numba is installed and not disabled by ``MICROFACET_NUMBA=0`` (checked without importing it).
AVAILABLE = os.environ.get("MICROFACET_NUMBA", "1") != "0" and importlib.util.find_spec("numba") is not None


def _compile_mode() -> str:
    mode = os.environ.get("MICROFACET_COMPILE", "background").strip().lower() or "background"
    if mode not in ("background", "wait"):
        raise ValueError(f"MICROFACET_COMPILE must be 'background' or 'wait', got {mode!r}")
    return mode


#: ``MICROFACET_COMPILE``: ``"background"`` (default) or ``"wait"``: what a BRDF method or a
#: :func:`compiled` function does while its kernel is not compiled yet in this process (module docstring).
COMPILE = _compile_mode()
#: Largest batch (pairs) that runs the NumPy reference while its kernel compiles in the background
#: (``COMPILE == "background"``); a larger batch waits for the kernel. Per 2^20 pairs the NumPy path
#: takes ~0.3-1 s (eval, pdf, GGX sample; Beckmann sample ~5 s) and ~0.4 GB, a cold kernel 5-30 s
#: (benchmarks/results/cold_start.md).
BACKGROUND_MAX = 1 << 20

@functools.cache
def _kernels():
    """The compiled kernels' module (imports Numba)."""
    from . import _numba_kernels
    return _numba_kernels


class Compiled:
    """``function`` compiled by ``numba.njit(cache=True, nogil=True)`` on demand (NumPy array
    expressions fused into one loop; the same source, so the NumPy function stays the reference).
    A call runs the compiled function for its argument types, compiling (or loading) it first
    with :data:`COMPILE` ``"wait"``; with ``"background"`` a call whose compiled function is not
    ready runs ``function`` itself (NumPy) and queues the compilation (the module docstring),
    arrays of up to :data:`BACKGROUND_MAX` elements. Example::

        f = Compiled(lambda c, eta, k: ...)      # kernels.compiled(...)
        f(np.linspace(0, 1, 5), 1.5, 2.0)

    Parameters
    ----------
    function : callable
        A NumPy function that Numba can compile (``nopython`` mode).

    Examples
    --------
    >>> import numpy as np
    >>> def hypot3(x):
    ...     return np.sqrt(np.sum(x * x, axis=-1))
    >>> f = Compiled(hypot3)
    >>> f.py_func is hypot3, f.__name__                # compiles at its first call, not here
    (True, 'hypot3')
    """

    def __init__(self, function):
        self.py_func = function
        functools.update_wrapper(self, function)

    @functools.cached_property
    def dispatcher(self):
        """The Numba dispatcher of ``function`` (imports Numba)."""
        import numba
        return numba.njit(cache=True, nogil=True)(self.py_func)

    def __call__(self, *args):
        n = max((a.size for a in args if isinstance(a, np.ndarray)), default=1)
        k = _kernel((self,), args, n, True)
        return self.py_func(*args) if k is None else k(*args)


def compiled(function):
    """:class:`Compiled` ``function`` (``numba.njit(cache=True)`` on demand, the NumPy function
    as its fallback while it compiles), or ``None`` without Numba. Callers build it on first
    use and keep it (a dispatcher loads from Numba's cache in milliseconds, a ``numba.vectorize``
    ufunc takes ~0.5 s to build).

    Parameters
    ----------
    function : callable
        A NumPy function that Numba can compile.

    Returns
    -------
    Compiled or None
        The lazily compiled function, or ``None`` without Numba.

    Examples
    --------
    >>> import numpy as np
    >>> f = compiled(np.hypot)
    >>> f is None if not AVAILABLE else isinstance(f, Compiled)
    True
    """
    if not AVAILABLE:
        return None
    return Compiled(function)


# -------------------------------------------------------------- compiling on demand
#: The kernels ready in this process (compiled or loaded from Numba's cache), by ``(maker,
#: argument types)`` (:func:`_kernel`): the Numba dispatcher to call.
_READY: dict = {}
#: Keys queued for, or being compiled on, the background thread; keys whose compilation failed
#: there (their calls then compile on the calling thread, which raises the error).
_QUEUED: set = set()
_FAILED: set = set()
_JOBS: queue.SimpleQueue = queue.SimpleQueue()
_WORKER_LOCK = threading.Lock()
_WORKER: list = []
#: The tag of a tuple's :func:`_arg_type`.
_TUPLE = "tuple"
#: Scalar argument types whose Numba type follows from the type alone (``numba.typeof(t())``).
_SCALARS = (bool, int, float, np.bool_, np.int64, np.float64, np.float32)


def _arg_type(a):
    """What Numba's dispatcher selects a compiled version by, for argument ``a``, without importing
    Numba: an array's dtype, ndim, layout (``C``, ``F`` or ``A``, as ``numba.typeof``), read-only and
    aligned flags; a scalar's type (:data:`_SCALARS`); a tuple's (a named tuple's too, such as the
    kernels' :class:`~microfacet.params.SmithParams` record) class and element types; ``None`` for
    anything else."""
    if isinstance(a, np.ndarray):
        layout = "C" if a.flags.c_contiguous else "F" if a.flags.f_contiguous else "A"
        return a.dtype.str, a.ndim, layout, not a.flags.writeable, a.flags.aligned
    t = type(a)
    if isinstance(a, tuple):
        items = tuple(map(_arg_type, a))
        return None if None in items else (_TUPLE, t, items)
    return t if t in _SCALARS else None


def _numba_type(t):
    """The Numba type of an :func:`_arg_type`."""
    import numba
    if isinstance(t, tuple) and t[0] is _TUPLE:
        _, cls, items = t
        return numba.types.BaseTuple.from_types([_numba_type(i) for i in items], None if cls is tuple else cls)
    if isinstance(t, tuple):
        dtype, ndim, layout, readonly, aligned = t
        return numba.types.Array(numba.from_dtype(np.dtype(dtype)), ndim, layout, readonly=readonly, aligned=aligned)
    return numba.typeof(t())


def _dispatcher(maker):
    """The Numba dispatcher of ``maker``: ``(name, *params)`` of :mod:`microfacet._numba_kernels`
    (``("eval_kernel", kind, dtype)`` -> ``eval_kernel(kind, dtype)``, ``("_unit_deviation",)``), or
    ``(Compiled,)``."""
    name, *params = maker
    if isinstance(name, Compiled):
        return name.dispatcher
    k = getattr(_kernels(), name)
    return k(*params) if params else k


def _compile(k, types) -> None:
    """Compiles the dispatcher ``k`` for the :func:`_arg_type` s ``types``, or loads it from Numba's
    cache, holding an exclusive lock on a file in that cache's folder (``fcntl.flock``; none where
    that is unavailable): Numba writes a function's cache index without one, so two processes that
    compile versions of a function at once can leave the index pointing at the other's code (numba
    issue #4807; seen here as wrong sample weights after test runs in parallel); with it the second
    process waits, then loads what the first saved."""
    sig = tuple(map(_numba_type, types))
    try:
        import fcntl
        folder = k._cache.cache_path                 # None without cache=True
        os.makedirs(folder, exist_ok=True)
        lock = open(os.path.join(folder, "microfacet-compile.lock"), "ab")
    except (ImportError, AttributeError, OSError, TypeError):
        k.compile(sig)
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            k.compile(sig)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _forget_in_child() -> None:
    """After ``fork``: the child has no background thread; its queue starts empty."""
    global _JOBS, _WORKER_LOCK
    _JOBS, _WORKER_LOCK = queue.SimpleQueue(), threading.Lock()
    _QUEUED.clear()
    _WORKER.clear()


def _fork_safely() -> None:
    """Makes ``os.fork`` wait for a compile in progress (holding Numba's compiler lock over the fork,
    as :mod:`logging` does with its locks): a child forked while the background thread held it
    would wait for it forever at its first compile."""
    from numba.core.compiler_lock import global_compiler_lock

    def child():
        global_compiler_lock.release()
        _forget_in_child()
    os.register_at_fork(before=global_compiler_lock.acquire, after_in_parent=global_compiler_lock.release,
                        after_in_child=child)


def _work() -> None:
    """The background thread: compiles (or loads from Numba's cache) the queued kernels, in order."""
    if hasattr(os, "register_at_fork"):
        _fork_safely()
    while True:
        key = _JOBS.get()
        try:
            k = _dispatcher(key[0])
            _compile(k, key[1])
            _READY[key] = k
        except BaseException:                    # compiled again on the calling thread, which raises
            _FAILED.add(key)
        finally:
            _QUEUED.discard(key)


def _queue(key) -> None:
    if key in _QUEUED:
        return
    _QUEUED.add(key)
    _JOBS.put(key)
    with _WORKER_LOCK:
        if not _WORKER:
            _WORKER.append(_background.in_background(_work))


def _kernel(maker, args, n: int, background: bool):
    """The dispatcher of ``maker`` (:func:`_dispatcher`) to call on ``args`` (a batch of ``n``
    pairs), or ``None``: the caller runs its NumPy reference. ``None`` only with ``background``, in
    :data:`COMPILE` ``"background"`` mode, for ``n`` up to :data:`BACKGROUND_MAX`, while the kernel for
    these argument types is not ready in this process: its compilation is then queued on the
    background thread (:func:`_work`). Otherwise the dispatcher, compiled for them first if needed
    (:func:`_compile`, or loaded from Numba's cache; waiting for the background thread if it is
    compiling it)."""
    types = tuple(map(_arg_type, args))
    key = (maker, types)
    k = _READY.get(key)
    if k is not None:
        return k
    if background and COMPILE == "background" and n <= BACKGROUND_MAX and None not in types and key not in _FAILED:
        _queue(key)
        return None
    k = _dispatcher(maker)
    if None not in types:
        _compile(k, types)
        _READY[key] = k
    return k


def ready(wait: float | None = 0.0) -> bool:
    """Whether no kernel is queued or compiling on the background thread (``COMPILE ==
    "background"``), after waiting up to ``wait`` seconds for it (``None``: until it is done).
    Example: ``mf.kernels.ready(wait=None)`` before timing a loop.

    Parameters
    ----------
    wait : float or None, optional
        Seconds to wait (default 0: do not wait); ``None``: until the queue is empty.

    Returns
    -------
    bool
        ``True`` when nothing is queued or compiling.

    Examples
    --------
    >>> ready(wait=None)             # nothing queued on the background thread any more
    True
    """
    import time
    end = None if wait is None else time.monotonic() + wait
    while _QUEUED:
        if end is not None and time.monotonic() >= end:
            return False
        time.sleep(0.01)
    return True


#: Batches smaller than this run on the calling thread only: waking worker threads costs
#: 4-8 ms on a loaded machine (measured: eval of 1e4 directions 0.27 ms on one thread,
#: 4-7 ms on two, 2 cores at load 4-5), more than the work.
PARALLEL_MIN = 1 << 16
#: Pairs per task of :func:`launch_ranges` (at least).
TASK_MIN = 1 << 15


def threads() -> int:
    """Threads the kernels use: Numba's (``NUMBA_NUM_THREADS``, default: the CPU count)."""
    import numba
    return numba.get_num_threads()


def launch(kernel, n: int, *args) -> None:
    """``kernel(*args)`` of a Numba ``parallel=True`` (``prange``) kernel over ``n`` elements,
    on one thread below :data:`PARALLEL_MIN` (for kernels that are not range kernels).

    Parameters
    ----------
    kernel : Numba dispatcher
        A ``parallel=True`` kernel.
    n : int
        Number of elements it processes.
    *args
        The kernel's arguments.

    Examples
    --------
    >>> import numpy as np
    >>> out = np.zeros(3)
    >>> def fill(out, value):          # a Numba prange kernel in the library; any callable here
    ...     out[:] = value
    >>> launch(fill, 3, out, 2.0)      # below PARALLEL_MIN: one thread
    >>> out
    array([2., 2., 2.])
    """
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


#: The names these had before they were public (``benchmarks/bench_brdf.py``).
_launch = launch


@functools.cache
def _pool(n: int):
    from concurrent.futures import ThreadPoolExecutor
    return ThreadPoolExecutor(n, thread_name_prefix="microfacet")


def launch_ranges(kernel, n: int, *args, cost: int = 1) -> list:
    """``kernel(start, stop, *args)`` over ``0:n`` (the Smith kernels, which work through a
    range; ``cost`` elements per index, e.g. a row's texels): on the calling thread below
    :data:`PARALLEL_MIN` elements, else as up to 4 tasks of at least :data:`TASK_MIN` elements
    per thread, which the calling thread and :func:`threads` ``- 1`` pool threads take in turn
    until none is left (the kernels release the GIL): the caller starts at once, without
    waiting for a pool thread to wake (~0.1 ms), and a thread slowed by the machine's load
    takes fewer. Returns the tasks' return values.

    Parameters
    ----------
    kernel : Numba dispatcher
        A range kernel ``kernel(start, stop, *args)`` that releases the GIL.
    n : int
        Number of indices.
    *args
        The kernel's other arguments.
    cost : int, optional
        Elements per index (default 1), to size the tasks.

    Returns
    -------
    list
        The tasks' return values, in task order.

    Examples
    --------
    >>> launch_ranges(lambda start, stop, scale: (stop - start) * scale, 10, 2)   # small: one task
    [20]
    """
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


_launch_ranges = launch_ranges


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


def _rows(a, shape):
    """``a`` broadcast to ``shape + (last,)`` as ``(n, last)`` read-only rows (a view where possible;
    a copy of Fortran-ordered rows, such as Dr.Jit's arrays seen through NumPy, so that the kernels
    see C-contiguous or broadcast rows only: the layouts that ``precompile`` compiles)."""
    if a.ndim == 2 and a.flags.f_contiguous and not a.flags.c_contiguous:
        a = np.ascontiguousarray(a)
    if a.ndim == 2 and a.shape[:1] == shape:
        return params.read_only(a)
    return params.read_only(np.broadcast_to(a, shape + a.shape[-1:]).reshape(-1, a.shape[-1]))


def _record(brdf, dtype=None):
    """The :class:`~microfacet.params.SmithParams` record of a Smith ``brdf`` for the kernels
    (``brdf.params``, built when the BRDF was made; made again for a ``dtype`` other than the
    BRDF's), or ``None``: no Numba, or a BRDF they do not cover."""
    if not AVAILABLE:
        return None
    p = getattr(brdf, "params", None)
    if p is None or dtype is None or np.dtype(dtype) == brdf.dtype:
        return p
    return params.smith_params(brdf.distribution, brdf.fresnel, brdf.shadowing, dtype)


def covers(brdf) -> bool:
    """Whether the fused kernels (:func:`smith_eval`; :func:`smith_pdf` and :func:`smith_sample` for
    visible-normal sampling) cover ``brdf``: Numba available, a Smith GAF, a scalar Beckmann or GGX
    and a :mod:`microfacet.fresnel` term they know. Imports neither Numba nor the kernels.

    Parameters
    ----------
    brdf : BRDF
        Any BRDF.

    Returns
    -------
    bool
        ``True`` when the fused kernels can evaluate it.

    Examples
    --------
    >>> import microfacet as mf
    >>> covers(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2))) == AVAILABLE
    True
    >>> covers(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2), gaf="vgroove"))
    False
    """
    return _record(brdf) is not None


def _shape_n(a, b):
    shape = a.shape[:-1] if a.shape[:-1] == b.shape[:-1] else np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    return shape, math.prod(shape)


def _output_like(dtype, ndim: int):
    """An empty array of the type of a kernel's output (C-contiguous, writeable, ``dtype``, ``ndim``
    dimensions), to choose the kernel (:func:`_kernel`) before the output is made."""
    return np.empty((0,) * ndim, dtype)


def smith_projected(distribution, shadowing: bool, wi, wo, divide_cos_i: bool, background: bool = False):
    """``(o.h, D G / (4 z_o) [/ z_i])`` by the compiled kernel, or ``None`` when it does
    not apply (no Numba, array parameters, another distribution) or, with ``background``,
    while it compiles (:func:`_kernel`; the caller runs the NumPy reference).

    Parameters
    ----------
    distribution : Distribution
        A scalar Beckmann or GGX distribution.
    shadowing : bool
        Whether ``G`` has the shadowing term ``Lambda(i)`` (else masking only).
    wi, wo : ndarray, shape (..., 3)
        Unit directions (their batch shapes broadcast).
    divide_cos_i : bool
        Divide by ``z_i`` (``True``) or not.
    background : bool, optional
        Return ``None`` instead of waiting while the kernel compiles (default ``False``).

    Returns
    -------
    (ndarray, ndarray) or None
        ``o.h`` and ``D G / (4 z_o)`` (``/ z_i``), each of the broadcast batch shape.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> n = np.array([[0.0, 0.0, 1.0]])
    >>> r = smith_projected(mf.GGX(alpha=0.3), True, n, n, True)    # precompiled by make setup
    >>> r is None or (r[0].round(4).tolist(), r[1].round(4).tolist())   # o.h, D G / (4 z_o z_i)
    ([1.0], [0.8842])
    """
    p = params.smith_params(distribution, None, shadowing) if AVAILABLE else None
    if p is None:
        return None
    shape, n = _shape_n(wi, wo)
    args = (p, _rows(wi, shape), _rows(wo, shape), bool(divide_cos_i))
    k = _kernel(("projected_kernel", p.kind), (0, 0, *args, (_output_like(np.float64, 1),) * 2), n, background)
    if k is None:
        return None
    oh, s = np.empty(n), np.empty(n)
    launch_ranges(k, n, *args, (oh, s))
    return oh.reshape(shape), s.reshape(shape)


def smith_eval(brdf, wi, wo, divide_cos_i: bool, dtype=np.float64, out=None, background: bool = False):
    """``(f, checks)``: ``f = F D G / (4 z_o) [/ z_i]`` RGB ``(..., 3)`` of a Smith ``brdf``
    (Eq. 2.1) by one compiled pass with the Fresnel term inside, computed and written as
    ``dtype`` (into ``out`` if given, an array checked by :func:`microfacet.protocol.output`), and the unit-length deviations of ``wi``
    and ``wo`` measured in that pass (:func:`_checks`; ``f`` is meaningless if they fail), or
    ``None`` when the kernel does not apply (no Numba, array parameters, another distribution,
    GAF or Fresnel class) or, with ``background``, while it compiles (:func:`_kernel`).

    Parameters
    ----------
    brdf : MicrofacetBRDF
        A Smith BRDF (:func:`covers`).
    wi, wo : ndarray, (..., 3)
        Unit directions (their batch shapes broadcast).
    divide_cos_i : bool
        Return ``f`` (True) or ``f cos theta_i`` (False).
    dtype : numpy.float64 or numpy.float32
        Arithmetic and output type.
    out : ndarray, optional
        The ``(..., 3)`` output to write.
    background : bool
        Return ``None`` instead of waiting while the kernel compiles.

    Returns
    -------
    (ndarray, dict) or None
        ``f`` and the input checks ``{"wi": deviation, "wo": deviation}``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 2.1.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> wi = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    >>> f, checks = smith_eval(brdf, wi, wi[::-1].copy(), True)     # precompiled by make setup
    >>> f.round(4), checks
    (array([[0.2699, 0.2699, 0.2699],
           [0.2699, 0.2699, 0.2699]]), {'wi': 0.0, 'wo': 0.0})
    >>> np.allclose(f, brdf.eval(wi, wi[::-1]))
    True
    """
    p = _record(brdf, dtype)
    if p is None:
        return None
    shape, n = _shape_n(wi, wo)
    args = (p, _rows(wi, shape), _rows(wo, shape), bool(divide_cos_i))
    k = _kernel(("eval_kernel", p.kind, np.dtype(dtype)), (0, 0, *args, _output_like(dtype, 2)), n, background)
    if k is None:
        return None
    out = _buffers.empty(shape + (3,), dtype) if out is None else out
    r = launch_ranges(k, n, *args, out.reshape(-1, 3))
    return out, _checks(("wi", "wo"), r)


def smith_pdf(brdf, wi, wo, dtype=np.float64, out=None, background: bool = False):
    """``(pdf, checks)``: the visible-normal sampling density ``D(h) / (4 A(o))`` (Eq. 2.17) of
    a Smith ``brdf`` by one compiled pass, computed and written as ``dtype`` (into ``out``), and
    the checks of ``wi`` and ``wo`` (as :func:`smith_eval`), or ``None`` when the kernel does not apply
    (or, with ``background``, while it compiles).

    Parameters
    ----------
    brdf : MicrofacetBRDF
        A Smith BRDF (:func:`covers`).
    wi, wo : ndarray, shape (..., 3)
        Unit directions (their batch shapes broadcast).
    dtype : numpy.float64 or numpy.float32, optional
        Arithmetic and output type (default float64).
    out : ndarray, optional
        The ``(...)`` output to write.
    background : bool, optional
        Return ``None`` instead of waiting while the kernel compiles (default ``False``).

    Returns
    -------
    (ndarray, dict) or None
        The density and the input checks ``{"wi": deviation, "wo": deviation}``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 2.17; Heitz 2018 (visible normals).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> n = np.array([[0.0, 0.0, 1.0]])
    >>> pdf, checks = smith_pdf(brdf, n, n)      # precompiled by make setup
    >>> pdf.round(4), np.allclose(pdf, brdf.pdf(n, n))
    (array([0.8842]), True)
    """
    p = _record(brdf, dtype)
    if p is None:
        return None
    shape, n = _shape_n(wi, wo)
    args = (p, _rows(wi, shape), _rows(wo, shape))
    k = _kernel(("pdf_kernel", p.kind, np.dtype(dtype)), (0, 0, *args, _output_like(dtype, 1)), n, background)
    if k is None:
        return None
    out = _buffers.empty(shape, dtype) if out is None else out
    r = launch_ranges(k, n, *args, out.reshape(-1))
    return out, _checks(("wi", "wo"), r)


def smith_sample(brdf, u, wo, dtype=np.float64, out=None, background: bool = False):
    """``((wi, weight, pdf), checks)``: visible-normal sampling (Sec. 2.2, 3.2, Eq. 2.23) of a
    Smith ``brdf`` by one compiled pass, computed and written as ``dtype`` (into ``out``'s
    arrays, checked by :func:`microfacet.protocol.sample_outputs`), and the checks of ``u`` (values outside ``[0, 1]``) and
    ``wo`` (:func:`_checks`) made in that pass, or ``None`` when the kernel does not apply (or,
    with ``background``, while it compiles).

    Parameters
    ----------
    brdf : MicrofacetBRDF
        A Smith BRDF (:func:`covers`).
    u : ndarray, shape (..., 2)
        Uniform random numbers in ``[0, 1)``.
    wo : ndarray, shape (..., 3)
        Unit view directions (batch shapes broadcast with ``u``).
    dtype : numpy.float64 or numpy.float32, optional
        Arithmetic and output type (default float64).
    out : tuple of 3 ndarray, optional
        ``(wi, weight, pdf)`` arrays to write into.
    background : bool, optional
        Return ``None`` instead of waiting while the kernel compiles (default ``False``).

    Returns
    -------
    ((ndarray, ndarray, ndarray), dict) or None
        ``(wi, weight, pdf)`` and the input checks ``{"u": count, "wo": deviation}``.

    References
    ----------
    Dupuy 2015, thesis, Sec. 2.2, 3.2, Eq. 2.23.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> (wi, weight, pdf), checks = smith_sample(brdf, np.array([[0.5, 0.5]]), np.array([[0.0, 0.0, 1.0]]))
    >>> wi.round(4), weight.round(4), pdf.round(4), checks
    (array([[0., 0., 1.]]), array([[1., 1., 1.]]), array([0.8842]), {'u': 0, 'wo': 0.0})
    """
    p = _record(brdf, dtype)
    if p is None:
        return None
    shape, n = _shape_n(u, wo)
    args = (p, _rows(u, shape), _rows(wo, shape))
    k = _kernel(("sample_kernel", p.kind, np.dtype(dtype)),
                (0, 0, *args, (_output_like(dtype, 2), _output_like(dtype, 2), _output_like(dtype, 1))), n, background)
    if k is None:
        return None
    wi, weight, pdf = (_buffers.empty(shape + (3,), dtype), _buffers.empty(shape + (3,), dtype),
                       _buffers.empty(shape, dtype)) if out is None else out
    r = launch_ranges(k, n, *args, (wi.reshape(-1, 3), weight.reshape(-1, 3), pdf.reshape(-1)))
    return (wi, weight, pdf), _checks(("u", "wo"), r)


def unit_deviation(w: np.ndarray, background: bool = True) -> float:
    """:func:`microfacet.geometry.unit_deviation` (``max | |w|^2 - 1 |``, ``inf`` on NaN/inf)
    in one compiled pass over a C-contiguous float64 or float32 ``w (..., 3)``; the NumPy reference
    for other arrays, without Numba or, with ``background`` (the default: this is the BRDFs' input
    check), while the pass compiles (:func:`_kernel`). Example: ``unit_deviation(np.array([[0, 0, 1.0]]))`` is 0.

    Parameters
    ----------
    w : ndarray, shape (..., 3)
        Directions.
    background : bool, optional
        Use the NumPy reference while the pass compiles (default ``True``).

    Returns
    -------
    float
        ``max | |w|^2 - 1 |`` (``inf`` on NaN or inf).

    Examples
    --------
    >>> import numpy as np
    >>> unit_deviation(np.array([[0.0, 0.0, 1.0]]))
    0.0
    >>> round(unit_deviation(np.array([[0.0, 0.0, 1.1]])), 4)
    0.21
    >>> unit_deviation(np.array([[0.0, 0.0, np.nan]]))
    inf
    """
    from .geometry import unit_deviation as reference
    if not AVAILABLE or w.dtype not in (np.float64, np.float32) or not w.flags.c_contiguous or w.size == 0:
        return reference(w)
    rows = params.read_only(w.reshape(-1, 3))
    k = _kernel(("_unit_deviation",), (rows,), len(rows), background)
    return reference(w) if k is None else float(k(rows))


def precompile_calls(calls, progress=None) -> int:
    """Runs ``calls`` (``[(name, call)]``, each a small instance of a code path) one after the
    other in this process with every kernel compiled before it runs (:data:`COMPILE` ``"wait"``
    meanwhile), so that Numba compiles them into its on-disk cache or loads them from it; one
    process at a time (:func:`_compile`). ``progress(name, seconds)`` is called after each. Returns
    how many ran; 0 without Numba. The loop of every precompile entry point
    (:mod:`microfacet.precompile`, :mod:`microfacet.kernels_extra`). Example:
    ``precompile_calls([("unit deviation", lambda: unit_deviation(np.eye(3), False))])`` is 1.

    Parameters
    ----------
    calls : sequence of (str, callable)
        Named calls without arguments.
    progress : callable, optional
        ``progress(name, seconds)`` called after each call (default none).

    Returns
    -------
    int
        The number of calls run (0 without Numba).

    Examples
    --------
    >>> import numpy as np
    >>> precompile_calls([("unit deviation", lambda: unit_deviation(np.eye(3), False))]) == int(AVAILABLE)
    True
    """
    import time
    global COMPILE
    if not AVAILABLE:
        return 0
    saved, COMPILE = COMPILE, "wait"
    try:
        for name, call in calls:
            t = time.perf_counter()
            call()
            if progress is not None:
                progress(name, time.perf_counter() - t)
    finally:
        COMPILE = saved
    return len(calls)


if __name__ == "__main__":                      # python -m microfacet.kernels --precompile (make setup)
    from microfacet.precompile import main
    raise SystemExit(main())
