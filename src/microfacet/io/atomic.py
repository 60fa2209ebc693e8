"""Atomic file writes: write a temporary sibling, then ``os.replace`` it onto the target.

``os.replace`` is atomic on POSIX and Windows when both paths are on the same file
system, which a sibling in the destination folder guarantees: readers see either the
old file or the complete new one, never a partial write.

A temporary file is named ``.<name>.<pid>@<host>.<random>.tmp`` after its writer, so that
a process killed while writing (``kill -9``, a crash: no cleanup runs) leaves a file the
next writer of the same output recognises as stale (:func:`remove_stale`: its owner is a
dead process of this host) and removes, while the temporaries of writers still running,
e.g. a second command writing the same output, are left alone. :func:`folder_lock` lets
one batch at a time write into a folder.

Examples
--------
>>> from microfacet.io.atomic import TMP_SUFFIX, LOCK_NAME, STAGING_NAME
>>> TMP_SUFFIX, LOCK_NAME, STAGING_NAME
('.tmp', '.microfacet.lock', 'microfacet-staging')
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "check_writable", "write_bytes", "write_text", "temporary_owner", "remove_stale",
           "folder_lock", "FolderBusy", "staging_folder", "TMP_SUFFIX", "LOCK_NAME", "STAGING_NAME"]

TMP_SUFFIX = ".tmp"
#: The lock file of :func:`folder_lock` (hidden: a batch takes no hidden file as input).
LOCK_NAME = ".microfacet.lock"
#: ``<pid>@<host>.<random>`` of a temporary's name, or the ``<random>`` alone of the names
#: written before the owner was recorded (``tempfile``'s 8 characters).
_OWNED = re.compile(r"(\d+)@([A-Za-z0-9.-]+)\.[a-z0-9_]{8}")
_LEGACY = re.compile(r"[a-z0-9_]{8}")


def _host() -> str:
    """This machine's name as it appears in temporary names (letters, digits, ``.``, ``-``)."""
    return re.sub(r"[^A-Za-z0-9.-]", "-", socket.gethostname())[:64] or "localhost"


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _temporary(path: Path) -> Path:
    """A new empty temporary file beside ``path``; the OSError if there is none names ``path``."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}@{_host()}.",
                                   suffix=TMP_SUFFIX)
    except OSError as e:        # name the destination, not the temporary file
        raise OSError(e.errno, f"cannot write here: {e.strerror}", str(path)) from None
    os.close(fd)
    return Path(tmp)


def check_writable(path: str | os.PathLike) -> None:
    """Raise the ``OSError`` that :func:`atomic_path` would raise for ``path`` (its folder
    missing, read-only, not a folder, ...), by creating and removing a temporary file there:
    commands check their outputs before their work.

    Parameters
    ----------
    path : str or os.PathLike
        The file a command will write.

    Examples
    --------
    >>> check_writable("out.exr")                        # the current folder is writable: no error
    >>> check_writable("missing-folder/out.exr")
    Traceback (most recent call last):
        ...
    FileNotFoundError: [Errno 2] cannot write here: No such file or directory: 'missing-folder/out.exr'
    """
    _temporary(Path(path)).unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success move it onto ``path``.

    The caller writes the complete file to the yielded path (e.g. a library that only
    accepts file names, such as OpenEXR). On success its data are flushed to disk, it
    gets the usual ``0o666 & ~umask`` permissions and replaces ``path`` atomically; on
    any exception it is removed and the exception propagates, leaving ``path`` as it was
    (an ``OSError`` that named no file or the temporary one, e.g. a full disk, is raised
    again naming ``path``).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write; its folder must exist.

    Yields
    ------
    Path
        The temporary file to write.

    Examples
    --------
    >>> from pathlib import Path
    >>> with atomic_path("table.csv") as tmp:           # write the whole file to tmp ...
    ...     _ = tmp.write_text("a,b" + chr(10))
    >>> Path("table.csv").read_text().strip()            # ... then it replaces table.csv at once
    'a,b'
    """
    path = Path(path)
    tmp = _temporary(path)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if e.errno and e.filename in (None, str(tmp)):       # name the destination (a full disk, ...)
            raise OSError(e.errno, e.strerror or os.strerror(e.errno), str(path)) from None
        raise
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def temporary_owner(tmp: str | os.PathLike, path: str | os.PathLike) -> tuple[int, str] | None | bool:
    """Who wrote the temporary file ``tmp`` of the output ``path``: ``(pid, host)``; ``None``
    for a temporary written before owners were recorded; ``False`` if ``tmp`` is not one of
    ``path``'s temporaries (e.g. one of ``path.x.exr``'s, whose name starts alike).

    Parameters
    ----------
    tmp : str or os.PathLike
        A file next to ``path``.
    path : str or os.PathLike
        The output.

    Returns
    -------
    (int, str) or None or False
        ``(pid, host)``, None or False (see above).

    Examples
    --------
    >>> import os
    >>> from pathlib import Path
    >>> with atomic_path("image.png") as tmp:
    ...     owner = temporary_owner(tmp, "image.png")
    ...     _ = tmp.write_bytes(b"x")
    >>> owner[0] == os.getpid()                           # this process wrote it
    True
    >>> temporary_owner("other.png.tmp", "image.png")     # not a temporary of image.png
    False
    """
    name, prefix = Path(tmp).name, f".{Path(path).name}."
    if not (name.startswith(prefix) and name.endswith(TMP_SUFFIX)):
        return False
    middle = name[len(prefix):-len(TMP_SUFFIX)]
    owned = _OWNED.fullmatch(middle)
    if owned:
        return int(owned.group(1)), owned.group(2)
    return None if _LEGACY.fullmatch(middle) else False


