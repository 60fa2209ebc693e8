"""Comparison picture of a BRDF (e.g. measured data) and its fits.

One PNG, Matplotlib's object API on the Agg canvas (no pyplot state, no display):

* bottom left: backscattering ``f_r(k, k)`` against ``theta_k`` (log scale), the quantity
  the power-iteration fit of thesis Ch. 4 starts from (Eq. 4.4-4.6);
* bottom right: in-plane slices ``f_r(wi, wo) cos theta_i`` against signed ``theta_i`` for a
  few view angles ``theta_o`` (the view at ``-theta_o``, as in :mod:`.lobes`), log scale
  so that peaks and the diffuse floor both show;
* top: the BRDFs on orthographic spheres (``size`` px, 192 by default, shown pixel for
  pixel) under a directional light 35 deg from the view (:data:`COMPARE_LIGHT`) and, in a
  second row, under a grazing light 75 deg from the view (:data:`GRAZING_LIGHT`): the same
  exposure for all spheres of a row, set by the first BRDF's 99.5th-percentile pixel; an
  optional note (e.g. fit errors) under each column;

Colour BRDFs are plotted as luminance (Rec. 709 weights). The first BRDF is the
reference (black); one legend below the plots names every colour. The grazing region
``cos theta < 0.1`` that fit errors exclude (:data:`microfacet.metrics.GRAZING_COS`) is
shaded grey. The figure is laid out in pixels (column width at least ``size + 40`` px), so
labels, notes and legends never overlap, whatever the number of BRDFs (3-5 typical).

Examples
--------
>>> from microfacet.render.compare import COMPARE_LIGHT, GRAZING_LIGHT
>>> COMPARE_LIGHT.direction, [round(float(c), 4) for c in GRAZING_LIGHT.direction]
((-0.5, 0.5, 1.0), [0.9659, 0.0, 0.2588])
"""
from __future__ import annotations

import gc
import io
import os
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..geometry import spherical_to_cartesian
from ..io import to_srgb8, write_bytes
from ..metrics import GRAZING_COS
from .lights import DirectionalLight
from .lobes import LUMINANCE, lobe_curve
from .sphere import Sphere

__all__ = ["backscattering_curve", "render_sphere", "save_fit_comparison", "fit_comparison_png", "fit_spheres_png",
           "warm_up",
           "COMPARE_LIGHT", "GRAZING_LIGHT"]

#: Light of the comparison spheres: up-left of the view, 35 deg from it, unit irradiance.
COMPARE_LIGHT = DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=1.0)
#: Second light of the comparison spheres: from the right, 75 deg from the view.
GRAZING_LIGHT = DirectionalLight(direction=(np.sin(np.radians(75.0)), 0.0, np.cos(np.radians(75.0))), irradiance=1.0)
#: Default side of the comparison spheres, pixels.
SPHERE_SIZE = 192
_COLOURS = ("black", "#1f77b4", "#2ca02c", "#ff7f0e", "#d62728", "#9467bd")
_VIEW_STYLES = ("-", "--", ":", "-.")
_GRAZING_DEG = float(np.degrees(np.arccos(GRAZING_COS)))
#: Axes titles at the top of their axes, where Matplotlib's automatic placement puts them
#: here (no ticks or labels above any axes): given explicitly, it skips measuring every
#: tick label again at drawing time (~40 % of the drawing, the same pixels; tested).
_TITLE_Y = 1.0
#: Gap between a sphere and its label above, points (Matplotlib's ``axes.titlepad``).
_LABEL_PAD_PT = 6.0
#: Ticks of the curves: length and label gap (Matplotlib's defaults), label size, points.
_TICK_PT, _TICK_PAD_PT, _TICK_FONT = 3.5, 3.5, 7
#: Silhouette circle of the spheres: line width (points) and grey level (8-bit sRGB).
_SILHOUETTE_PT = 0.6
_SILHOUETTE_GREY = 0.35 * 255.0
#: Largest sphere size whose pixel geometry is kept between calls (:func:`_directions`).
_CACHED_SIZE = 512
#: zlib level of the PNG (Pillow's ``compress_level``; the picture is mostly flat colour).
_PNG_LEVEL = 1


