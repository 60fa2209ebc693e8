"""Comparison picture of a BRDF (e.g. measured data) and its fits.

One PNG, Matplotlib's object API on the Agg canvas (no pyplot state, no display):

* top left: backscattering ``f_r(k, k)`` against ``theta_k`` (log scale), the quantity
  the power-iteration fit of thesis Ch. 4 starts from (Eq. 4.4-4.6);
* top right: in-plane slices ``f_r(wi, wo) cos theta_i`` against signed ``theta_i`` for a
  few view angles ``theta_o`` (the view at ``-theta_o``, as in :mod:`.lobes`), log scale
  so that peaks and the diffuse floor both show;
* bottom: the BRDFs on small orthographic spheres under one directional light (the same
  exposure for all, set by the first BRDF's 99.5th-percentile pixel), each with an
  optional note below it (e.g. its fit errors).

Colour BRDFs are plotted as luminance (Rec. 709 weights). The first BRDF is the
reference (black); the grazing region ``cos theta < 0.1`` that fit errors exclude
(:data:`microfacet.metrics.GRAZING_COS`) is shaded grey.
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

__all__ = ["backscattering_curve", "render_sphere", "save_fit_comparison", "fit_comparison_png", "COMPARE_LIGHT"]

#: Light of the comparison spheres: up-left of the view, 35 deg from it, unit irradiance.
COMPARE_LIGHT = DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=1.0)
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
    ``k`` at azimuth ``phi``."""
    theta = np.linspace(0.0, theta_max, n)
    k = spherical_to_cartesian(theta, np.full(n, phi))
    return theta, brdf.eval(k, k) @ LUMINANCE


def render_sphere(brdf, size: int, light: DirectionalLight = COMPARE_LIGHT) -> np.ndarray:
    """Linear RGB ``(size, size, 3)`` of ``brdf`` on an orthographic sphere under ``light``."""
    sphere = Sphere(size)
    radiance = shade_directional(brdf, sphere.wo, sphere.to_local(light.w), light.rgb)
    return sphere.image(np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0))


def _positive(y: np.ndarray) -> np.ndarray:
    """``y`` with non-positive values masked (NaN), for log axes."""
    return np.where(y > 0, y, np.nan)


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
            name = label + (f", φ = {plane:g}°" if len(planes_deg) > 1 else "")
            ax.plot(np.degrees(theta), _positive(f), _VIEW_STYLES[j % len(_VIEW_STYLES)],
                    color=_COLOURS[k % len(_COLOURS)], lw=1.6 if k == 0 else 1.1, label=name)
    ax.set_yscale("log")
    if 0 < lo < np.inf and hi > 0:
        top = max(hi, lo) * 3.0
        ax.set_ylim(max(lo / 30.0, top * 1e-8), top)
    ax.axvspan(_GRAZING_DEG, 90.0, color="0.85", lw=0)
    ax.set_xlim(0, 90)
    ax.set_xlabel("θ (deg)", fontsize=8)
    ax.set_title("backscattering f(k, k) (log)", fontsize=9, y=_TITLE_Y)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6, frameon=False)


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
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6, frameon=False, title="line style", title_fontsize=6)


def save_fit_comparison(path: str | os.PathLike, brdfs: Mapping, title: str = "",
                        views_deg: Sequence[float] = (0, 30, 60), planes_deg: Sequence[float] = (0,),
                        size: int = 96, dpi: int = 100, notes: Mapping[str, str] | None = None) -> Path:
    """Write the comparison picture of :func:`fit_comparison_png` to ``path``, atomically;
    return ``path``."""
    return write_bytes(path, fit_comparison_png(brdfs, title, views_deg, planes_deg, size, dpi, notes))


def fit_comparison_png(brdfs: Mapping, title: str = "", views_deg: Sequence[float] = (0, 30, 60),
                       planes_deg: Sequence[float] = (0,), size: int = 96, dpi: int = 100,
                       notes: Mapping[str, str] | None = None) -> bytes:
    """The comparison picture (module docstring) of ``brdfs`` as PNG bytes, in memory (so
    that a caller can render it before writing any of its files).

    Parameters
    ----------
    brdfs : mapping of str -> BRDF
        Label and BRDF, the reference (data) first, e.g. ``{"data": m, "tabulated fit":
        fit, "GGX": fit.to_ggx(), "Beckmann": fit.to_beckmann()}``.
    title : str
        Figure title (e.g. the material name).
    views_deg : sequence of float
        View angles of the in-plane slices.
    planes_deg : sequence of float
        Azimuths of the backscattering curves (e.g. ``(0, 90)`` for anisotropic data).
    size : int
        Side of each sphere image, pixels.
    notes : mapping of str -> str, optional
        Text under the sphere of a label (e.g. fit errors); labels not in ``brdfs`` are
        an error.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    if not brdfs:
        raise ValueError("save_fit_comparison needs at least one BRDF")
    notes = dict(notes or {})
    unknown = sorted(set(notes) - set(brdfs))
    if unknown:
        raise ValueError(f"save_fit_comparison: notes for labels not in brdfs: {unknown}")
    n = len(brdfs)
    images = [render_sphere(b, size) for b in brdfs.values()]
    lum = images[0] @ LUMINANCE
    top = float(np.percentile(lum[lum > 0], 99.5)) if np.any(lum > 0) else 1.0
    scale = 1.0 / top if np.isfinite(top) and top > 0 else 1.0
    exposure = float(np.log2(scale))

    fig = Figure(figsize=(max(8.0, 1.9 * n), 6.2 + (0.35 if notes else 0.0)))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, n, height_ratios=(1.35, 1.0))
    half = max(1, n // 2)
    _plot_backscattering(fig.add_subplot(grid[0, :half]), brdfs, planes_deg)
    _plot_slices(fig.add_subplot(grid[0, half:]), brdfs, views_deg)
    for k, (label, image) in enumerate(zip(brdfs, images, strict=True)):
        ax = fig.add_subplot(grid[1, k])
        ax.imshow(to_srgb8(image, exposure), interpolation="nearest")
        ax.set_axis_off()
        ax.set_title(label, fontsize=8, color=_COLOURS[k % len(_COLOURS)], y=_TITLE_Y)
        if label in notes:
            ax.text(0.5, -0.04, notes[label], transform=ax.transAxes, ha="center", va="top", fontsize=6.5)
    fig.text(0.5, 0.015, f"spheres: directional light, common exposure {exposure:+.2f} stops; "
                         f"grey: grazing (cos θ < {GRAZING_COS:g}), excluded from fit errors",
             ha="center", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.9 if title else 0.95, bottom=0.1 if notes else 0.06,
                        wspace=0.35, hspace=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()
