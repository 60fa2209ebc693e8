"""Worker processes that die with the process that started them.

A ``ProcessPoolExecutor`` worker waits on a queue whose write end it holds itself, so it
outlives a parent killed by ``kill -9`` (no cleanup runs); with the ``forkserver`` start
method its parent is the fork server, which in turn lives as long as a worker holds its
"alive" pipe, and the resource tracker as long as either holds its pipe: all of them stay,
holding the caller's stdout and stderr (a shell pipeline or ``subprocess.run`` never
finishes). :func:`exit_with` makes a worker exit as soon as a given process (the batch's
or the demo's main process) ends; once the workers are gone, the fork server and the
resource tracker see their pipes close and exit too.
"""
from __future__ import annotations

import os
import select
import threading
import time

__all__ = ["exit_with", "process_ended"]

#: Seconds between checks where the system has no ``pidfd_open`` (not Linux >= 5.3).
POLL_SECONDS = 0.5


def process_ended(pid: int) -> bool:
    """Whether process ``pid`` has ended (gone, or a zombie not yet reaped).

    Parameters
    ----------
    pid : int
        Process id.

    Returns
    -------
    bool
        ``True`` when the process is gone or a zombie.

    Examples
    --------
    >>> import os, subprocess, sys
    >>> process_ended(os.getpid())
    False
    >>> child = subprocess.Popen([sys.executable, "-c", "pass"])
    >>> _ = child.wait()
    >>> process_ended(child.pid)
    True
    """
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return False


def _watch(pid: int) -> None:
    try:
        fd = os.pidfd_open(pid)                 # readable when the process ends
    except ProcessLookupError:
        os._exit(1)
    except (AttributeError, OSError):           # no pidfd: poll
        fd = None
    while True:
        if fd is not None:
            select.select([fd], [], [], POLL_SECONDS * 20)
        else:
            time.sleep(POLL_SECONDS)
        if process_ended(pid):
            os._exit(1)                         # no cleanup: the parent that wanted the work is gone


def exit_with(pid: int) -> None:
    """Make this process exit (``os._exit(1)``) when process ``pid`` ends: a daemon thread
    waits on a ``pidfd`` of ``pid`` (Linux >= 5.3), else polls every :data:`POLL_SECONDS`.
    Call it in a worker's initializer with the main process's pid.

    Parameters
    ----------
    pid : int
        Process id to watch (usually the main process's).

    Examples
    --------
    >>> exit_with(os.getppid())             # in a worker started by a plain fork or spawn
    """
    if pid == os.getpid():
        return
    if process_ended(pid):
        os._exit(1)
    threading.Thread(target=_watch, args=(pid,), name="microfacet-exit-with", daemon=True).start()
