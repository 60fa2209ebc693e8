"""Pure per-file tasks of a batch: ``bake`` (LEAN/LEADR moment pyramid), ``glints`` (glint
microsurface) and ``fit`` (measured BRDF fit).

A task reads one input file and writes its outputs (a main output and side outputs with
the same stem), each atomically (:mod:`microfacet.io.atomic`); it returns the figures of
its summary row. It has no other effect, so it can run in any process or on any machine
that sees the files, any number of times: the outputs are the same bytes every time.

Examples
--------
>>> sorted(TASKS), PLAUSIBLE_ALPHA, SUGGESTED_ALPHA
(['bake', 'fit', 'glints'], 4.0, 0.2)
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import inspect
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._background import in_background
from ..errors import MicrofacetError
from ..io.names import input_name
from ..io.read import MEASURED_BRDF, read_decompressed

__all__ = ["Task", "TASKS", "get_task", "bake_file", "glints_file", "fit_file", "image_pixels",
           "slope_scale_warning", "PLAUSIBLE_ALPHA", "SUGGESTED_ALPHA"]

#: Peak resident memory of a task in a worker process: a fixed part (interpreter, NumPy,
#: SciPy, OpenEXR, Numba, matplotlib) plus bytes per input pixel, the least-squares line
#: through peaks measured in fresh processes (``python benchmarks/bench_batch.py
#: --memory``: bake 216/243/327/750 MB at 512^2/1024^2/2048^2/4096^2 -> 34.0 B/px +
#: 204 MB; glints 172/190/235 MB at 256^2/512^2/1024^2 -> 65.9 B/px + 170 MB), rounded up.
WORKER_BYTES = 220e6
BAKE_BYTES_PER_PIXEL = 36.0
GLINTS_BYTES_PER_PIXEL = 70.0
#: Peak of one fit, fixed-size inputs (measured: 315 MB for MERL nickel, 216 MB for an
#: RGL file, isotropic N = 90), with a margin.
FIT_PEAK_BYTES = 400e6


def image_pixels(path: str | os.PathLike) -> int:
    """Pixels of a PNG (its IHDR chunk) or EXR (its header), without decoding the image;
    for another or an unreadable file, its size in bytes (an upper bound for a PNG).

    Parameters
    ----------
    path : str or path-like
        An image file.

    Returns
    -------
    int
        Width times height for a PNG or EXR; else the file's size in bytes (0 when it
        cannot be read).

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.io import write_png_data
    >>> image_pixels(write_png_data("tile.png", np.zeros((16, 8), np.uint8)))
    128
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(24)
        if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
            return int.from_bytes(head[16:20], "big") * int.from_bytes(head[20:24], "big")
        if head[:4] == b"\x76\x2f\x31\x01":
            from ..io.exr import read_headers           # quiet: OpenEXR's messages are captured
            x0, x1 = np.asarray(read_headers(path)[0]["dataWindow"])
            return int(np.prod(x1 - x0 + 1))
        return path.stat().st_size
    except Exception:       # the task itself reports unreadable files
        return 0


