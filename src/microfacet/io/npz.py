"""Reading ``.npz`` archives written by microfacet, with errors that name the file."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .read import read_bytes

__all__ = ["load_npz", "ZIP_MAGIC"]

#: First bytes of a zip archive (``.npz``): a local file header, or the end record of an empty one.
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def load_npz(path: str | os.PathLike, kind: str) -> dict[str, np.ndarray]:
    """All arrays of the ``.npz`` archive ``path``, read without pickle.

    ``kind`` says what the file should be (e.g. ``"a microfacet fit file"``). Anything
    that is not a readable archive of plain arrays (a missing file, other bytes, a
    truncated or corrupt archive, object arrays) raises :class:`MicrofacetError`
    naming the file and saying that it is not ``kind`` (never NumPy's "pickled data ...
    allow_pickle" message, which describes how it tried to read it)."""
    path = Path(path)
    head = read_bytes(path, kind, 4)
    if head not in ZIP_MAGIC:
        raise MicrofacetError(f"{path}: not {kind} (not a .npz archive: starts with "
                              f"{head.hex() or 'nothing, empty file'})")
    try:
        with np.load(path, allow_pickle=False) as z:
            return {name: z[name] for name in z.files}
    except Exception as e:    # zipfile, zlib, EOFError, ValueError of np.load on corrupt archives
        why = "holds object arrays" if "pickle" in str(e) else f"{type(e).__name__}: {e}"
        raise MicrofacetError(f"{path}: not {kind} (corrupt .npz archive: {why})") from None
