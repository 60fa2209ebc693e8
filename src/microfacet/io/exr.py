"""OpenEXR images through the ``OpenEXR`` package (never imageio, which misreads EXR).

Images are ``(H, W)`` or ``(H, W, C)`` arrays, row 0 at the top, with ``C`` = 1 (``Y``),
3 (``R, G, B``) or 4 (``R, G, B, A``) channels of linear values.

Examples
--------
>>> from microfacet.io.exr import COMPRESSIONS, EXR_MAGIC
>>> sorted(COMPRESSIONS)
['none', 'piz', 'rle', 'zip', 'zips', 'zstd']
>>> EXR_MAGIC.hex()
'762f3101'
"""
from __future__ import annotations

import errno
import os
import re
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import OpenEXR

from ..errors import MicrofacetError
from .atomic import atomic_path
from .quiet import native_output_captured
from .read import read_bytes

__all__ = ["read_exr", "write_exr", "EXR_MAGIC", "check_exr_magic", "COMPRESSIONS", "exr_compression", "exr_threads",
           "exr_write_errors", "exr_read_errors"]

#: First four bytes of every OpenEXR file (``20000630`` little-endian).
EXR_MAGIC = b"\x76\x2f\x31\x01"

_NAMES = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}

#: The lossless OpenEXR compressions (float32 round-trips bit for bit), by name. On LEADR
#: pyramids ``none`` writes several times faster than ``zip``, whose files are barely smaller
#: (``benchmarks/bench_leadr.py``); ``zstd`` needs OpenEXR >= 3.4 to read.
COMPRESSIONS = {"none": OpenEXR.NO_COMPRESSION, "rle": OpenEXR.RLE_COMPRESSION,
                "zips": OpenEXR.ZIPS_COMPRESSION, "zip": OpenEXR.ZIP_COMPRESSION,
                "piz": OpenEXR.PIZ_COMPRESSION, "zstd": OpenEXR.ZSTD_COMPRESSION}


def exr_compression(name: str):
    """The OpenEXR compression constant for a lossless ``name`` in :data:`COMPRESSIONS`.

    Parameters
    ----------
    name : str
        A key of :data:`COMPRESSIONS`.

    Returns
    -------
    OpenEXR compression constant
        The constant.

    Examples
    --------
    >>> exr_compression("zip") == COMPRESSIONS["zip"]
    True
    >>> exr_compression("lossy")
    Traceback (most recent call last):
        ...
    ValueError: EXR compression must be one of ['none', 'piz', 'rle', 'zip', 'zips', 'zstd'] (lossless), got 'lossy'
    """
    if name not in COMPRESSIONS:
        raise ValueError(f"EXR compression must be one of {sorted(COMPRESSIONS)} (lossless), got {name!r}")
    return COMPRESSIONS[name]


_threads_lock = threading.Lock()
_threads_users = 0          # exr_threads() blocks now running, in any thread
_threads_before = 0         # the global count the first of them found


@contextmanager
def exr_threads():
    """Let OpenEXR (de)compress on every core this process may use (OpenEXR's default, 0,
    works on the calling thread only), restoring its process-global thread count when the
    last concurrent user leaves: a lock and a count of users make overlapping blocks in
    several threads safe (a save/restore per block would restore too early, or leak).

    Examples
    --------
    >>> import numpy as np
    >>> with exr_threads():
    ...     path = write_exr("big.exr", np.zeros((64, 64, 3)))
    >>> path.name
    'big.exr'
    """
    global _threads_users, _threads_before
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    with _threads_lock:
        if _threads_users == 0:
            _threads_before = OpenEXR.global_thread_count()
            OpenEXR.set_global_thread_count(cores)
        _threads_users += 1
    try:
        yield
    finally:
        with _threads_lock:
            _threads_users -= 1
            if _threads_users == 0:
                OpenEXR.set_global_thread_count(_threads_before)


#: System errors OpenEXR reports in the text of its ``RuntimeError`` (by their ``strerror``).
_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS, errno.EACCES, errno.EPERM)


@contextmanager
def exr_write_errors(path: str | os.PathLike):
    """Within the block, an OpenEXR write's ``RuntimeError`` (``Failed to write pixel data to
    image file "...tmp". No space left on device.``) becomes an ``OSError`` naming ``path``,
    with the system error it reports (``ENOSPC``, ...; else ``EIO`` and OpenEXR's message), so
    that a command says it in one line: ``out.exr: No space left on device``.

    Parameters
    ----------
    path : str or os.PathLike
        The file written, for messages.

    Examples
    --------
    >>> import numpy as np
    >>> with exr_write_errors("out.exr"):              # as write_exr uses it
    ...     path = write_exr("out.exr", np.ones((2, 2)))
    >>> path.name
    'out.exr'
    """
    try:
        yield
    except RuntimeError as e:
        text = " ".join(str(e).split())
        code = next((c for c in _WRITE_ERRNOS if os.strerror(c).lower() in text.lower()), None)
        if code is not None:
            raise OSError(code, os.strerror(code), str(path)) from None
        raise OSError(errno.EIO, f"cannot write the EXR file (OpenEXR: {text})", str(path)) from None


