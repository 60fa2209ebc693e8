"""Work started on a daemon thread (a ``Future``) or in a forked process (an iterator of its
items): what the commands overlap with their imports or with other work. A thread suits work
that releases the GIL (a file's decode or decompression, NumPy loops); work that runs much
Python (the perceptual fits' many small solves) runs in a process (:func:`in_process_items`)."""
from __future__ import annotations

import multiprocessing
import os
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future

__all__ = ["in_background", "in_process_items", "can_fork", "Handoff"]


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
    """Whether :func:`in_process_items` forks: on Linux, with two CPUs or more, from a process that
    is not itself a worker (a batch's workers already use the CPUs; daemons cannot fork)."""
    return (sys.platform.startswith("linux") and (os.cpu_count() or 1) > 1
            and multiprocessing.parent_process() is None and not multiprocessing.current_process().daemon)


class Handoff:
    """One value that this process gives to the child of :func:`in_process_items` after
    forking it (pass the handoff among the child's arguments): :meth:`put` here, :meth:`get`
    in the child, which waits for it there. The value is sent on a daemon thread, so
    :meth:`put` does not wait for the child to read it. Where the generator is not forked
    (it then runs here, as it is read), :meth:`get` returns what :meth:`put` gave.

    Example
    -------
    >>> def scaled(handoff, xs):
    ...     k = handoff.get()
    ...     for x in xs:
    ...         yield k * x
    >>> factor = Handoff()
    >>> items = in_process_items(scaled, factor, [1, 2])
    >>> factor.put(10)
    >>> list(items)
    [10, 20]
    """

    def __init__(self):
        self._value, self._given, self._pipe = None, False, None

    def _fork(self, context) -> None:
        """Called by :func:`in_process_items` before it forks: the value will travel on a pipe."""
        if self._pipe is None:
            self._pipe = context.Pipe(duplex=False)

    def put(self, value) -> None:
        """Give ``value`` (once)."""
        self._value, self._given = value, True
        if self._pipe is not None:
            receive, send = self._pipe
            receive.close()
            in_background(self._send, send, value)

    @staticmethod
    def _send(send, value) -> None:
        try:
            send.send(value)
        except OSError:                          # the child has ended: its items say why
            pass
        finally:
            send.close()

    def get(self):
        """The value :meth:`put` gives, waiting for it in a forked child."""
        if self._given:
            return self._value
        if self._pipe is None:
            raise RuntimeError("Handoff.get: nothing was put, and no child was forked to wait for it")
        receive, send = self._pipe
        send.close()
        with receive:
            return receive.recv()


def _child(fn: Callable, args: tuple, conn) -> None:
    from .batch.workers import exit_with
    exit_with(os.getppid())                      # no orphan computing for a parent killed by kill -9
    try:
        for item in fn(*args):
            _send(conn, ("item", item), fn)
        message = ("ok", None)
    except BaseException as e:                   # sent back as the parent's exception
        message = ("error", e)
    _send(conn, message, fn)
    conn.close()


def _send(conn, message: tuple, fn: Callable) -> None:
    try:
        conn.send(message)
    except Exception as e:                       # an unpicklable item or exception
        conn.send(("error", RuntimeError(f"{getattr(fn, '__name__', 'work')}: {e!r}")))


def _receive(fn: Callable, child, receive) -> tuple:
    """The child's next message, ``(status, value)``; an exception if it ended without one."""
    try:
        return receive.recv()
    except EOFError:
        child.join()
        raise RuntimeError(f"{getattr(fn, '__name__', 'work')}: worker process ended "
                           f"(exit code {child.exitcode})") from None


def in_process_items(fn: Callable, *args) -> Iterator:
    """The items of the generator ``fn(*args)`` made in a forked child process
    (:func:`can_fork`; else the generator itself, run as it is read), each as soon as it is
    made: the caller works on early items while the child makes the next. Items must pickle;
    a :class:`Handoff` among ``args`` carries a value the caller gives after the fork.
    Fork it before starting threads; ``fn`` must not run Numba's parallel kernels (GNU OpenMP
    aborts a forked child that does, once its parent has used them). The child ends with its
    parent (even one killed by ``kill -9``) and is daemonic. An exception in the child is raised where the items stop; a caller that
    stops reading early stops the child.

    Parameters
    ----------
    fn : callable
        A generator function; its items must pickle.
    *args
        Its arguments.

    Returns
    -------
    Iterator
        The items, in the order made.

    Examples
    --------
    >>> def squares(n):
    ...     for k in range(n):
    ...         yield k * k
    >>> list(in_process_items(squares, 4))
    [0, 1, 4, 9]
    """
    if not can_fork():
        return fn(*args)
    context = multiprocessing.get_context("fork")
    for a in args:
        if isinstance(a, Handoff):
            a._fork(context)
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(fn, args, send), daemon=True,
                            name=f"microfacet-{getattr(fn, '__name__', 'work')}")
    child.start()
    send.close()

    def items():
        status = "item"
        try:
            while status == "item":
                status, value = _receive(fn, child, receive)
                if status == "item":
                    yield value
                elif status == "error":
                    raise value
        finally:                                 # read to the end, or left early (then the child stops)
            receive.close()
            if status == "item":
                child.terminate()
            child.join()
    return items()
