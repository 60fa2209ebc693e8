"""Atomic file writes: write a temporary sibling, then ``os.replace`` it onto the target.

``os.replace`` is atomic on POSIX and Windows when both paths are on the same file
system, which a sibling in the destination folder guarantees: readers see either the
old file or the complete new one, never a partial write.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "check_writable", "write_bytes", "write_text"]

TMP_SUFFIX = ".tmp"


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _temporary(path: Path) -> Path:
    """A new empty temporary file beside ``path``; the OSError if there is none names ``path``."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TMP_SUFFIX)
    except OSError as e:        # name the destination, not the temporary file
        raise OSError(e.errno, f"cannot write here: {e.strerror}", str(path)) from None
    os.close(fd)
    return Path(tmp)


def check_writable(path: str | os.PathLike) -> None:
    """Raise the ``OSError`` that :func:`atomic_path` would raise for ``path`` (its folder
    missing, read-only, not a folder, ...), by creating and removing a temporary file there:
    commands check their outputs before their work."""
    _temporary(Path(path)).unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success move it onto ``path``.

    The caller writes the complete file to the yielded path (e.g. a library that only
    accepts file names, such as OpenEXR). On success its data are flushed to disk, it
    gets the usual ``0o666 & ~umask`` permissions and replaces ``path`` atomically; on
    any exception it is removed and the exception propagates, leaving ``path`` as it was.
    """
    path = Path(path)
    tmp = _temporary(path)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically; return ``path``."""
    return write_bytes(path, text.encode("utf-8"))
