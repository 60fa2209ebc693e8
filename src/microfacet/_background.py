"""Work started on a daemon thread or in a forked process, as a ``Future``: what the
commands overlap with their imports or with other work. A thread suits work that releases
the GIL (a file's decode or decompression, NumPy loops); work that runs much Python (the
perceptual fits' many small solves) runs in a process (:func:`in_process`)."""
from __future__ import annotations

import multiprocessing
import os
import sys
import threading
from collections.abc import Callable
from concurrent.futures import Future

__all__ = ["in_background", "in_process", "can_fork"]


def in_background(fn: Callable, *args) -> Future:
    """``fn(*args)`` started on a new daemon thread: a ``Future`` of its result or exception
    (Ctrl-C included). Daemon, so an interrupted command exits at once rather than after the
    work, whose results only ever reach the caller through the ``Future``."""
    future = Future()

    def run():
        future.set_running_or_notify_cancel()
        try:
            future.set_result(fn(*args))
        except BaseException as e:                  # re-raised by future.result()
            future.set_exception(e)
    threading.Thread(target=run, name=f"microfacet-{getattr(fn, '__name__', 'work')}", daemon=True).start()
    return future


def can_fork() -> bool:
    """Whether :func:`in_process` forks: on Linux, with two CPUs or more, from a process that
    is not itself a worker (a batch's workers already use the CPUs; daemons cannot fork)."""
    return (sys.platform.startswith("linux") and (os.cpu_count() or 1) > 1
            and multiprocessing.parent_process() is None and not multiprocessing.current_process().daemon)


def _child(fn: Callable, args: tuple, conn) -> None:
    from .batch.workers import exit_with
    exit_with(os.getppid())                      # no orphan computing for a parent killed by kill -9
    try:
        message = ("ok", fn(*args))
    except BaseException as e:                   # sent back as the parent's exception
        message = ("error", e)
    try:
        conn.send(message)
    except Exception as e:                       # an unpicklable result or exception
        conn.send(("error", RuntimeError(f"{getattr(fn, '__name__', 'work')}: {e!r}")))
    conn.close()


def in_process(fn: Callable, *args) -> Future:
    """``fn(*args)`` run in a forked child process (:func:`can_fork`; else on a thread, as
    :func:`in_background`): a ``Future`` of its result, which must pickle, or of its
    exception. Fork it before starting threads; ``fn`` must not run Numba's parallel kernels
    (GNU OpenMP aborts a forked child that does, once its parent has used them). The child
    ends with its parent (even one killed by ``kill -9``) and is daemonic, so an interrupted
    command does not wait for it."""
    if not can_fork():
        return in_background(fn, *args)
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(fn, args, send), daemon=True,
                            name=f"microfacet-{getattr(fn, '__name__', 'work')}")
    child.start()
    send.close()

    def wait():
        try:
            status, value = receive.recv()
        except EOFError:
            child.join()
            raise RuntimeError(f"{getattr(fn, '__name__', 'work')}: worker process ended "
                               f"(exit code {child.exitcode})") from None
        finally:
            receive.close()
        child.join()
        if status == "error":
            raise value
        return value
    return in_background(wait)
