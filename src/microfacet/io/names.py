"""The name of an input file without its data suffixes: the stem every command's outputs take.

``nickel.binary.gz`` -> ``nickel`` (a measured material), ``h.png`` -> ``h`` (a map),
``fit.npz`` -> ``fit``. Used by the CLI's output rule, batches and fits alike.

Examples
--------
>>> from microfacet.io.names import MEASURED_SUFFIXES, DATA_SUFFIXES
>>> MEASURED_SUFFIXES[:3], DATA_SUFFIXES
(('.binary.gz', '.bsdf.gz', '.bin.gz'), ('.png', '.exr', '.npz'))
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["material_name", "input_name", "MEASURED_SUFFIXES", "DATA_SUFFIXES"]

#: Measured-BRDF file suffixes (longest first), dropped by :func:`material_name`.
MEASURED_SUFFIXES = (".binary.gz", ".bsdf.gz", ".bin.gz", ".binary", ".bsdf", ".bin", ".gz")
#: Map and result suffixes dropped by :func:`input_name` as well.
DATA_SUFFIXES = (".png", ".exr", ".npz")


def material_name(path: str | os.PathLike) -> str:
    """File name without its measured-BRDF suffix: ``nickel.binary.gz`` -> ``nickel``.

    Parameters
    ----------
    path : str or os.PathLike
        A measured-BRDF file path.

    Returns
    -------
    str
        The name.

    Examples
    --------
    >>> material_name("data/merl/nickel.binary.gz"), material_name("ibiza.bsdf")
    ('nickel', 'ibiza')
    """
    name = Path(path).name
    for suffix in MEASURED_SUFFIXES:
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def input_name(source: str | os.PathLike) -> str:
    """A file's name without its data suffixes: ``nickel.binary.gz`` -> ``nickel``, ``h.png`` -> ``h``.

    Parameters
    ----------
    source : str or os.PathLike
        A file path.

    Returns
    -------
    str
        The name.

    Examples
    --------
    >>> input_name("nickel.binary.gz"), input_name("maps/height.png"), input_name("fit.npz")
    ('nickel', 'height', 'fit')
    """
    name = material_name(source)
    return name.rsplit(".", 1)[0] if Path(name).suffix.lower() in DATA_SUFFIXES else name