#: What OpenEXR's Python binding prints when it drops a part it cannot read (it then raises
#: "file has 0 parts"): the real cause follows the dash.
_DROPPED_PART = re.compile(r"Exception raised reading pixel data for part \d+ - (.+)")


def _read_cause(path: Path, text: str, error: Exception) -> str:
    """The cause of a failed read, from OpenEXR's captured output ``text`` (its C library's first
    ``EXR_ERR`` line, else the cause its binding gave for a dropped part) or the exception (may be None)."""
    lines = [ln.strip().removeprefix(f"{path}:").strip() for ln in text.splitlines() if ln.strip()]
    native = [ln for ln in lines if "EXR_ERR" in ln]
    if native:
        return native[0]
    dropped = _DROPPED_PART.search(text)
    if dropped:
        return dropped.group(1).strip()
    if error is None:
        return "unknown cause"
    return " ".join(str(error).split()) or type(error).__name__


def _memory_bytes() -> int | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def _check_size(path: Path, headers) -> None:
    """``MicrofacetError`` naming the size when reading the parts of ``headers`` (``dataWindow``,
    ``channels``) as float32 arrays and their float64 copy would need more than this machine's memory."""
    need, dims = 0, None
    for h in headers:
        lo, hi = (np.asarray(v, dtype=np.int64) for v in h["dataWindow"])
        w, hgt = (hi - lo + 1).tolist()
        n = len(h.get("channels", ())) or 1
        need += max(w, 0) * max(hgt, 0) * n * (4 + 8)
        dims = dims or (w, hgt, n)
    total = _memory_bytes()
    if total and need > total:
        raise MicrofacetError(f"{path}: {dims[0]} x {dims[1]} pixels, {dims[2]} channels: reading needs "
                              f"{need / 2**30:.1f} GiB, more than this machine's {total / 2**30:.1f} GiB of memory")


@contextmanager
def exr_read_errors(path: str | os.PathLike):
    """Within the block (OpenEXR reads of ``path``), OpenEXR's own messages on stdout/stderr are
    captured, not printed, and an exception becomes one :class:`MicrofacetError` naming the file
    and the cause OpenEXR gave (``trunc.exr: unreadable or corrupt EXR ((EXR_ERR_BAD_CHUNK_LEADER)
    ...)``, not its binding's "file has 0 parts").

    Parameters
    ----------
    path : str or os.PathLike
        The file read, for messages.

    Examples
    --------
    >>> from pathlib import Path
    >>> _ = Path("trunc.exr").write_bytes(EXR_MAGIC + bytes(16))
    >>> read_exr("trunc.exr")                           # exr_read_errors turns OpenEXR's error into one line
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: trunc.exr: unreadable or corrupt EXR (...)
    """
    path = Path(path)
    text: list[str] = []
    try:
        with native_output_captured(text):
            yield
    except MicrofacetError:
        raise
    except Exception as e:  # OpenEXR raises RuntimeError/others for corrupt files
        raise MicrofacetError(f"{path}: unreadable or corrupt EXR ({_read_cause(path, ''.join(text), e)})") from None
    if _DROPPED_PART.search("".join(text)):    # a part the binding dropped without raising
        raise MicrofacetError(f"{path}: unreadable or corrupt EXR ({_read_cause(path, ''.join(text), None)})")


def read_headers(path: str | os.PathLike) -> list[dict]:
    """The headers of the parts of the EXR file ``path`` (OpenEXR's ``header_only`` read, quiet:
    :func:`exr_read_errors`)."""
    with exr_read_errors(path):
        return [p.header for p in OpenEXR.File(str(path), header_only=True).parts]