@dataclasses.dataclass(frozen=True)
class Task:
    """A per-file task with its options.

    ``function(source, out, **options) -> dict`` writes ``out`` (suffix ``suffixes[0]``)
    and its side outputs ``out.with_suffix(s)`` for ``s`` in ``suffixes[1:]`` and returns
    the figures named by ``columns``. ``inputs`` are the input suffixes it takes from a
    folder (``()``: every file). ``peak(source)`` estimates its peak memory in bytes.

    Parameters
    ----------
    name : str
        The task's name (``bake``, ``glints``, ``fit``).
    function : callable
        ``function(source, out, **options) -> dict`` processing one file.
    suffixes : tuple of str
        Suffix of the main output, then of the side outputs.
    inputs : tuple of str
        Lower-case input suffixes taken from a folder; ``()``: every file.
    columns : tuple of str
        Names of the figures ``function`` returns (summary columns).
    peak : callable
        ``peak(source) -> float``: estimated peak memory in bytes for one file.
    options : tuple of (str, object) pairs, optional
        Keyword arguments given to ``function``, sorted by name (default none).

    Examples
    --------
    >>> task = get_task("bake", scale=0.02)
    >>> task.name, task.suffixes, task.inputs, task.options
    ('bake', ('.exr', '.png'), ('.png', '.exr'), (('scale', 0.02),))
    >>> task.with_options(roughness=0.1).options
    (('roughness', 0.1), ('scale', 0.02))
    """
    name: str
    function: Callable[..., dict]
    suffixes: tuple[str, ...]
    inputs: tuple[str, ...]
    columns: tuple[str, ...]
    peak: Callable[[Path], float]
    options: tuple[tuple[str, object], ...] = ()

    def with_options(self, **options) -> "Task":
        """This task with ``options`` (keyword arguments of its function) set.

        Parameters
        ----------
        **options
            Keyword arguments of the task's function; they override those already set.

        Returns
        -------
        Task
            A new task (this one is unchanged).
        """
        known = [p for p in inspect.signature(self.function).parameters][2:]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(f"{self.name}: unknown option(s) {', '.join(unknown)} (known: {', '.join(known)})")
        return dataclasses.replace(self, options=tuple(sorted({**dict(self.options), **options}.items())))

    def option_names(self) -> list[str]:
        """Keyword arguments of the task's function.

        Returns
        -------
        list of str
            The names of the function's parameters after ``source`` and ``out``.
        """
        return list(inspect.signature(self.function).parameters)[2:]

    def accepts(self, path: Path) -> bool:
        """Whether a folder's file ``path`` is an input of this task.

        Parameters
        ----------
        path : Path
            A file found in an input folder.

        Returns
        -------
        bool
            ``True`` when its suffix is one of :attr:`inputs` (or :attr:`inputs` is empty).
        """
        return not self.inputs or path.suffix.lower() in self.inputs

    def outputs(self, out: Path) -> list[Path]:
        """The files written for the main output ``out``.

        Parameters
        ----------
        out : Path
            The main output (suffix ``suffixes[0]``).

        Returns
        -------
        list of Path
            ``out`` followed by its side outputs (``out.with_suffix(s)``).
        """
        return [out, *(out.with_suffix(s) for s in self.suffixes[1:])]

    def __call__(self, source: Path, out: Path) -> dict:
        return self.function(Path(source), Path(out), **dict(self.options))


# ---------------------------------------------------------------------------- bake
#: Largest Beckmann roughness a height map's slopes plausibly have over the whole map: alpha 4
#: is an RMS facet slope of 2.8 (70 degrees) per axis, steeper than any material's
#: microgeometry; beyond it the preview and viewer are black and the heights are most likely
#: in another unit than the map's width (pixels, millimetres), i.e. ``--scale`` is wrong.
PLAUSIBLE_ALPHA = 4.0
#: The roughness that the ``--scale`` suggested by :func:`slope_scale_warning` gives.
SUGGESTED_ALPHA = 0.2


def slope_scale_warning(source, top, scale: float, base=None) -> str | None:
    """The warning for a height map baked at an implausible ``scale``, or ``None``.

    ``top`` are the moments ``E1..E5`` of the pyramid's top level (the whole map), ``base``
    the base roughness merged into them (:func:`microfacet.leadr.base_moments`'s argument).
    The slopes' own roughness is ``alpha = sqrt(2 max(var_x, var_y))`` of the top level less
    the base's variances (thesis Eq. 3.5-3.9); above :data:`PLAUSIBLE_ALPHA` the message gives
    the scale that makes it :data:`SUGGESTED_ALPHA` (slopes scale linearly with ``scale``),
    to one significant digit.

    Parameters
    ----------
    source : str or Path
        The height map, named in the message.
    top : array-like, shape (5,)
        Moments ``E1..E5`` of the pyramid's top level.
    scale : float
        The height scale the map was baked at.
    base : optional
        The base roughness merged into the moments (as given to
        :func:`microfacet.leadr.base_moments`); ``None``: none.

    Returns
    -------
    str or None
        The warning message, or ``None`` when the roughness is plausible.

    References
    ----------
    Dupuy 2015, thesis, Eq. 3.5-3.9.

    Examples
    --------
    >>> from microfacet.leadr import to_moments
    >>> slope_scale_warning("h.exr", to_moments(26.4, 2.1), 1.0)
    "h.exr: at --scale 1 the heights' slopes have roughness alpha 26.4 (above 4: facets steeper than 70 degrees, a black preview; are the heights in another unit than the map's width?); --scale 0.008 gives alpha ~0.2"
    >>> slope_scale_warning("h.exr", to_moments(0.3, 0.2), 1.0) is None
    True
    """
    from ..leadr import base_moments
    E = np.asarray(top, dtype=np.float64).reshape(5)
    var = np.array([E[2] - E[0] ** 2, E[3] - E[1] ** 2])
    b = base_moments(base)
    if b is not None:
        var -= np.array([b[2] - b[0] ** 2, b[3] - b[1] ** 2])
    alpha = float(np.sqrt(2.0 * max(float(var.max()), 0.0)))
    if not alpha > PLAUSIBLE_ALPHA or scale == 0:
        return None
    suggested = float(f"{scale * SUGGESTED_ALPHA / alpha:.1g}")
    return (f"{source}: at --scale {scale:g} the heights' slopes have roughness alpha {alpha:.4g} (above "
            f"{PLAUSIBLE_ALPHA:g}: facets steeper than 70 degrees, a black preview; are the heights in another "
            f"unit than the map's width?); --scale {suggested:g} gives alpha ~{SUGGESTED_ALPHA:g}")