def backscattering_curve(brdf, phi: float = 0.0, n: int = 200,
                         theta_max: float = np.radians(89.0)) -> tuple[np.ndarray, np.ndarray]:
    """``theta_k`` ``(n,)`` in ``[0, theta_max]`` and the luminance of ``f_r(k, k)`` for
    ``k`` at azimuth ``phi``.

    Parameters
    ----------
    brdf : BRDF
        The BRDF.
    phi : float
        Azimuth of the directions, radians.
    n : int
        Number of angles.
    theta_max : float
        Largest elevation, radians.

    Returns
    -------
    theta : (n,) ndarray
        Elevations, radians.
    luminance : (n,) ndarray
        Luminance of ``f_r(k, k)``.

    Examples
    --------
    >>> import microfacet as mf
    >>> theta, f = backscattering_curve(mf.Lambertian(1.0), n=3)
    >>> theta.round(3), (f * 3.141592653589793).round(6)             # f(k, k) of a white Lambertian: 1 / pi
    (array([0.   , 0.777, 1.553]), array([1., 1., 1.]))
    """
    theta = np.linspace(0.0, theta_max, n)
    k = spherical_to_cartesian(theta, np.full(n, phi))
    return theta, brdf.eval(k, k) @ LUMINANCE


def render_sphere(brdf, size: int, light: DirectionalLight = COMPARE_LIGHT) -> np.ndarray:
    """Linear RGB ``(size, size, 3)`` of ``brdf`` on an orthographic sphere under ``light``.

    Parameters
    ----------
    brdf : BRDF
        The BRDF.
    size : int
        Image width and height, pixels.
    light : DirectionalLight
        The light.

    Returns
    -------
    (size, size, 3) ndarray
        Linear RGB radiance (black background).

    Examples
    --------
    >>> import microfacet as mf
    >>> image = render_sphere(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), 64)
    >>> image.shape, float(image[0, 0].max())                       # black outside the sphere
    ((64, 64, 3), 0.0)
    """
    return _render_spheres(brdf, size, (light,))[0]


def _render_spheres(brdf, size: int, lights: Sequence[DirectionalLight]) -> list[np.ndarray]:
    """:func:`render_sphere` of ``brdf`` under each of ``lights`` (:func:`_sphere_pixels`)."""
    images = []
    for where, values in _sphere_pixels(brdf, size, lights):
        image = np.zeros((size * size, 3))                          # black background, as Sphere.image
        image[where] = values
        images.append(image.reshape(size, size, 3))
    return images