def _as_channels(image) -> np.ndarray:
    """``image`` as a float ``(H, W, C)`` array, ``C`` in {1, 3, 4}."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in _NAMES or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"an EXR image must be (H, W) or (H, W, 1|3|4), got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"an EXR image must be numeric, got dtype {a.dtype}")
    return a


def write_exr(path: str | os.PathLike, image, half: bool = False, compression: str = "zip",
              allow_nonfinite: bool = False) -> Path:
    """Write a linear image as a scanline EXR (lossless ``compression``), atomically.

    Parameters
    ----------
    path : path-like
        Destination ``.exr`` file; its folder must exist.
    image : array_like
        ``(H, W)`` or ``(H, W, C)`` with ``C`` = 1, 3 or 4 (Y, RGB, RGBA).
    half : bool
        Store 16-bit half floats instead of 32-bit floats.
    compression : str
        A name in :data:`COMPRESSIONS`.
    allow_nonfinite : bool
        Write NaN/inf samples (and values beyond the float32/half range, which become inf)
        instead of raising ``ValueError``, as :func:`read_exr` reads them only when asked.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import numpy as np
    >>> write_exr("ramp.exr", np.linspace(0, 1, 8).reshape(2, 4), compression="piz").name
    'ramp.exr'
    >>> read_exr("ramp.exr").shape
    (2, 4, 1)
    """
    with np.errstate(over="ignore"):                 # overflow to inf: counted below
        a = _as_channels(image).astype(np.float16 if half else np.float32)
    bad = np.count_nonzero(~np.isfinite(a))
    if bad and not allow_nonfinite:
        raise ValueError(f"{path}: {bad} NaN or infinite values (after conversion to "
                         f"{'half' if half else 'float32'}); nothing written (allow_nonfinite=True writes them)")
    channels = {name: np.ascontiguousarray(a[..., c]) for c, name in enumerate(_NAMES[a.shape[2]])}
    header = {"compression": exr_compression(compression), "type": OpenEXR.scanlineimage}
    with exr_write_errors(path), atomic_path(path) as tmp, exr_threads():
        OpenEXR.File(header, channels).write(str(tmp))
    return Path(path)


def check_exr_magic(path: Path, kind: str = "an OpenEXR file") -> None:
    """Raise :class:`MicrofacetError` "``path``: not ``kind``" unless ``path`` starts with :data:`EXR_MAGIC`.

    Parameters
    ----------
    path : Path
        The file.
    kind : str
        What the file should be, for the message.

    Examples
    --------
    >>> from pathlib import Path
    >>> _ = Path("not.exr").write_text("text")
    >>> check_exr_magic(Path("not.exr"))
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: not.exr: not an OpenEXR file (bad magic number 74657874)
    """
    magic = read_bytes(path, kind, 4)
    if magic != EXR_MAGIC:
        raise MicrofacetError(f"{path}: not {kind} (bad magic number {magic.hex() or 'empty'})")


def read_exr(path: str | os.PathLike, allow_nonfinite: bool = False) -> np.ndarray:
    """Read the first part of an EXR file as a float64 ``(H, W, C)`` array.

    ``C`` is 1 for a luminance (``Y``) image, 3 for ``R, G, B`` and 4 when an ``A``
    channel is present as well.

    Parameters
    ----------
    path : str or os.PathLike
        The EXR file.
    allow_nonfinite : bool
        Accept NaN and inf samples.

    Returns
    -------
    (H, W, C) ndarray
        Float64 samples.

    Raises
    ------
    MicrofacetError
        If the file is missing, not an EXR (magic number), unreadable or truncated (OpenEXR's
        own messages are not printed: :func:`exr_read_errors`), too large for this machine's
        memory (the size is read from its header first), has
        neither ``R, G, B`` nor ``Y`` channels, or holds NaN/inf (unless ``allow_nonfinite``).
        The message names the file and the problem.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.random.default_rng(0).random((4, 6, 3))
    >>> _ = write_exr("image.exr", image)
    >>> bool(np.array_equal(read_exr("image.exr"), image.astype(np.float32)))   # float32 storage
    True
    """
    path = Path(path)
    check_exr_magic(path)
    _check_size(path, read_headers(path)[:1])
    with exr_read_errors(path), exr_threads():
        channels = OpenEXR.File(str(path), separate_channels=True).channels()
        pixels = {name: np.asarray(ch.pixels) for name, ch in channels.items()}
    names = next((n for n in (_NAMES[4], _NAMES[3], _NAMES[1]) if set(n) <= set(pixels)), None)
    if names is None:
        raise MicrofacetError(f"{path}: needs R, G, B or Y channels, found {sorted(pixels) or 'none'}")
    shapes = {pixels[n].shape for n in names}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise MicrofacetError(f"{path}: channels {names} have unusable shapes {sorted(shapes)} (subsampled?)")
    image = np.stack([pixels[n].astype(np.float64) for n in names], axis=-1)
    bad = ~np.isfinite(image)
    if bad.any() and not allow_nonfinite:
        raise MicrofacetError(f"{path}: {int(bad.sum())} NaN or infinite values")
    return image
