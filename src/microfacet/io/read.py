"""Reading input files with errors that name the file and say what is wrong."""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import MicrofacetError

__all__ = ["read_bytes"]


def read_bytes(path: str | os.PathLike, kind: str, size: int | None = None) -> bytes:
    """The first ``size`` bytes of ``path`` (all of it if ``None``); a missing file, a folder
    or an unreadable file raises :class:`MicrofacetError` naming it (``kind``: what was
    expected, e.g. ``"a PNG file"``)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            return f.read() if size is None else f.read(size)
    except FileNotFoundError:
        raise MicrofacetError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise MicrofacetError(f"{path}: is a directory, not {kind}") from None
    except OSError as e:
        raise MicrofacetError(f"{path}: cannot read ({e.strerror or e})") from None
