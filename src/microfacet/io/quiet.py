"""Native libraries' messages kept off the terminal: OpenEXR's C library prints up to hundreds
of lines on stderr for a corrupt file (its Python binding a warning on stdout), libpng its
warnings; the readers capture them and say what matters in one line."""
from __future__ import annotations

import ctypes
import io
import logging
import os
import sys
import tempfile
import threading
from contextlib import contextmanager

__all__ = ["native_output_captured", "log_captured"]

_lock = threading.RLock()


@contextmanager
def native_output_captured(into: list):
    """Within the block, what native code writes to file descriptors 1 and 2 goes to a temporary
    file, and what is printed through ``sys.stdout``/``sys.stderr`` to a buffer; their text is
    appended to ``into`` at the end (OpenEXR's C library prints up to
    hundreds of lines on stderr for a corrupt file, its binding a warning on stdout). Blocks in
    several threads take turns (a lock): the descriptors are the process's, so what other
    threads print meanwhile is captured too.

    Parameters
    ----------
    into : list
        Receives the captured text.

    Examples
    --------
    >>> text = []
    >>> with native_output_captured(text):
    ...     _ = os.write(2, b"libfoo: warning\\n")
    >>> text
    ['libfoo: warning\\n']
    """
    with _lock, tempfile.TemporaryFile() as tmp:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, OSError, ValueError):
                pass
        try:
            saved = [os.dup(1), os.dup(2)]
        except OSError:                      # no descriptors 1 and 2 (a detached process)
            yield
            return
        try:
            libc = ctypes.CDLL(None)
        except OSError:                      # no C library to flush by name (Windows)
            libc = None
        streams = sys.stdout, sys.stderr
        python = io.StringIO()               # what bindings print through Python (pybind11's py::print)
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            sys.stdout = sys.stderr = python
            yield
        finally:
            sys.stdout, sys.stderr = streams
            if libc is not None:
                libc.fflush(None)            # C stdio buffers (C++ iostreams write through them)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            tmp.seek(0)
            into.append(python.getvalue() + tmp.read().decode("utf-8", "replace"))


class _Records(logging.Handler):
    def __init__(self, into: list):
        super().__init__(logging.DEBUG)
        self.into = into

    def emit(self, record: logging.LogRecord) -> None:
        self.into.append(record.getMessage())


@contextmanager
def log_captured(name: str, into: list):
    """Within the block, the records of logger ``name`` (e.g. ``"imagecodecs"``, which logs
    libpng's warnings) are appended to ``into`` as messages instead of being handled (printed
    by logging's last-resort handler when the application configured none).

    Parameters
    ----------
    name : str
        Logger name.
    into : list
        Receives the messages.

    Examples
    --------
    >>> import logging
    >>> records = []
    >>> with log_captured("imagecodecs", records):
    ...     logging.getLogger("imagecodecs").warning("noisy codec message")
    >>> records
    ['noisy codec message']
    """
    logger = logging.getLogger(name)
    handler, propagate = _Records(into), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