def bake_file(source: Path, out: Path, scale: float = 1.0, normal_map: bool = False, border: str = "wrap",
              roughness: float | None = None, material: str | os.PathLike | None = None,
              encoding: str = "auto", z: str = "auto", compression: str = "none") -> dict:
    """``microfacet bake``: a height (or normal) map's LEAN/LEADR moment pyramid
    (E1..E5, thesis Eq. 3.5-3.9, merged with a base roughness by Listing 5.1) as
    ``out`` (.exr, lossless ``compression``, see ``leadr.write_pyramid``) and its filtered-appearance preview ``out.png``. Returns the size, the
    number of MIP levels and the top level's Beckmann lobe.

    Parameters
    ----------
    source : pathlib.Path
        A height map (PNG, 8/16-bit, or EXR), or a normal map with ``normal_map``.
    out : pathlib.Path
        The pyramid's ``.exr``; the preview is written as ``out.with_suffix(".png")``.
    scale : float
        Height scale (:func:`microfacet.leadr.bake`; integer heights are first divided by their
        type's largest value); for a normal map, the factor of its slopes.
    normal_map : bool
        ``source`` is a tangent-space normal map (decoded with ``encoding`` and ``z``,
        :func:`microfacet.leadr.decode_normal_map`).
    border : {"wrap", "clamp"}
        Central differences at the edges of a height map.
    roughness : float, optional
        Base roughness merged into every texel.
    material : str or PathLike, optional
        A fit file whose Beckmann conversion is the base lobe instead (``fit.load(...).to_beckmann()``).
    encoding, z : str
        Normal-map decoding.
    compression : str
        Lossless EXR compression (:func:`microfacet.leadr.write_pyramid`).

    Returns
    -------
    dict
        ``width``, ``height``, ``levels`` and the top level's lobe: ``alpha_x``, ``alpha_y``,
        ``rho``, ``mean_x``, ``mean_y``.

    Raises
    ------
    MicrofacetError
        An unreadable map, or moments that overflow (naming ``source``); a
        :class:`~microfacet.errors.HeightMapWarning` for an implausible ``scale``
        (:func:`slope_scale_warning`).

    References
    ----------
    Dupuy 2015, thesis, Eq. 3.5-3.9, Listing 5.1; Dupuy et al. 2013.

    Examples
    --------
    >>> import numpy as np
    >>> from pathlib import Path
    >>> from microfacet.io import write_png_data
    >>> from microfacet.leadr import gaussian_heightfield
    >>> h = gaussian_heightfield((16, 16), 0.3, seed=0)          # a 16 x 16 16-bit height map
    >>> _ = write_png_data("bumps.png", np.round((h - h.min()) / np.ptp(h) * 65535).astype(np.uint16))
    >>> row = bake_file(Path("bumps.png"), Path("bumps.exr"), scale=0.05)
    >>> row["width"], row["levels"], round(row["alpha_x"], 3)
    (16, 5, 0.088)
    """
    from ..io.image import read_image
    reading = None if normal_map else in_background(read_image, source)   # the decode overlaps the imports
    from .. import leadr
    from ..io import write_png
    from ..leadr.files import height_levels
    from ..leadr.preview import preview_image
    base = roughness
    if material is not None:
        from ..fit import load
        base = load(material).to_beckmann()
    with contextlib.ExitStack() as files:
        storage = None
        try:
            if normal_map:
                pyramid = leadr.mip_pyramid(leadr.normal_map_to_moments(source, base, scale, encoding=encoding, z=z))
            else:
                levels, top = height_levels(reading.result(), source)
                if compression == "none" and sys.byteorder == "little":   # baked into the file (pyramid_file)
                    storage = files.enter_context(leadr.pyramid_file(out, *levels.shape[:2]))
                pyramid = leadr.bake(levels, scale / top, base, border=border, out=storage)
        except ValueError as e:
            raise MicrofacetError(f"{source}: {e}") from None
        preview = preview_image(pyramid)              # before the pyramid is written: a failure leaves no file
        if storage is None:
            leadr.write_pyramid(out, pyramid, compression=compression)
    try:
        write_png(out.with_suffix(".png"), preview)
    except BaseException:                             # Ctrl-C, a full disk: no pyramid without its preview
        out.unlink(missing_ok=True)
        raise
    lobe = leadr.from_moments(pyramid[-1][0, 0])
    if not normal_map:
        message = slope_scale_warning(source, pyramid[-1][0, 0], scale, base)
        if message:
            import warnings
            from ..errors import HeightMapWarning
            warnings.warn(message, HeightMapWarning, stacklevel=2)
    h, w = pyramid[0].shape[:2]
    return {"width": w, "height": h, "levels": len(pyramid), "alpha_x": float(lobe.alpha_x),
            "alpha_y": float(lobe.alpha_y), "rho": float(lobe.rho), "mean_x": float(lobe.xn),
            "mean_y": float(lobe.yn)}


