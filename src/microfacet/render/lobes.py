"""Polar plots of BRDF lobes ``f_r(wi, wo) cos theta_i`` in a plane of incidence.

The view ``wo`` lies at ``-theta_o`` in the plane of azimuth ``phi`` (left of the
normal), ``wi`` sweeps the same plane from -90 to 90 deg, so a mirror-like lobe peaks at
``theta_i = +theta_o`` (right). Colour BRDFs are plotted as luminance (Rec. 709 weights).
Figures use Matplotlib's object API on the Agg canvas (no pyplot state, no display);
Matplotlib is imported on first use, so importing this module stays cheap.

Examples
--------
>>> from microfacet.render.lobes import LUMINANCE
>>> LUMINANCE
array([0.2126, 0.7152, 0.0722])
"""
from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from .._colour import LUMINANCE
from ..geometry import spherical_to_cartesian
from ..io import write_bytes

__all__ = ["lobe_curve", "plot_lobes", "lobe_figure", "save_lobe_figure", "LUMINANCE"]

_COLOURS = ("#1f77b4", "#2ca02c", "#ff7f0e", "#d62728", "#9467bd")
_STYLES = ("-", "--", ":")


def lobe_curve(brdf, theta_o: float, phi: float = 0.0, n: int = 721) -> tuple[np.ndarray, np.ndarray]:
    """Signed ``theta_i`` in ``[-pi/2, pi/2]`` ``(n,)`` and the luminance of
    ``f_r(wi, wo) cos theta_i`` along the plane of azimuth ``phi`` (module docstring).

    Parameters
    ----------
    brdf : BRDF
        The BRDF.
    theta_o : float
        View elevation, radians.
    phi : float
        Azimuth of the plane, radians.
    n : int
        Number of light angles.

    Returns
    -------
    theta_i : (n,) ndarray
        Signed light elevations, radians.
    luminance : (n,) ndarray
        Luminance of ``f_r cos theta_i``.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> theta_i, f = lobe_curve(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), np.radians(30), n=181)
    >>> round(float(np.degrees(theta_i[np.argmax(f)])))          # the peak: the mirror direction
    30
    """
    theta_i = np.linspace(-np.pi / 2, np.pi / 2, n)
    wi = spherical_to_cartesian(np.abs(theta_i), np.where(theta_i < 0, phi + np.pi, phi))
    wo = spherical_to_cartesian(theta_o, phi + np.pi)
    return theta_i, brdf.eval_cos(wi, np.broadcast_to(wo, wi.shape)) @ LUMINANCE


def plot_lobes(ax, brdf, theta_o_deg: Sequence[float] = (0, 30, 60, 80),
               planes_deg: Sequence[float] = (0,), title: str = "") -> None:
    """Draw the lobes of ``brdf`` for each view angle (colour) and plane azimuth (line
    style) on a polar ``ax``; view directions are drawn as thin lines from the origin.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        A polar axes.
    brdf : BRDF
        The BRDF.
    theta_o_deg : sequence of float
        View angles, degrees.
    planes_deg : sequence of float
        Plane azimuths, degrees.
    title : str
        Panel title.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import matplotlib.pyplot as plt
    >>> import microfacet as mf
    >>> fig, ax = plt.subplots(subplot_kw={"projection": "polar"})
    >>> plot_lobes(ax, mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), theta_o_deg=(0, 45))
    >>> len(ax.lines) >= 2
    True
    >>> plt.close(fig)
    """
    from matplotlib.ticker import FormatStrFormatter, MaxNLocator
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_thetalim(-np.pi / 2, np.pi / 2)
    top = 0.0
    for j, plane in enumerate(planes_deg):
        for k, to in enumerate(theta_o_deg):
            th, f = lobe_curve(brdf, np.radians(to), np.radians(plane))
            label = f"θo = {to:g}°" + (f", plane {plane:g}°" if len(planes_deg) > 1 else "")
            ax.plot(th, f, _STYLES[j % len(_STYLES)], color=_COLOURS[k % len(_COLOURS)], lw=1.2, label=label)
            top = max(top, float(np.max(f)))
    top = top * 1.05 if top > 0 else 1.0
    for k, to in enumerate(theta_o_deg):
        ax.plot([-np.radians(to)] * 2, [0, top], color=_COLOURS[k % len(_COLOURS)], lw=0.6, alpha=0.6)
    ax.set_ylim(0, top)
    # Rings at nice values up to 0.8 of the radius; only the outermost is labelled: side by
    # side along the baseline, two labels such as "0.12" and "0.06" overlapped, and one label
    # inside the rim's "-90°" gives the panel's scale.
    ticks = [t for t in MaxNLocator(3).tick_values(0.0, 0.8 * top) if 0 < t <= 0.8 * top]
    ax.set_yticks(ticks)
    ax.set_yticklabels([""] * (len(ticks) - 1) + [FormatStrFormatter("%g")(ticks[-1])] if ticks else [])
    ax.set_rlabel_position(-90 + 8)
    ax.tick_params(labelsize=6)
    ax.set_title(title, fontsize=8)


def save_lobe_figure(path: str | os.PathLike, brdfs: Sequence, labels: Sequence[str],
                     theta_o_deg: Sequence[float] = (0, 30, 60, 80),
                     planes_deg: Sequence[float] = (0,), ncols: int | None = None,
                     dpi: int = 110) -> Path:
    """One polar panel per BRDF, shared legend, written atomically as a PNG (:func:`lobe_figure`).

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file to write.
    brdfs, labels, theta_o_deg, planes_deg, ncols
        As :func:`lobe_figure`.
    dpi : int
        Resolution.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> save_lobe_figure("lobes.png", [mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3))], ["Beckmann 0.3"]).name
    'lobes.png'
    """
    fig = lobe_figure(brdfs, labels, theta_o_deg, planes_deg, ncols)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return write_bytes(path, buf.getvalue())


def lobe_figure(brdfs: Sequence, labels: Sequence[str], theta_o_deg: Sequence[float] = (0, 30, 60, 80),
                planes_deg: Sequence[float] = (0,), ncols: int | None = None):
    """The Matplotlib figure of :func:`save_lobe_figure` (Agg canvas): one polar panel per
    BRDF (:func:`plot_lobes`) in ``ncols`` columns, and a shared legend.

    Parameters
    ----------
    brdfs : sequence of BRDF
        The BRDFs, one panel each.
    labels : sequence of str
        Panel titles.
    theta_o_deg : sequence of float
        View angles, degrees.
    planes_deg : sequence of float
        Plane azimuths, degrees.
    ncols : int, optional
        Columns; None: all panels in a row.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Examples
    --------
    >>> import microfacet as mf
    >>> fig = lobe_figure([mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), mf.Lambertian(0.5)], ["GGX", "Lambertian"])
    >>> len(fig.axes)
    2
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    ncols = ncols or len(brdfs)
    nrows = -(-len(brdfs) // ncols)
    row_h, legend_h = 1.4, 0.4
    fig = Figure(figsize=(2.3 * ncols, row_h * nrows + legend_h))
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(nrows, ncols, i + 1, projection="polar") for i in range(len(brdfs))]
    for ax, brdf, label in zip(axes, brdfs, labels, strict=True):
        plot_lobes(ax, brdf, theta_o_deg, planes_deg, label)
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=len(names), fontsize=7, frameon=False)
    height = row_h * nrows + legend_h
    fig.subplots_adjust(left=0.02, right=0.98, top=1 - 0.25 / height, bottom=(legend_h + 0.05) / height,
                        wspace=0.25, hspace=0.35)
    return fig
