"""Memory of batch tasks: a task's peak resident memory, the machine's available memory
and the number of local workers that fits in it.

A task's peak is the worker process's peak resident set size (Linux ``VmHWM``) while it
runs: the peak is reset before the task (``/proc/self/clear_refs``, Linux >= 4.0), so a
worker that runs many tasks reports each one's own peak; elsewhere it is the process's
lifetime peak (``resource.getrusage(...).ru_maxrss``), an upper bound.
"""
from __future__ import annotations

import os
import resource
import sys

__all__ = ["reset_peak", "peak_bytes", "available_bytes", "cpu_count", "default_jobs"]

_CLEAR_REFS, _STATUS = "/proc/self/clear_refs", "/proc/self/status"


def reset_peak() -> bool:
    """Reset this process's peak resident set size to its current one; ``False`` where
    the system cannot (then :func:`peak_bytes` is the lifetime peak).

    Returns
    -------
    bool
        ``True`` when the peak was reset.

    Examples
    --------
    >>> reset_peak() in (True, False)
    True
    """
    try:
        with open(_CLEAR_REFS, "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_bytes() -> int:
    """This process's peak resident set size in bytes since :func:`reset_peak` (``VmHWM``),
    else since it started (``ru_maxrss``: kB on Linux, bytes on macOS).

    Returns
    -------
    int
        Peak resident set size in bytes.

    Examples
    --------
    >>> peak_bytes() > 0
    True
    """
    try:
        with open(_STATUS) as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss if sys.platform == "darwin" else rss * 1024


def available_bytes() -> int:
    """Memory available to new work: ``MemAvailable`` of ``/proc/meminfo``, else the free
    physical pages (``os.sysconf``).

    Returns
    -------
    int
        Available memory in bytes.

    Examples
    --------
    >>> available_bytes() > 0
    True
    """
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def cpu_count() -> int:
    """CPUs this process may run on.

    Returns
    -------
    int
        The number of CPUs (at least 1).

    Examples
    --------
    >>> cpu_count() >= 1
    True
    """
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def default_jobs(peak_estimate: int, n_files: int, available: int | None = None, cpus: int | None = None) -> int:
    """Local worker processes: ``jobs x peak_estimate <= available`` memory, at most the CPU
    count and the number of files, at least 1.

    Parameters
    ----------
    peak_estimate : int
        A task's estimated peak memory, bytes.
    n_files : int
        Files in the batch.
    available : int, optional
        Memory available, bytes (default :func:`available_bytes`).
    cpus : int, optional
        CPUs (default :func:`cpu_count`).

    Returns
    -------
    int
        ``max(1, min(cpus, n_files, available // peak_estimate))``.

    Examples
    --------
    >>> GB = 2 ** 30
    >>> default_jobs(peak_estimate=3 * GB, n_files=100, available=16 * GB, cpus=8)    # memory-bound
    5
    >>> default_jobs(peak_estimate=GB // 10, n_files=100, available=16 * GB, cpus=8)  # CPU-bound
    8
    >>> default_jobs(peak_estimate=GB, n_files=2, available=16 * GB, cpus=8)          # two files
    2
    """
    available = available_bytes() if available is None else available
    cpus = cpu_count() if cpus is None else cpus
    by_memory = available // max(int(peak_estimate), 1)
    return int(max(1, min(cpus, n_files, by_memory)))