# -------------------------------------------------------------------------- glints
def glints_file(source: Path, out: Path, spacing: float = 1.0, sigma_eps: float = 0.01,
                encoding: str = "auto", z: str = "auto") -> dict:
    """``microfacet glints``: a normal map's Beckmann lobe mixture and hierarchy
    (Chermain et al. 2019, Eq. 3-6, Sec. 4.2.2, 5) as ``out`` (.npz). Returns the lobe
    count, map size, MIP levels and the lobes' median and largest roughness.

    Parameters
    ----------
    source : pathlib.Path
        A tangent-space normal map (PNG or EXR).
    out : pathlib.Path
        The microsurface's ``.npz``.
    spacing : float
        Spacing of the lobes' grid in texels (``h``, :class:`microfacet.glints.Microsurface`).
    sigma_eps : float
        Smallest standard deviation of a lobe's slopes (Chermain et al. 2019, Sec. 3.2).
    encoding, z : str
        Normal-map decoding (:func:`microfacet.leadr.decode_normal_map`).

    Returns
    -------
    dict
        ``width``, ``height``, ``lobes``, ``levels``, ``alpha_median``, ``alpha_max``.

    References
    ----------
    Chermain et al. 2019, Eq. 3-6, Sec. 4.2.2, 5.

    Examples
    --------
    >>> import numpy as np
    >>> from pathlib import Path
    >>> from microfacet.leadr import encode_normal_map, gaussian_heightfield, height_to_slopes, write_normal_map
    >>> slopes = height_to_slopes(gaussian_heightfield((16, 16), 0.3, seed=0))
    >>> _ = write_normal_map("normals.png", encode_normal_map(slopes))     # a 16 x 16 normal map
    >>> row = glints_file(Path("normals.png"), Path("normals.npz"))
    >>> row["lobes"], row["levels"]
    (256, 5)
    """
    from ..glints import Microsurface
    ms = Microsurface.from_normal_map(source, h=spacing, sigma_eps=sigma_eps, encoding=encoding, z=z)
    ms.save(out)
    median, largest = ms.alpha_summary()
    return {"width": ms.resolution[1], "height": ms.resolution[0], "lobes": ms.n_lobes,
            "levels": len(ms.mip), "alpha_median": median, "alpha_max": largest}


# ----------------------------------------------------------------------------- fit
#: The fit's summary figures (:data:`microfacet.fit.outputs.SUMMARY_COLUMNS` less the
#: row's own ``file``/``status``/``seconds``; ``fit_seconds`` is the fit time alone).
FIT_COLUMNS = ("material", "format", "fit_seconds", "method",
               *(f"{m}_{k}" for m in ("error", "uniform", "albedo") for k in ("tabulated", "ggx", "beckmann")),
               "error_ggx_moments", "ggx_alpha_x", "ggx_alpha_y", "ggx_rho", "ggx_diffuse",
               "beckmann_alpha_x", "beckmann_alpha_y", "beckmann_rho", "beckmann_diffuse")