def _sphere_pixels(brdf, size: int, lights: Sequence[DirectionalLight]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per light of ``lights``, the flat indices of the pixels of the ``size`` px sphere it
    reaches and their linear RGB ``(M, 3)`` (:func:`render_sphere`'s values there; ``f_r``
    is 0 below the horizon: the other pixels are black), with one evaluation of ``brdf``
    for all the lights."""
    wo, wi, pixels = _directions(int(size), tuple(tuple(light.w) for light in lights))
    f_cos = brdf.eval_cos(wi, wo)
    out, start = [], 0
    for light, (where, coverage) in zip(lights, pixels):
        part = f_cos[start:start + len(where)]
        start += len(where)
        radiance = np.nan_to_num(np.asarray(light.rgb, dtype=np.float64) * part, nan=0.0, posinf=0.0, neginf=0.0)
        out.append((where, coverage * radiance))
    return out


def _directions(size: int, lights: tuple) -> tuple[np.ndarray, np.ndarray, list]:
    """Local view and light directions (read-only) of the pixels of the :class:`Sphere` of
    ``size`` px that each light direction (world) of ``lights`` reaches, one light after
    the other, and per light the pixels' flat indices and coverages ``(M, 1)``; kept for
    the last two sizes up to :data:`_CACHED_SIZE` (building the sphere costs more than
    shading it)."""
    return (_cached_directions if size <= _CACHED_SIZE else _new_directions)(size, lights)


def _new_directions(size: int, lights: tuple) -> tuple[np.ndarray, np.ndarray, list]:
    """:func:`_directions`, computed."""
    sphere = Sphere(size)
    flat = np.flatnonzero(sphere.mask)
    wo, wi, pixels = [], [], []
    for w in lights:
        local = sphere.to_local(w)
        lit = local[:, 2] > 0.0
        wo.append(sphere.wo[lit])
        wi.append(local[lit])
        pixels.append((flat[lit], sphere.coverage[lit][:, None]))
    wo, wi = np.concatenate(wo), np.concatenate(wi)
    for a in [wo, wi] + [a for pair in pixels for a in pair]:
        a.flags.writeable = False
    return wo, wi, pixels


_cached_directions = lru_cache(maxsize=2)(_new_directions)


def _positive(y: np.ndarray) -> np.ndarray:
    """``y`` with non-positive values masked (NaN), for log axes."""
    return np.where(y > 0, y, np.nan)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _log_ticks(ax) -> None:
    """Decade ticks on the log y axis of ``ax`` (its limits set, :func:`_ticks`): at most 6
    labelled decades (every decade, or every 2nd, 3rd, ...), the others unlabelled minor
    ticks, labels ``10⁻³`` in plain text (no mathtext)."""
    lo, hi = sorted(ax.get_ylim())
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):   # no positive value to show
        lo, hi = 1e-3, 1.0
        ax.set_ylim(lo, hi)
    decades = np.arange(np.ceil(np.log10(lo) - 1e-9), np.floor(np.log10(hi) + 1e-9) + 1).astype(int)
    stride = max(1, -(-len(decades) // 6))
    major = decades[(decades - decades[-1]) % stride == 0] if len(decades) else decades
    _ticks(ax, "y", 10.0 ** major, [f"10{str(e).translate(_SUPERSCRIPT)}" for e in major],
           10.0 ** np.setdiff1d(decades, major))


def _ticks(ax, which: str, major: Sequence[float], labels: Sequence[str], minor: Sequence[float] = ()) -> list:
    """Ticks of the ``which`` (``"x"``, ``"y"``) axis of ``ax`` at data positions ``major``
    (labelled) and ``minor``, drawn as Matplotlib's default outward ticks (major 3.5 pt
    long and 0.8 pt wide, minor 2 and 0.6 pt, 7 pt labels 3.5 pt beyond the marks) but as
    one marker line per kind and one text per label, instead of the Axis' ticks (four
    artists and a locator/formatter pass per tick: most of the drawing time here); the
    label texts."""
    from matplotlib.lines import Line2D
    from matplotlib.markers import TICKDOWN, TICKLEFT
    from matplotlib.ticker import NullLocator
    from matplotlib.transforms import offset_copy
    axis = ax.xaxis if which == "x" else ax.yaxis
    axis.set_major_locator(NullLocator())
    axis.set_minor_locator(NullLocator())
    along = ax.get_xaxis_transform() if which == "x" else ax.get_yaxis_transform()
    for where, size, width in ((major, _TICK_PT, 0.8), (minor, 2.0, 0.6)):
        if len(where):
            xy = (where, np.zeros(len(where)))
            ax.add_artist(Line2D(*(xy if which == "x" else xy[::-1]), linestyle="none", color="black",
                                 marker=TICKDOWN if which == "x" else TICKLEFT, markersize=size,
                                 markeredgewidth=width, transform=along, clip_on=False))
    pad = _TICK_PT + _TICK_PAD_PT
    if which == "x":
        at = offset_copy(along, fig=ax.figure, y=-pad, units="points")
        return [ax.text(x, 0.0, label, transform=at, ha="center", va="top", fontsize=_TICK_FONT, clip_on=False)
                for x, label in zip(major, labels)]
    at = offset_copy(along, fig=ax.figure, x=-pad, units="points")
    return [ax.text(0.0, y, label, transform=at, ha="right", va="center_baseline", fontsize=_TICK_FONT,
                    clip_on=False) for y, label in zip(major, labels)]


def _x_axis(ax, ticks: Sequence[int], label: str) -> None:
    """x ticks at ``ticks`` (degrees, labelled as Matplotlib's default formatter: Unicode
    minus) and the x label 4 pt under the tick labels, where Matplotlib puts it (their
    extents measured once, on the renderer that draws them, which keeps the measures)."""
    from matplotlib.transforms import offset_copy
    texts = _ticks(ax, "x", ticks, [f"{t:d}".replace("-", "\u2212") for t in ticks])
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    bottom = min(t.get_window_extent(renderer).y0 for t in texts)
    below = (ax.transAxes.transform((0.0, 0.0))[1] - bottom) * 72.0 / fig.dpi + 4.0
    ax.set_xlabel(label, fontsize=8)
    ax.xaxis.set_label_coords(0.5, 0.0, transform=offset_copy(ax.transAxes, fig=fig, y=-below, units="points"))


def _plot_backscattering(ax, brdfs: Mapping, planes_deg: Sequence[float]) -> None:
    """Log-scale curves; the y range follows the reference (first) curve: from 1/30 of its
    minimum (at most 8 decades below the top) to 3x the largest value of any curve
    outside the grazing region."""
    lo, hi = np.inf, 0.0
    for j, plane in enumerate(planes_deg):
        for k, (label, brdf) in enumerate(brdfs.items()):
            theta, f = backscattering_curve(brdf, np.radians(plane))
            inside = (np.degrees(theta) <= _GRAZING_DEG) & (f > 0) & np.isfinite(f)
            if np.any(inside):
                hi = max(hi, float(np.max(f[inside])))
                if k == 0:
                    lo = min(lo, float(np.min(f[inside])))
            ax.plot(np.degrees(theta), _positive(f), _VIEW_STYLES[j % len(_VIEW_STYLES)],
                    color=_COLOURS[k % len(_COLOURS)], lw=1.6 if k == 0 else 1.1,
                    label=f"φ = {plane:g}°" if k == 0 and len(planes_deg) > 1 else None)
    ax.set_yscale("log")
    if 0 < lo < np.inf and hi > 0:
        top = max(hi, lo) * 3.0
        ax.set_ylim(max(lo / 30.0, top * 1e-8), top)
    ax.axvspan(_GRAZING_DEG, 90.0, color="0.85", lw=0)
    ax.set_xlim(0, 90)
    _x_axis(ax, range(0, 91, 10), "θ (deg)")
    ax.set_title("backscattering f(k, k) (log)", fontsize=9, y=_TITLE_Y)
    if len(planes_deg) > 1:
        ax.legend(fontsize=7, frameon=True, framealpha=0.85, title="line style", title_fontsize=7,
                  loc="upper right")
    _log_ticks(ax)


def _plot_slices(ax, brdfs: Mapping, views_deg: Sequence[float]) -> None:
    """Log-scale slices over 6 decades below the highest non-grazing value of the data."""
    top = 0.0
    for j, view in enumerate(views_deg):
        for k, (label, brdf) in enumerate(brdfs.items()):
            theta_i, f = lobe_curve(brdf, np.radians(view), 0.0, n=361)
            inside = (np.abs(np.degrees(theta_i)) <= _GRAZING_DEG) & np.isfinite(f)
            if k == 0 and np.any(inside):
                top = max(top, float(np.max(f[inside])))
            ax.plot(np.degrees(theta_i), _positive(f), _VIEW_STYLES[j % len(_VIEW_STYLES)],
                    color=_COLOURS[k % len(_COLOURS)], lw=1.6 if k == 0 else 1.1,
                    label=f"θo = {view:g}°" if k == 0 else None)
    for side in (-1, 1):
        ax.axvspan(side * _GRAZING_DEG, side * 90.0, color="0.85", lw=0)
    ax.set_xlim(-90, 90)
    _x_axis(ax, range(-80, 81, 20), "θi (deg), view at −θo, plane φ = 0")
    ax.set_yscale("log")
    if top > 0:
        ax.set_ylim(top * 1e-6, top * 3.0)
    ax.set_title("in-plane f cos θi (log)", fontsize=9, y=_TITLE_Y)
    _log_ticks(ax)
    ax.legend(fontsize=7, frameon=True, framealpha=0.85, title="line style", title_fontsize=7, loc="lower center")


def save_fit_comparison(path: str | os.PathLike, brdfs: Mapping, title: str = "",
                        views_deg: Sequence[float] = (0, 30, 60), planes_deg: Sequence[float] = (0,),
                        size: int = SPHERE_SIZE, dpi: int = 100, notes: Mapping[str, str] | None = None) -> Path:
    """Write the comparison picture of :func:`fit_comparison_png` to ``path``, atomically;
    return ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file to write.
    brdfs, title, views_deg, planes_deg, size, dpi, notes
        As :func:`fit_comparison_png`.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> save_fit_comparison("comparison.png", {"data": data, "Beckmann": mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3))},
    ...                     title="GGX vs Beckmann", size=32).name
    'comparison.png'
    """
    return write_bytes(path, fit_comparison_png(brdfs, title, views_deg, planes_deg, size, dpi, notes))


def _exposure(image: np.ndarray) -> float:
    """Exposure (stops) putting the 99.5th-percentile luminance of ``image`` (linear RGB
    ``(..., 3)``: an image or some of its pixels; black ones do not count) at 1."""
    lum = image @ LUMINANCE
    top = float(np.percentile(lum[lum > 0], 99.5)) if np.any(lum > 0) else 1.0
    return float(np.log2(1.0 / top)) if np.isfinite(top) and top > 0 else 0.0


def fit_comparison_png(brdfs: Mapping, title: str = "", views_deg: Sequence[float] = (0, 30, 60),
                       planes_deg: Sequence[float] = (0,), size: int = SPHERE_SIZE, dpi: int = 100,
                       notes: Mapping[str, str] | None = None) -> bytes:
    """The comparison picture (module docstring) of ``brdfs`` as PNG bytes, in memory (so
    that a caller can render it before writing any of its files).

    Parameters
    ----------
    brdfs : mapping of str -> BRDF
        Label and BRDF, the reference (data) first, e.g. ``{"data": m, "best: lobe": best,
        "tabulated fit": fit, "ABC": abc}`` (any number; 3-5 read best).
    title : str
        Figure title (e.g. the material name).
    views_deg : sequence of float
        View angles of the in-plane slices.
    planes_deg : sequence of float
        Azimuths of the backscattering curves (e.g. ``(0, 90)`` for anisotropic data).
    size : int
        Side of each sphere image, pixels (shown pixel for pixel at ``dpi``).
    dpi : int
        Resolution of the PNG (the layout is in pixels at this resolution).
    notes : mapping of str -> str, optional
        Text under the spheres of a label (e.g. fit errors, a few short lines); labels
        not in ``brdfs`` are an error.

    Returns
    -------
    bytes
        The PNG file's content.

    Example
    -------
    >>> import microfacet as mf
    >>> png = fit_comparison_png({"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)),
    ...                           "fit": mf.MicrofacetBRDF(mf.GGX(alpha=0.25))}, "GGX", size=64)
    >>> png[:4] == b"\\x89PNG"
    True
    """
    with _drawing():
        return _png(_comparison_figure(brdfs, title, views_deg, planes_deg, size, dpi, notes))


def warm_up() -> None:
    """Import what :func:`fit_comparison_png` draws with and draw a small figure in its fonts:
    the first picture's fixed cost (Matplotlib's imports and font loading), paid here (e.g. on
    another thread while a fit runs) rather than in the first picture.

    Example
    -------
    >>> warm_up()
    """
    from matplotlib import artist, lines, markers, ticker, transforms  # noqa: F401  (the picture's modules)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from PIL import Image  # noqa: F401
    with _drawing():
        fig = Figure(figsize=(1.0, 0.5), dpi=50)
        FigureCanvasAgg(fig)
        for size in (7, 9, 11):
            fig.text(0.5, 0.5, "0.042 θ", fontsize=size)
        fig.add_axes((0.1, 0.1, 0.8, 0.8)).plot([0.0, 1.0])
        fig.canvas.draw()


@contextmanager
def _drawing():
    """Where the figure is built and drawn: unhinted glyphs (FreeType's hinting is most of
    the text's cost, the same legibility at these sizes), and Python's cyclic garbage
    collector off (as it was, after): Matplotlib's ~10^4 new objects otherwise set off a
    full collection of the caller's whole heap (~0.1 s after a fit); its cycles are
    collected later."""
    from matplotlib import rc_context
    was = gc.isenabled()
    gc.disable()
    try:
        with rc_context({"text.hinting": "no_hinting"}):
            yield
    finally:
        if was:
            gc.enable()


def _png(fig) -> bytes:
    """PNG bytes (8-bit RGB, no metadata) of ``fig`` drawn on its Agg canvas at its own dpi,
    encoded by Pillow at zlib level :data:`_PNG_LEVEL`."""
    from PIL import Image
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    rgb = np.empty(rgba.shape[:2] + (3,), dtype=np.uint8)
    for c in range(3):                                              # 5x faster than rgba[..., :3].copy()
        rgb[..., c] = rgba[..., c]
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG", compress_level=_PNG_LEVEL)
    return buf.getvalue()


def _silhouette(size: int, width: float) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Pixels ``(rows, columns)`` and coverage ``(M, 1)`` in ``(0, 1]`` of a circle of line
    ``width`` px through the edge of a ``size`` px square (centre at the square's centre,
    radius ``size / 2``): the box-filtered radial profile of the line, as Agg antialiases it."""
    i = np.arange(size) - (size - 1) / 2.0
    d = np.hypot(i[:, None], i[None, :])
    r = size / 2.0
    alpha = np.clip(np.minimum(d + 0.5, r + width / 2.0) - np.maximum(d - 0.5, r - width / 2.0), 0.0, 1.0)
    where = np.nonzero(alpha > 0)
    return where, alpha[where][:, None]


def _sphere_canvas(rows: Sequence[Sequence[tuple[np.ndarray, np.ndarray]]], exposures: Sequence[float],
                   size: int, xs: Sequence[int], row_step: int, line_px: float) -> np.ndarray:
    """One white ``uint8`` RGBA canvas with every sphere of ``size`` px (row ``r`` of ``rows``
    at ``r * row_step`` px from the top, column ``k`` at ``xs[k]`` px from the left; each
    sphere as :func:`_sphere_pixels` gives it) in sRGB at its row's exposure on black, each
    with its silhouette circle (:func:`_silhouette`, grey 0.35)."""
    canvas = np.full(((len(rows) - 1) * row_step + size, xs[-1] + size, 4), 255, dtype=np.uint8)
    ring, alpha = _silhouette(size, line_px)
    for r, (spheres, exposure) in enumerate(zip(rows, exposures)):
        for x, (where, values) in zip(xs, spheres):
            srgb = np.zeros((size * size, 3), dtype=np.uint8)
            srgb[where] = to_srgb8(values, exposure)
            srgb = srgb.reshape(size, size, 3)
            srgb[ring] = np.rint(srgb[ring] * (1.0 - alpha) + _SILHOUETTE_GREY * alpha).astype(np.uint8)
            canvas[r * row_step:r * row_step + size, x:x + size, :3] = srgb
    return canvas


@lru_cache(maxsize=None)
def _pixels_artist():
    """The Matplotlib artist class drawing an RGBA ``uint8`` image pixel for pixel at a
    pixel position of the figure: :class:`matplotlib.image.FigureImage` without its
    resampling pass (one blit)."""
    from matplotlib.artist import Artist

    class Pixels(Artist):
        def __init__(self, rgba: np.ndarray, x: int, y: int):
            super().__init__()
            # Agg's draw_image takes the bottom row first; y: of the bottom row, from below
            self.rgba, self.x, self.y = np.ascontiguousarray(rgba[::-1]), int(x), int(y)

        def draw(self, renderer):
            if self.get_visible():
                gc = renderer.new_gc()
                renderer.draw_image(gc, self.x, self.y, self.rgba)
                gc.restore()

    return Pixels


class _Spheres(NamedTuple):
    """The spheres of a comparison picture (its top part), laid out in pixels from the
    top-left (:func:`_spheres`): ``canvas`` (RGBA ``uint8``, every sphere; its top-left at
    ``(xs[0], title_h + label_h)``), the column of each label (``xs``: a sphere's left edge;
    ``left``, ``cell``: the columns' cells), the picture's ``width``, the heights of its
    title, labels and notes, ``bottom`` (where the spheres' part ends), the rows' exposures
    (stops), the labels' baseline ``label_y`` and the notes' top ``notes_y``; :meth:`label_x`
    and :meth:`note_x` centre a column's label and note."""
    canvas: np.ndarray
    labels: list
    notes: dict
    xs: list
    left: float
    cell: int
    width: int
    title_h: int
    label_h: int
    notes_h: int
    bottom: int
    exposures: list
    size: int
    label_y: float
    notes_y: int

    def label_x(self, k: int) -> float:
        """Centre of column ``k``'s label: its sphere's."""
        return self.xs[k] + self.size / 2.0

    def note_x(self, k: int) -> float:
        """Centre of column ``k``'s note: its cell's."""
        return self.left + (k + 0.5) * self.cell


def _spheres(brdfs: Mapping, title: str, size: int, notes: Mapping[str, str] | None, min_width: int,
             dpi: float) -> _Spheres:
    """:class:`_Spheres` of ``brdfs`` (each under :data:`COMPARE_LIGHT`, then
    :data:`GRAZING_LIGHT`; the same exposure in a row, set by the first BRDF's pixels), at
    least ``min_width`` px wide, its lengths in points (silhouettes, the labels' gap above
    the spheres) at ``dpi``; bad arguments raise ValueError."""
    if not brdfs:
        raise ValueError("save_fit_comparison needs at least one BRDF")
    if int(size) != size or size < 8:
        raise ValueError(f"size must be an integer >= 8, got {size!r}")
    size = int(size)
    notes = {k: str(v) for k, v in dict(notes or {}).items()}
    unknown = sorted(set(notes) - set(brdfs))
    if unknown:
        raise ValueError(f"save_fit_comparison: notes for labels not in brdfs: {unknown}")
    n = len(brdfs)
    rows = list(zip(*(_sphere_pixels(b, size, (COMPARE_LIGHT, GRAZING_LIGHT)) for b in brdfs.values())))
    exposures = [_exposure(spheres[0][1]) for spheres in rows]      # the black pixels do not count
    note_lines = max((v.count("\n") + 1 for v in notes.values()), default=0)
    cell = max(size + 40, 170)
    width = max(min_width, n * cell + 40)
    title_h, label_h, gap = (36 if title else 10), 22, 8
    notes_h = 13 * note_lines + (10 if note_lines else 0)
    left = (width - n * cell) / 2.0
    xs = [int(round(left + k * cell + (cell - size) / 2.0)) for k in range(n)]
    row_step = label_h + size + gap
    canvas = _sphere_canvas(rows, exposures, size, [x - xs[0] for x in xs], row_step, _SILHOUETTE_PT * dpi / 72.0)
    bottom = title_h + 2 * row_step + notes_h
    return _Spheres(canvas, list(brdfs), notes, xs, left, cell, width, title_h, label_h, notes_h, bottom, exposures,
                    size, title_h + label_h - _LABEL_PAD_PT * dpi / 72.0, bottom - notes_h + 4)


def _row_text(exposures: Sequence[float], sep: str = " ") -> str:
    """The text that says how the spheres are lit and exposed (``sep`` before its second half)."""
    return (f"spheres: light 35° from the view (top row, exposure {exposures[0]:+.2f} stops) and 75° "
            f"(bottom row, {exposures[1]:+.2f} stops),{sep}the same exposure for every sphere of a row")


@lru_cache(maxsize=None)
def _font(px: int):
    """DejaVu Sans of ``px`` pixels, the font of the Matplotlib pictures, read by Pillow from
    Matplotlib's data folder (found without importing Matplotlib); Pillow's own default font
    where that file is missing."""
    import importlib.util
    from PIL import ImageFont
    spec = importlib.util.find_spec("matplotlib")
    for root in (spec.submodule_search_locations or ()) if spec else ():
        path = os.path.join(root, "mpl-data", "fonts", "ttf", "DejaVuSans.ttf")
        if os.path.isfile(path):
            return ImageFont.truetype(path, px)
    return ImageFont.load_default(size=px)


def fit_spheres_png(brdfs: Mapping, title: str = "", size: int = SPHERE_SIZE,
                    notes: Mapping[str, str] | None = None) -> bytes:
    """The spheres of :func:`fit_comparison_png` without its curves, as PNG bytes: each BRDF
    under :data:`COMPARE_LIGHT` (top row) and :data:`GRAZING_LIGHT` (bottom row), the same
    exposure in a row, the same pixels, labels and notes, drawn by Pillow alone. It is the
    picture of ``microfacet fit``, whose ``--curves`` (:func:`fit_comparison_png`) cost
    Matplotlib's import and drawing, about 0.5 s of CPU (``benchmarks/results/fit_command.md``).

    Parameters
    ----------
    brdfs : mapping of str -> BRDF
        Label and BRDF, the reference (data) first; its pixels set each row's exposure.
    title : str
        Title above the spheres.
    size : int
        Side of each sphere image, pixels (at least 8).
    notes : mapping of str -> str, optional
        Text under the spheres of a label (a few short lines); labels not in ``brdfs`` are
        an error.

    Returns
    -------
    bytes
        The PNG file's content (8-bit RGB).

    Example
    -------
    >>> import io, microfacet as mf
    >>> from PIL import Image
    >>> png = fit_spheres_png({"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)),
    ...                        "fit": mf.MicrofacetBRDF(mf.GGX(alpha=0.25))}, "GGX", size=64, notes={"fit": "a note"})
    >>> Image.open(io.BytesIO(png)).size
    (600, 281)
    """
    from PIL import Image, ImageDraw
    dpi = 100.0                                      # the pixel sizes of fit_comparison_png's default
    part = _spheres(brdfs, title, size, notes, 600, dpi)
    footer_h = 34
    height = part.bottom + footer_h
    image = Image.new("RGB", (part.width, height), "white")
    image.paste(Image.fromarray(np.ascontiguousarray(part.canvas[..., :3])), (part.xs[0], part.title_h + part.label_h))
    draw = ImageDraw.Draw(image)
    if title:
        draw.text((part.width / 2.0, 8), title, font=_font(15), fill="black", anchor="ma")
    for k, label in enumerate(part.labels):
        draw.text((part.label_x(k), part.label_y), label, font=_font(13), fill=_COLOURS[k % len(_COLOURS)],
                  anchor="ms")
        if label in part.notes:
            draw.multiline_text((part.note_x(k), part.notes_y), part.notes[label], font=_font(10), fill="black",
                                anchor="ma", align="center", spacing=3)
    draw.multiline_text((part.width / 2.0, height - footer_h / 2.0), _row_text(part.exposures, "\n"), font=_font(10),
                        fill="black", anchor="mm", align="center", spacing=3)
    buf = io.BytesIO()
    image.save(buf, format="PNG", compress_level=_PNG_LEVEL)
    return buf.getvalue()


def _comparison_figure(brdfs: Mapping, title: str, views_deg: Sequence[float], planes_deg: Sequence[float],
                       size: int, dpi: int, notes: Mapping[str, str] | None):
    """The Matplotlib figure of :func:`fit_comparison_png` (Agg canvas attached): the
    spheres one image (:func:`_spheres`) placed pixel for pixel, texts on the figure,
    two Axes for the curves."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    part = _spheres(brdfs, title, size, notes, 900, dpi)
    n, width, labels, notes = len(brdfs), part.width, part.labels, part.notes
    plot_h, legend_h, footer_h = 330, 34, 34
    height = part.bottom + plot_h + legend_h + footer_h

    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    FigureCanvasAgg(fig)

    def box(x, y, w, h):                             # pixels from the top-left -> figure fraction
        return [x / width, 1.0 - (y + h) / height, w / width, h / height]

    canvas_y = height - (part.title_h + part.label_h) - part.canvas.shape[0]     # its bottom row, from below
    fig.add_artist(_pixels_artist()(part.canvas, part.xs[0], canvas_y))
    for k, label in enumerate(labels):
        fig.text(part.label_x(k) / width, 1.0 - part.label_y / height, label, ha="center", va="baseline",
                 fontsize=9, color=_COLOURS[k % len(_COLOURS)])
        if label in notes:
            fig.text(part.note_x(k) / width, 1.0 - part.notes_y / height, notes[label], ha="center", va="top",
                     fontsize=7.5, linespacing=1.25)
    row_text = _row_text(part.exposures)

    top = part.bottom + 26                          # room for the axes titles
    axes_h = plot_h - 26 - 48                       # room below for tick labels and x labels
    margin_l, margin_r, between = 70, 20, 80
    axes_w = (width - margin_l - margin_r - between) / 2.0
    _plot_backscattering(fig.add_axes(box(margin_l, top, axes_w, axes_h)), brdfs, planes_deg)
    _plot_slices(fig.add_axes(box(margin_l + axes_w + between, top, axes_w, axes_h)), brdfs, views_deg)
    handles = [Line2D([], [], color=_COLOURS[k % len(_COLOURS)], lw=1.6 if k == 0 else 1.2) for k in range(n)]
    fig.legend(handles, labels, loc="center", ncol=min(n, 5), fontsize=8, frameon=False,
               bbox_to_anchor=(0.5, 1.0 - (part.bottom + plot_h + legend_h / 2.0) / height))
    fig.text(0.5, 1.0 - (height - footer_h / 2.0) / height,
             row_text + f"\ncurves: grey band, grazing (cos θ < {GRAZING_COS:g}), excluded from fit errors",
             ha="center", va="center", fontsize=7, linespacing=1.3)
    if title:
        fig.suptitle(title, fontsize=11, y=1.0 - 6.0 / height, va="top")
    return fig