def _alive(pid: int) -> bool:
    """Whether process ``pid`` of this machine exists (a zombie counts as dead)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:         # another user's process
        return True
    try:                            # Linux: a killed process not yet reaped by its parent
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def remove_stale(path: str | os.PathLike, other_hosts: bool = False) -> list[Path]:
    """Remove the temporaries of ``path`` (:func:`atomic_path`) whose writer is gone: those of
    a dead process of this machine, and those written before owners were recorded; with
    ``other_hosts``, those of other machines too (a batch that holds its folder's
    :func:`folder_lock` and reruns a task whose worker died elsewhere). Temporaries of live
    processes (another command writing the same output) are kept. Returns the paths removed.

    Parameters
    ----------
    path : str or os.PathLike
        The output whose temporaries are looked for.
    other_hosts : bool
        Remove the temporaries of other machines too.

    Returns
    -------
    list of Path
        The files removed.

    Examples
    --------
    >>> from pathlib import Path
    >>> Path("out").mkdir()
    >>> _ = Path("out/.h.exr.4242@box.x1y2z3w4.tmp").write_bytes(b"")   # left by a killed writer
    >>> remove_stale("out/h.exr", other_hosts=True)   # a batch rerunning a task of a dead worker
    [PosixPath('out/.h.exr.4242@box.x1y2z3w4.tmp')]
    """
    path = Path(path)
    removed = []
    if not path.parent.is_dir():
        return removed
    host = _host()
    try:
        candidates = [p for p in path.parent.iterdir() if p.name.startswith(f".{path.name}.")]
    except OSError:
        return removed
    for tmp in candidates:
        owner = temporary_owner(tmp, path)
        if owner is False:
            continue
        if owner is not None:
            pid, where = owner
            if (where == host and _alive(pid)) or (where != host and not other_hosts):
                continue
        try:
            if tmp.is_dir() and not tmp.is_symlink():      # a staging folder (:func:`staging_folder`)
                shutil.rmtree(tmp)
            else:
                tmp.unlink()
            removed.append(tmp)
        except OSError:
            pass
    return removed


#: Name of the staging folders of :func:`staging_folder` (before their owner and ``.tmp``).
STAGING_NAME = "microfacet-staging"


@contextlib.contextmanager
def staging_folder(folder: str | os.PathLike, last: str = "") -> Iterator[Path]:
    """All or nothing for a set of files: yield a new hidden folder inside ``folder``
    (``.microfacet-staging.<pid>@<host>.<random>.tmp``) to write them into; when the block
    succeeds, move each of them (``os.replace``: no copy, no new disk space) to the same
    relative path in ``folder``, replacing what is there, the file named ``last`` at the
    end; when it fails (a full disk, Ctrl-C), remove the staging folder, leaving ``folder``
    as it was. Staging folders of dead processes (a ``kill -9``) are removed first.

    Parameters
    ----------
    folder : str or os.PathLike
        The destination folder (it must exist).
    last : str
        Relative path of the file to move last (e.g. a manifest); empty: none.

    Yields
    ------
    Path
        The staging folder.

    Examples
    --------
    >>> import os
    >>> os.makedirs("report", exist_ok=True)
    >>> with staging_folder("report", last="index.html") as stage:
    ...     _ = write_text(stage / "table.csv", "a,b")
    ...     _ = write_text(stage / "index.html", "<p>done</p>")
    >>> sorted(os.listdir("report"))                   # both files, moved in at the end
    ['index.html', 'table.csv']
    """
    folder = Path(folder)
    remove_stale(folder / STAGING_NAME)
    try:
        stage = Path(tempfile.mkdtemp(dir=folder, prefix=f".{STAGING_NAME}.{os.getpid()}@{_host()}.",
                                      suffix=TMP_SUFFIX))
    except OSError as e:
        raise OSError(e.errno, f"cannot write here: {e.strerror}", str(folder)) from None
    try:
        yield stage
        files = sorted((p for p in stage.rglob("*") if not p.is_dir()),
                       key=lambda p: (p.relative_to(stage).as_posix() == last, p.relative_to(stage).as_posix()))
        for f in files:
            target = folder / f.relative_to(stage)
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(f, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


class FolderBusy(OSError):
    """Another process holds the folder's :func:`folder_lock` (and ``wait`` was false).

    Examples
    --------
    >>> with folder_lock("."):
    ...     try:
    ...         with folder_lock(".", wait=False):
    ...             pass
    ...     except FolderBusy as e:
    ...         print("busy")
    busy
    """


def _lock_holder(fd: int) -> int:
    """The pid written in a lock file, 0 if none can be read."""
    try:
        return int(os.pread(fd, 32, 0).split()[0])
    except (ValueError, IndexError, OSError):
        return 0


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike, wait: bool = True, on_wait=None) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (``fcntl.flock`` on its :data:`LOCK_NAME` file,
    which holds the holder's pid and is removed on release) for the block, so that two
    batches never write into one folder at once. When another process holds it: with
    ``wait``, call ``on_wait(pid)`` (the holder's pid, 0 if unknown) once and block until it
    is released; else raise :class:`FolderBusy` naming the folder and the holder. The lock
    dies with its process (``kill -9`` included: the file then stays, unlocked). Elsewhere
    than POSIX it is a no-op.

    Parameters
    ----------
    folder : str or os.PathLike
        The folder to lock (it must exist).
    wait : bool
        Block until the lock is free (else raise :class:`FolderBusy`).
    on_wait : callable, optional
        ``on_wait(pid)``, called once before blocking.

    Yields
    ------
    Path
        The lock file.

    Examples
    --------
    >>> import os
    >>> os.makedirs("batch", exist_ok=True)
    >>> with folder_lock("batch") as lock:
    ...     lock.name                       # write into batch/ here
    '.microfacet.lock'
    >>> os.path.exists("batch/.microfacet.lock")     # removed on release
    False
    """
    folder = Path(folder)
    try:
        import fcntl
    except ImportError:                     # Windows: no flock
        yield folder / LOCK_NAME
        return
    lock, told = folder / LOCK_NAME, False
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666 & ~_umask())
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as e:
                if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise
                pid = _lock_holder(fd)
                if not wait:
                    holder = f"process {pid}" if pid else "another process"
                    raise FolderBusy(errno.EBUSY, f"another microfacet batch ({holder}) is writing into this "
                                                  "folder; wait for it or choose another output folder",
                                     str(folder)) from None
                if on_wait is not None and not told:
                    on_wait(pid)
                    told = True
                fcntl.flock(fd, fcntl.LOCK_EX)
            try:                            # the holder before removed the file: lock the new one
                same = os.path.samestat(os.fstat(fd), os.stat(lock))
            except FileNotFoundError:
                same = False
            if not same:
                continue
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            try:
                yield lock
            finally:
                with contextlib.suppress(OSError):
                    lock.unlink()           # while still held: a waiter then retries on a new file
            return
        finally:
            os.close(fd)                    # releases the lock


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist.
    data : bytes
        The content.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> write_bytes("data.bin", b"MERL").read_bytes()
    b'MERL'
    """
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically; return ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist.
    text : str
        The content.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> write_text("notes.txt", "hello").read_text()
    'hello'
    """
    return write_bytes(path, text.encode("utf-8"))
