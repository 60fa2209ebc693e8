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

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..geometry import spherical_to_cartesian
from ..io import to_srgb8, write_bytes
from ..metrics import GRAZING_COS
from .integrate import shade_directional
from .lights import DirectionalLight
from .lobes import LUMINANCE, lobe_curve
from .sphere import Sphere

__all__ = ["backscattering_curve", "render_sphere", "save_fit_comparison", "fit_comparison_png", "COMPARE_LIGHT",
           "GRAZING_LIGHT"]

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
    sphere = Sphere(size)
    radiance = shade_directional(brdf, sphere.wo, sphere.to_local(light.w), light.rgb)
    return sphere.image(np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0))


def _positive(y: np.ndarray) -> np.ndarray:
    """``y`` with non-positive values masked (NaN), for log axes."""
    return np.where(y > 0, y, np.nan)


def _log_ticks(ax) -> None:
    """At most ~6 labelled decades on a log y axis, unlabelled minor ticks, small labels:
    no two tick labels overlap."""
    from matplotlib.ticker import LogLocator, NullFormatter
    ax.yaxis.set_major_locator(LogLocator(base=10.0, numticks=6))
    ax.yaxis.set_minor_locator(LogLocator(base=10.0, subs=(), numticks=6))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.tick_params(labelsize=7)


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
    ax.set_xlabel("θ (deg)", fontsize=8)
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
    ax.set_yscale("log")
    if top > 0:
        ax.set_ylim(top * 1e-6, top * 3.0)
    ax.set_xlabel("θi (deg), view at −θo, plane φ = 0", fontsize=8)
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
    """Exposure (stops) putting the 99.5th-percentile luminance of ``image`` at 1."""
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
    fig = _comparison_figure(brdfs, title, views_deg, planes_deg, size, dpi, notes)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def _comparison_figure(brdfs: Mapping, title: str, views_deg: Sequence[float], planes_deg: Sequence[float],
                       size: int, dpi: int, notes: Mapping[str, str] | None):
    """The Matplotlib figure of :func:`fit_comparison_png` (Agg canvas attached)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle
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
    rows = [[render_sphere(b, size, light) for b in brdfs.values()] for light in (COMPARE_LIGHT, GRAZING_LIGHT)]
    exposures = [_exposure(images[0]) for images in rows]

    # layout in pixels, from the top
    note_lines = max((v.count("\n") + 1 for v in notes.values()), default=0)
    cell = max(size + 40, 170)
    width = max(900, n * cell + 40)
    title_h, label_h, gap = (36 if title else 10), 22, 8
    notes_h = 13 * note_lines + (10 if note_lines else 0)
    plot_h, legend_h, footer_h = 330, 34, 34
    spheres_h = 2 * (label_h + size + gap) + notes_h
    height = title_h + spheres_h + plot_h + legend_h + footer_h

    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    FigureCanvasAgg(fig)

    def box(x, y, w, h):                             # pixels from the top-left -> figure fraction
        return [x / width, 1.0 - (y + h) / height, w / width, h / height]

    left = (width - n * cell) / 2.0
    rows_top = title_h
    labels = list(brdfs)
    for r, (images, exposure) in enumerate(zip(rows, exposures)):
        y = rows_top + r * (label_h + size + gap) + label_h
        for k, (label, image) in enumerate(zip(labels, images)):
            ax = fig.add_axes(box(left + k * cell + (cell - size) / 2.0, y, size, size))
            ax.imshow(to_srgb8(image, exposure), interpolation="nearest")
            ax.add_patch(Circle(((size - 1) / 2.0, (size - 1) / 2.0), size / 2.0, fill=False, lw=0.6,
                                color="0.35"))       # the silhouette, where the sphere is dark
            ax.set_axis_off()
            if r == 0:
                ax.set_title(label, fontsize=9, color=_COLOURS[k % len(_COLOURS)], y=_TITLE_Y)
    for k, label in enumerate(labels):
        if label in notes:
            fig.text((left + (k + 0.5) * cell) / width, 1.0 - (rows_top + spheres_h - notes_h + 4) / height,
                     notes[label], ha="center", va="top", fontsize=7.5, linespacing=1.25)
    row_text = (f"spheres: light 35° from the view (top row, exposure {exposures[0]:+.2f} stops) and 75° "
                f"(bottom row, {exposures[1]:+.2f} stops), the same exposure for every sphere of a row")

    top = title_h + spheres_h + 26                  # room for the axes titles
    axes_h = plot_h - 26 - 48                       # room below for tick labels and x labels
    margin_l, margin_r, between = 70, 20, 80
    axes_w = (width - margin_l - margin_r - between) / 2.0
    _plot_backscattering(fig.add_axes(box(margin_l, top, axes_w, axes_h)), brdfs, planes_deg)
    _plot_slices(fig.add_axes(box(margin_l + axes_w + between, top, axes_w, axes_h)), brdfs, views_deg)
    handles = [Line2D([], [], color=_COLOURS[k % len(_COLOURS)], lw=1.6 if k == 0 else 1.2) for k in range(n)]
    fig.legend(handles, labels, loc="center", ncol=min(n, 5), fontsize=8, frameon=False,
               bbox_to_anchor=(0.5, 1.0 - (title_h + spheres_h + plot_h + legend_h / 2.0) / height))
    fig.text(0.5, 1.0 - (height - footer_h / 2.0) / height,
             row_text + f"\ncurves: grey band, grazing (cos θ < {GRAZING_COS:g}), excluded from fit errors",
             ha="center", va="center", fontsize=7, linespacing=1.3)
    if title:
        fig.suptitle(title, fontsize=11, y=1.0 - 6.0 / height, va="top")
    return fig
