"""Output arrays of the compiled kernels from a cache of freed ones (:func:`empty`).

A new large array is memory fresh from the system: each of its pages faults in (zeroed by
the kernel) the first time the kernels write it. glibc returns a freed block of more than
its trim threshold (~48 MB after the first frees) to the system, so a batch whose outputs
exceed it pays that again at every call, and writing fresh outputs is then markedly slower
than writing into outputs passed with ``out=`` (``benchmarks/bench_brdf.py``).
Dr.Jit, under Mitsuba, keeps freed memory for reuse; so does this cache: the memory of an
output array is kept when the array (and every view of it) is freed, up to
``MICROFACET_OUTPUT_CACHE_MB`` (default 1024; 0 turns the cache off), and handed to the next
output of the same size. :func:`release` gives it back to the system.
"""
from __future__ import annotations

import ctypes
import os
import threading
import weakref

import numpy as np

#: Outputs smaller than this come from ``np.empty`` (glibc keeps such blocks itself).
MIN_BYTES = 1 << 20
_PAGE = 4096


class _Cache:
    """Freed buffers by size, at most ``limit`` bytes in all (oldest dropped first)."""

    def __init__(self, limit: int):
        self.limit, self.kept, self.free = limit, 0, {}
        self.lock = threading.Lock()

    def take(self, size: int):
        with self.lock:
            stack = self.free.get(size)
            if not stack:
                return None
            self.kept -= size
            return stack.pop()

    def give(self, raw) -> None:
        with self.lock:
            if raw.nbytes > self.limit:
                return
            self.free.setdefault(raw.nbytes, []).append(raw)
            self.kept += raw.nbytes
            while self.kept > self.limit:           # drop the oldest of the largest size
                size = max(s for s, stack in self.free.items() if stack)
                self.free[size].pop(0)
                self.kept -= size

    def clear(self) -> None:
        with self.lock:
            self.free, self.kept = {}, 0


def _limit() -> int:
    """``MICROFACET_OUTPUT_CACHE_MB`` in bytes (``ValueError`` naming it unless it is a finite number >= 0)."""
    text = os.environ.get("MICROFACET_OUTPUT_CACHE_MB", "1024")
    try:
        mb = float(text)
    except ValueError:
        mb = -1.0
    if not 0 <= mb < float("inf"):
        raise ValueError(f"MICROFACET_OUTPUT_CACHE_MB must be a finite number of MiB >= 0 (0: no cache), got {text!r}")
    return int(mb * (1 << 20))


_cache = _Cache(_limit())


def empty(shape, dtype) -> np.ndarray:
    """``np.empty(shape, dtype)``, C-contiguous and writeable, whose memory returns to the cache
    when the array and its views are freed (a plain ``np.empty`` below :data:`MIN_BYTES`, or
    with the cache off).

    Parameters
    ----------
    shape : int or tuple of int
        The array's shape.
    dtype : dtype-like
        The array's dtype.

    Returns
    -------
    numpy.ndarray
        An uninitialised array of ``shape`` and ``dtype``.
    """
    dtype = np.dtype(dtype)
    count = int(np.prod(shape))
    nbytes = count * dtype.itemsize
    if nbytes < MIN_BYTES or _cache.limit <= 0:
        return np.empty(shape, dtype)
    size = -(-nbytes // _PAGE) * _PAGE
    raw = _cache.take(size)
    if raw is None:
        raw = np.empty(size, np.uint8)
    holder = (ctypes.c_char * size).from_buffer(raw)      # alive while any view of the array is
    weakref.finalize(holder, _cache.give, raw).atexit = False
    return np.frombuffer(holder, dtype, count).reshape(shape)


def release() -> int:
    """Give the cached memory back to the system; returns how many bytes the cache held.

    Returns
    -------
    int
        Bytes the cache held before it was emptied.

    Examples
    --------
    >>> n = release()                      # bytes the cache held (0 when nothing was freed)
    >>> isinstance(n, int) and n >= 0
    True
    """
    kept = _cache.kept
    _cache.clear()
    return kept