def fit_file(source: Path, out: Path, resolution: int = 90, anisotropic: bool = False, gaf: str = "smith",
             method: str = "least_squares", diffuse: str = "auto", fresnel: str = "table",
             albedo_weight: float | None = None, coat: bool = False, picture: bool = True,
             curves: bool = False) -> dict:
    """``microfacet fit``: a measured BRDF's power-iteration fit (thesis Ch. 4) and its
    least-squares GGX and Beckmann fits as ``out`` (.npz) with ``out.json`` and ``out.png``
    (:func:`microfacet.fit.outputs.fit_material`; no picture with ``picture=False``).
    Returns the summary figures.

    Parameters
    ----------
    source : pathlib.Path
        A measured BRDF file (MERL, RGL or UTIA, :func:`microfacet.measured.load`).
    out : pathlib.Path
        The fit file (``.npz``); ``.json`` and ``.png`` are written beside it.
    resolution, anisotropic, gaf, method, diffuse, fresnel, albedo_weight, coat, picture, curves
        As :func:`microfacet.fit.outputs.fit_material`.

    Returns
    -------
    dict
        The summary figures of the fit (the ``fit`` task's columns).

    References
    ----------
    Dupuy 2015, thesis, Ch. 4; Dupuy et al. 2015.

    Examples
    --------
    >>> from pathlib import Path
    >>> row = fit_file(Path("gold.binary"), Path("gold.npz"), resolution=32)   # needs a MERL file, ~3 s  # doctest: +SKIP
    >>> sorted(row)[:3]                                                          # doctest: +SKIP
    ['albedo_beckmann', 'albedo_ggx', 'albedo_tabulated']
    """
    reading = in_background(read_decompressed, source, MEASURED_BRDF)   # read + gunzip (GIL released) overlap the imports
    from ..fit.outputs import fit_material, summary_row
    from ..measured import load_bytes
    brdf = load_bytes(reading.result(), source)
    name = input_name(source)
    summary = fit_material(brdf, out, resolution, anisotropic, gaf, title=name, method=method, diffuse=diffuse,
                           fresnel=fresnel, albedo_weight=albedo_weight, coat=coat, picture=picture,
                           curves=curves)
    row = summary_row(name, source, getattr(brdf, "format", ""), summary)
    row["fit_seconds"] = row["seconds"]
    return {k: row[k] for k in FIT_COLUMNS}


def map_peak(source: Path, bytes_per_pixel: float) -> float:
    """Estimated peak memory of a map task: :data:`WORKER_BYTES` + ``bytes_per_pixel`` x pixels."""
    return WORKER_BYTES + bytes_per_pixel * image_pixels(source)


def fit_peak(source: Path) -> float:
    """Estimated peak memory of a fit: :data:`FIT_PEAK_BYTES` (inputs have a fixed size)."""
    return FIT_PEAK_BYTES


TASKS = {
    "bake": Task("bake", bake_file, (".exr", ".png"), (".png", ".exr"),
                 ("width", "height", "levels", "alpha_x", "alpha_y", "rho", "mean_x", "mean_y"),
                 functools.partial(map_peak, bytes_per_pixel=BAKE_BYTES_PER_PIXEL)),
    "glints": Task("glints", glints_file, (".npz",), (".png", ".exr"),
                   ("width", "height", "lobes", "levels", "alpha_median", "alpha_max"),
                   functools.partial(map_peak, bytes_per_pixel=GLINTS_BYTES_PER_PIXEL)),
    "fit": Task("fit", fit_file, (".npz", ".json", ".png"), (), FIT_COLUMNS, fit_peak),
}


def get_task(task: "str | Task", **options) -> Task:
    """The task named ``task`` (``bake``, ``glints``, ``fit``) or ``task`` itself, with ``options``.

    Parameters
    ----------
    task : str or Task
        A name of :data:`TASKS` or a task.
    **options
        Keyword arguments of the task's function to set.

    Returns
    -------
    Task
        The task with ``options``.

    Examples
    --------
    >>> get_task("glints").columns
    ('width', 'height', 'lobes', 'levels', 'alpha_median', 'alpha_max')
    >>> get_task("render")
    Traceback (most recent call last):
        ...
    ValueError: unknown batch task 'render' (known: bake, glints, fit)
    """
    if isinstance(task, str):
        if task not in TASKS:
            raise ValueError(f"unknown batch task {task!r} (known: {', '.join(TASKS)})")
        task = TASKS[task]
    return task.with_options(**options) if options else task
