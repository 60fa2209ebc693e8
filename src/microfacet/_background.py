"""Work started on a daemon thread, as a ``Future``: what the commands overlap with their
imports or with other work (a file's decode or decompression, NumPy loops; all release the GIL)."""
from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future

__all__ = ["in_background"]


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
