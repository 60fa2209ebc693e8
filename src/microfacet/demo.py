"""The demo: spheres and lobes showing what thesis Figs. 2.2-2.6 show.

Each figure varies one ingredient of the microfacet BRDF (Eq. 2.1): the Fresnel term
(Fig. 2.2), the geometric attenuation factor (2.3), isotropic roughness (2.4),
anisotropic roughness (2.5) and its orientation (2.6). Every BRDF is rendered on an
orthographic sphere under a directional light and under a small environment (Monte
Carlo with the BRDF's own importance sampling), written as EXR (data) and PNG (preview),
plotted as polar lobes, and gathered in ``index.html``. The fitting section fits measured
materials of the shared corpus (or, without it, built-in analytic ones) as ``microfacet
fit`` does and shows data, best fit, tabulated fit and the published ABC fit side by side.

>>> DEFAULT_SIZE, DEFAULT_SPP, DEFAULT_SEED
(128, 64, 0)
>>> ABC_LABEL
'ABC (Löw 2012)'
>>> run_demo("demo-output", size=48, workers=default_workers())   # doctest: +SKIP
PosixPath('demo-output/index.html')
"""
from __future__ import annotations

import contextlib
import functools
import logging
import multiprocessing
import os
import shutil
import signal
import time
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from html import escape
from pathlib import Path

import numpy as np
from tqdm import tqdm

from . import fresnel as fr
from .brdf import BRDF, MicrofacetBRDF
from .distributions import GGX, Beckmann
from .errors import MicrofacetError
from .io import html_figure, html_grid, html_page, write_bytes, write_exr, write_png, write_text
from .demo_materials import (CORPUS_MATERIALS, LIGHT, FitExample, corpus_cache, corpus_examples,  # noqa: F401
                             corpus_file, fit_demo_material, fit_examples, fit_materials, preview_exposure,
                             shared_data)
from .io.atomic import staging_folder
from .render import (DirectionalLight, Environment, Sphere, procedural_sky, save_lobe_figure,
                     shade_directional, shade_environment)

__all__ = ["Panel", "DemoFigure", "thesis_figures", "render_panel", "run_demo", "default_workers",
           "FitExample", "fit_examples", "fit_section", "fit_materials", "fit_and_picture", "fit_demo_material",
           "corpus_examples", "corpus_file", "corpus_cache", "shared_data", "shown_fits", "fit_sizes",
           "CORPUS_MATERIALS", "ABC_LABEL", "preview_exposure",
           "DEFAULT_SIZE", "DEFAULT_SPP", "DEFAULT_SEED", "LIGHT"]

#: Logger of the demo's section times (INFO; ``microfacet demo --timings`` prints them).
log = logging.getLogger(__name__)

#: Sphere image side, pixels.
DEFAULT_SIZE = 128
#: Environment samples per pixel (a power of two stratifies best).
DEFAULT_SPP = 64
#: Random seed of the environment samples.
DEFAULT_SEED = 0
EXPOSURE = 0.0          # preview exposure in stops, the same for every image
#: Grazing side light (102 deg from the view), where GAFs differ most (Fig. 2.3).
SIDE_LIGHT = DirectionalLight(direction=(-1.0, 0.3, -0.2), irradiance=1.0)


@dataclass(frozen=True)
class Panel:
    """One BRDF of a figure, captioned ``label (detail)``.

    Parameters
    ----------
    key : str
        File-name key of its images.
    label : str
        Short label.
    brdf : BRDF
        The BRDF rendered.
    detail : str
        Optional detail, in parentheses in the caption.

    Examples
    --------
    >>> from microfacet import GGX, MicrofacetBRDF
    >>> Panel("ggx", "GGX", MicrofacetBRDF(GGX(alpha=0.2)), "α = 0.2").caption
    'GGX (α = 0.2)'
    """

    key: str
    label: str
    brdf: BRDF
    detail: str = ""

    @property
    def caption(self) -> str:
        return f"{self.label} ({self.detail})" if self.detail else self.label


@dataclass(frozen=True)
class DemoFigure:
    """A thesis figure: rows of panels, with what the rows share stated in ``caption``.

    Parameters
    ----------
    key : str
        File-name key of the figure.
    title : str
        Its heading.
    caption : str
        What its panels share and show.
    rows : tuple of (str, tuple of Panel)
        Rows of panels, each with its label (``""``: none).
    lobe_views_deg : tuple of float
        View angles (degrees) of the polar lobe plots.
    lobe_planes_deg : tuple of float
        Azimuths (degrees) of the planes of incidence of the lobe plots.
    light : DirectionalLight
        The spheres' directional light; default :data:`LIGHT`.

    Attributes
    ----------
    panels : tuple of Panel
        Every panel, row by row.

    Examples
    --------
    >>> from microfacet import GGX, MicrofacetBRDF
    >>> p = Panel("ggx", "GGX", MicrofacetBRDF(GGX(alpha=0.2)))
    >>> fig = DemoFigure("one", "One panel", "A GGX sphere.", (("", (p,)),))
    >>> fig.panels == (p,), fig.light == LIGHT
    (True, True)
    """

    key: str
    title: str
    caption: str
    rows: tuple[tuple[str, tuple[Panel, ...]], ...]
    lobe_views_deg: tuple[float, ...] = (0, 30, 60)
    lobe_planes_deg: tuple[float, ...] = (0,)
    light: DirectionalLight = LIGHT
    panels: tuple[Panel, ...] = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "panels", tuple(p for _, row in self.rows for p in row))


def _fresnel_figure() -> DemoFigure:
    d = Beckmann(alpha=0.2)
    terms = [("ideal", "ideal F = 1", fr.Ideal()),
             ("dielectric", "dielectric η = 1.5", fr.Dielectric(1.5)),
             ("schlick", "Schlick F0 = 0.04", fr.Schlick.from_eta(1.5)),
             ("gold", "conductor Au", fr.Conductor.metal("Au")),
             ("copper", "conductor Cu", fr.Conductor.metal("Cu"))]
    panels = tuple(Panel(k, lab, MicrofacetBRDF(d, fresnel=f)) for k, lab, f in terms)
    return DemoFigure(
        "fig2_2", "Fig. 2.2 — Fresnel term",
        "Beckmann α = 0.2, Smith height-correlated GAF; only F(θd) changes. The dielectric and "
        "its Schlick approximation brighten toward grazing angles; conductors tint the reflection.",
        (("", panels),))


def _gaf_figure() -> DemoFigure:
    d = Beckmann(alpha=0.5)
    gafs = [("smith", "Smith", "smith", True), ("vgroove", "V-groove", "vgroove", True),
            ("normal_map", "normal map", "normal_map", True),
            ("smith_masking", "Smith, masking only", "smith", False)]
    panels = tuple(Panel(k, lab, MicrofacetBRDF(d, fresnel=fr.Ideal(), gaf=g, shadowing=sh))
                   for k, lab, g, sh in gafs)
    return DemoFigure(
        "fig2_3", "Fig. 2.3 — geometric attenuation factor",
        "Beckmann α = 0.5, ideal Fresnel (F = 1); only the GAF G(i, o) changes. The directional "
        "light comes from the left and slightly behind (102° from the view), so that light and "
        "view are grazing over much of the sphere: with shadowing (Smith, V-groove) the lit side "
        "fades smoothly to the terminator, without it (normal map, Smith masking only) it ends "
        "abruptly; toward the silhouette (grazing view) the V-groove and normal-map GAFs darken "
        "faster than Smith's.",
        (("", panels),), lobe_views_deg=(0, 30, 60, 80), light=SIDE_LIGHT)


def _roughness_figure() -> DemoFigure:
    alphas = (0.05, 0.1, 0.2, 0.4, 0.8)
    f = fr.Conductor.metal("Ag")
    rows = tuple((cls.__name__, tuple(Panel(f"{cls.__name__.lower()}_{a:g}", f"α = {a:g}",
                                            MicrofacetBRDF(cls(alpha=a), fresnel=f)) for a in alphas))
                 for cls in (Beckmann, GGX))
    return DemoFigure(
        "fig2_4", "Fig. 2.4 — isotropic roughness",
        "Beckmann (top) and GGX (bottom) with α from 0.05 to 0.8, silver Fresnel, Smith GAF. "
        "The highlight widens and dims as α grows; GGX keeps longer tails (a glow around the "
        "highlight) than Beckmann at equal α.",
        rows)


def _anisotropy_figure() -> DemoFigure:
    pairs = ((0.05, 0.4), (0.1, 0.2), (0.2, 0.2), (0.2, 0.1), (0.4, 0.05))
    f = fr.Conductor.metal("Al")
    panels = tuple(Panel(f"ax{ax:g}_ay{ay:g}", f"αx = {ax:g}, αy = {ay:g}",
                         MicrofacetBRDF(GGX(alpha_x=ax, alpha_y=ay), fresnel=f)) for ax, ay in pairs)
    return DemoFigure(
        "fig2_5", "Fig. 2.5 — anisotropic roughness",
        "GGX with αx ≠ αy, ρ = 0, aluminium Fresnel, Smith GAF. The local x axis is world x "
        "projected on the tangent plane, so the highlight is stretched horizontally where "
        "αx > αy and vertically where αy > αx. Lobes: planes of incidence at azimuth 0° (xz, "
        "solid) and 90° (yz, dashed).",
        (("", panels),), lobe_views_deg=(0, 45, 75), lobe_planes_deg=(0, 90))


def _orientation_figure() -> DemoFigure:
    a1, a2 = 0.4, 0.05
    f = fr.Conductor.metal("Al")
    panels = []
    for deg in (0, 45, 90, 135):
        d = GGX.from_ellipse(a1, a2, np.radians(deg))
        detail = f"αx = {float(d.alpha_x):.3f}, αy = {float(d.alpha_y):.3f}, ρ = {float(d.rho):+.3f}"
        panels.append(Panel(f"phi{deg}", f"φ = {deg}°", MicrofacetBRDF(d, fresnel=f), detail))
    return DemoFigure(
        "fig2_6", "Fig. 2.6 — orientation of the anisotropy",
        f"GGX.from_ellipse(α1 = {a1}, α2 = {a2}, φ): the long axis of the slope ellipse turns by φ "
        "from the local x axis (Eq. 2.29-2.31), i.e. through correlation ρ; aluminium Fresnel, "
        "Smith GAF. The stretched highlight turns with φ. Lobes: planes of incidence at azimuth 0° "
        "(xz, solid) and 90° (yz, dashed); in-plane lobes cannot tell φ = 45° from 135°, the spheres can.",
        (("", tuple(panels)),), lobe_views_deg=(0, 45, 75), lobe_planes_deg=(0, 90))


def thesis_figures() -> list[DemoFigure]:
    """The figures of the demo, in thesis order (Figs. 2.2-2.6).

    Returns
    -------
    list of DemoFigure
        The five figures.

    Examples
    --------
    >>> [fig.key for fig in thesis_figures()]
    ['fig2_2', 'fig2_3', 'fig2_4', 'fig2_5', 'fig2_6']
    """
    return [_fresnel_figure(), _gaf_figure(), _roughness_figure(), _anisotropy_figure(),
            _orientation_figure()]


# ------------------------------------------------------------------------ fitting
#: Side (px) of the comparison picture's spheres at the default demo size (the size of
#: ``microfacet fit``'s picture); smaller demos scale it down.
FIT_SPHERE_SIZE = 192
#: Largest side (px) of the fitting section's environment-lit spheres.
FIT_ENV_SIZE = 96
#: Label of the published ABC fit (Löw et al. 2012) in the fitting pictures.
ABC_LABEL = "ABC (Löw 2012)"


def fit_sizes(size: int) -> tuple[int, int]:
    """Sphere sides (px) of the fitting section for a demo of ``size``: the comparison
    picture's (:data:`FIT_SPHERE_SIZE` at the default 128) and the environment row's.

    Parameters
    ----------
    size : int
        The demo's sphere side (px).

    Returns
    -------
    tuple of int
        The comparison picture's and the environment row's sphere sides (px).

    Examples
    --------
    >>> fit_sizes(128)
    (192, 96)
    >>> fit_sizes(16)
    (32, 16)
    """
    return max(32, min(FIT_SPHERE_SIZE, 3 * size // 2)), max(16, min(FIT_ENV_SIZE, size))


def shown_fits(summary: dict) -> list[tuple[str, str]]:
    """``(label, fit name)`` of the fits the demo shows from a ``microfacet fit`` summary:
    the best and the tabulated fit, or, where the tabulated fit is the best, the best
    analytic fit (:func:`microfacet.fit.outputs.best_fit` of those with a model).

    Parameters
    ----------
    summary : dict
        A fit's summary (``OUT.json``, :func:`fit_demo_material`): its ``"best"`` fit and
        its ``"fits"``.

    Returns
    -------
    list of (str, str)
        Label and fit name of each fit shown.

    Examples
    --------
    >>> summary = {"best": "ggx", "fits": {"ggx": {"model": "ggx"}, "tabulated": {"model": None}}}
    >>> shown_fits(summary)
    [('best: ggx', 'ggx'), ('tabulated fit', 'tabulated')]
    """
    from .fit.outputs import best_fit
    fits, best = summary["fits"], summary["best"]
    out = [(f"best: {best}", best)]
    if best != "tabulated":
        out.append(("tabulated fit", "tabulated"))
    else:
        analytic = {k: v["metrics"] for k, v in fits.items() if k != "tabulated" and v["model"] is not None}
        if analytic:
            name = best_fit(analytic)
            out.append((f"best analytic: {name}", name))
    return out


def _metrics_note(metrics: dict) -> str:
    """Two lines of figures under a sphere of the fitting picture."""
    text = f"image {metrics['image']:.3f} · log {metrics['log']:.4f}"
    if "albedo_ratio_worst" in metrics:
        text += f"\nalbedo ratio {metrics['albedo_ratio_worst']:.2f}"
    return text


def fit_and_picture(example: FitExample, work: str | os.PathLike, size: int) -> dict:
    """The fitting section's work for one material (a task of the demo's process pool):
    :func:`fit_demo_material`, the ABC fit's errors against the data (the same judges as
    the fits': :data:`microfacet.fit.outputs.IMAGE_SIZE`-px image error and
    :data:`~microfacet.fit.outputs.LOG_PAIRS`-pair log error), the comparison picture
    (:func:`microfacet.render.fit_comparison_png`) of data | best | tabulated | ABC with
    each one's errors, and the environment images of :func:`microfacet.metrics.render_images`.

    Parameters
    ----------
    example : FitExample
        The material.
    work : path-like
        The folder of its fit files.
    size : int
        The demo's sphere side (px; :func:`fit_sizes`).

    Returns
    -------
    dict
        ``{"summary", "npz", "shown": [(label, fit name)], "abc": {"image", "log",
        "chromaticity"} or None, "picture": PNG bytes, "environment": {label: (S, S, 3)
        image}, "seconds": wall time of this work}``.

    Examples
    --------
    >>> example = fit_examples()[0]
    >>> r = fit_and_picture(example, ".", size=32)      # doctest: +SKIP
    >>> r["picture"][:4]                                # doctest: +SKIP
    b'\x89PNG'
    """
    from .fit import load
    from .fit.outputs import IMAGE_SIZE, LOG_PAIRS
    from .metrics import ImageError, LogError, render_images
    from .render import fit_comparison_png
    start = time.perf_counter()
    picture_size, env_size = fit_sizes(size)
    data = example.material()
    summary, npz = fit_demo_material(example, work)
    shown = shown_fits(summary)
    brdfs = {"data": data, **{label: load(npz, model=name) for label, name in shown}}
    notes = {label: _metrics_note(summary["fits"][name]["metrics"]) for label, name in shown}
    abc = None
    if example.abc is not None:
        details = ImageError(data, size=IMAGE_SIZE).details(example.abc)
        abc = {"image": details["image"], "chromaticity": details["chromaticity"],
               "log": LogError(data, n=LOG_PAIRS)(example.abc)}
        brdfs[ABC_LABEL] = example.abc
        notes[ABC_LABEL] = _metrics_note(abc)
    picture = fit_comparison_png(brdfs, title=f"fit of {example.label}", size=picture_size, notes=notes)
    environment = {label: render_images(b, size=env_size, reference=data)[3] for label, b in brdfs.items()}
    return {"summary": summary, "npz": npz, "shown": shown, "abc": abc, "picture": picture,
            "environment": environment, "seconds": time.perf_counter() - start}


def _slug(label: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in label.split(":")[0].split(" (")[0].lower()).strip("_")


def _fit_table(examples: Sequence[FitExample], results: Sequence[dict]) -> str:
    head = ("material", "best fit", "image error: best / tabulated / ABC", "log error: best / tabulated / ABC",
            "worst albedo ratio (best)", "fits tried")
    rows = []
    for ex, r in zip(examples, results, strict=True):
        fits, best = r["summary"]["fits"], r["summary"]["best"]
        abc = r["abc"]

        def trio(key, digits, fits=fits, best=best, abc=abc):
            vals = [fits[best]["metrics"][key], fits["tabulated"]["metrics"][key]] + ([abc[key]] if abc else [])
            return " / ".join(f"{v:.{digits}f}" for v in vals) + ("" if abc else " / —")
        cells = (ex.label, best, trio("image", 3), trio("log", 4),
                 f"{fits[best]['metrics']['albedo_ratio_worst']:.2f}", ", ".join(fits))
        rows.append("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in cells) + "</tr>")
    return ('<table class="grid"><tr>' + "".join(f"<th>{escape(h)}</th>" for h in head) + "</tr>"
            + "".join(rows) + "</table>")


def fit_section(out: Path, size: int, examples: Sequence[FitExample] | None = None,
                progress=None, results: Sequence | None = None, note: str = "") -> str:
    """Fit each material of ``examples`` (default: :func:`fit_materials`) as ``microfacet
    fit`` does and write its pictures under ``out/fitting/``: the comparison picture of
    data | best fit | tabulated fit | ABC (MERL materials with a published fit) under two
    lights with backscattering and in-plane curves, and the same under the environment;
    return the HTML section. ``results``: the materials' :func:`fit_and_picture` results or
    futures of them (``.result()``), as :func:`run_demo` computes them in its pool; default
    computed here, the fit files into a temporary folder.

    Parameters
    ----------
    out : Path
        The demo's folder.
    size : int
        The demo's sphere side (px; :func:`fit_sizes`).
    examples : sequence of FitExample, optional
        The materials; default :func:`fit_materials`.
    progress : callable, optional
        Called with 1 after each material.
    results : sequence, optional
        The materials' :func:`fit_and_picture` results or futures of them.
    note : str
        What the materials are (the second value of :func:`fit_materials`).

    Returns
    -------
    str
        The HTML section.

    Examples
    --------
    >>> examples, note = fit_materials(quick=True)
    >>> html = fit_section(Path("."), 32, examples, note=note)   # doctest: +SKIP
    >>> html.startswith('<section id="fitting">')               # doctest: +SKIP
    True
    """
    from .fit.outputs import IMAGE_SIZE, LOG_PAIRS
    from .metrics import describe_image_error, describe_log_error
    if examples is None:
        examples, note = fit_materials()
    examples = list(examples)
    if results is None:
        import tempfile
        with tempfile.TemporaryDirectory() as work:
            done = [fit_and_picture(ex, work, size) for ex in examples]
        return fit_section(out, size, examples, progress, done, note)
    folder = out / "fitting"
    folder.mkdir(exist_ok=True)
    done, parts = [], []
    for ex, task in zip(examples, results, strict=True):
        r = task.result() if hasattr(task, "result") else task
        if "seconds" in r:
            log.info("demo: fitting %s: %.1f s (in its worker)", ex.key, r["seconds"])
        done.append(r)
        write_bytes(folder / f"{ex.key}.png", r["picture"])
        labels = list(r["environment"])
        exposure = preview_exposure(r["environment"]["data"])
        cells = []
        for label in labels:
            stem = f"{ex.key}-environment-{_slug(label)}"
            write_exr(folder / f"{stem}.exr", r["environment"][label])
            write_png(folder / f"{stem}.png", r["environment"][label], exposure)
            cells.append((f"fitting/{stem}.png", label))           # the errors: in the table and picture
        shown = " | ".join(labels)
        parts.append(html_figure(f"fitting/{ex.key}.png",
                                 f"{ex.label}: {shown} under a light 35° (top) and 75° (bottom) from the view, "
                                 "backscattering and in-plane curves, each fit's image and log errors.",
                                 css_class="lobes")
                     + html_grid([(f"{ex.label}, environment", cells)]))
        if progress:
            progress(1)
    env = fit_sizes(size)[1]
    intro = (f"{note} Each is fitted as microfacet fit FILE -o OUT.npz does (microfacet.fit.outputs.fit_material, "
             "the CLI's defaults): the tabulated fit (power iterations, thesis Ch. 4), its GGX and Beckmann moment "
             "conversions, least-squares GGX and Beckmann fits and the perceptual fits (one GGX lobe + "
             "Schlick Fresnel + Lambertian base, core + halo lobes), the best being the one of least image "
             "error. Shown: the data, the best fit, the tabulated fit (or, where it is the best, the best "
             "analytic fit) and, for MERL materials, the published ABC fit of Löw et al. 2012, whose errors are "
             f"computed here by the same judges. The environment row: the image error's studio environment "
             f"({env} px, a deterministic quadrature, the same exposure across the row). Load a fit with "
             "microfacet.fit.load(OUT.npz, model=\"best\").")
    metrics = (f"Image error: {describe_image_error(IMAGE_SIZE)}. Log error: {describe_log_error(LOG_PAIRS)}. "
               "Albedo ratio: the directional albedo of the fit over the data's, farthest from 1 over views and "
               "channels.")
    return ('<section id="fitting"><h2>Fitting measured materials: data, best fit, tabulated fit, ABC</h2>'
            f"<p>{escape(intro)}</p>{_fit_table(examples, done)}<p><small>{escape(metrics)}</small></p>"
            + "".join(parts) + "</section>")


# ------------------------------------------------------------------------ running
def _save(out: Path, stem: str, image: np.ndarray) -> str:
    """Write ``stem.exr`` and ``stem.png`` under ``out``; warn about non-finite pixels."""
    bad = int(np.count_nonzero(~np.isfinite(image).all(axis=-1)))
    if bad:
        warnings.warn(f"{stem}: {bad} pixels are NaN or infinite", RuntimeWarning, stacklevel=3)
    write_exr(out / f"{stem}.exr", image)
    write_png(out / f"{stem}.png", image, EXPOSURE)
    return f"{stem}.png"


@functools.lru_cache(maxsize=2)
def _sphere(size: int) -> Sphere:
    return Sphere(size)


def render_panel(brdf: BRDF, light: DirectionalLight, size: int, env_map: np.ndarray, spp: int,
                 seed: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Directional and environment renders ``(size, size, 3)`` of one BRDF on the sphere;
    the environment uniforms come from ``default_rng(seed)``.

    Parameters
    ----------
    brdf : BRDF
        The material.
    light : DirectionalLight
        The directional light.
    size : int
        Image side (pixels).
    env_map : ndarray
        Lat-long environment ``(H, W, 3)`` (:func:`microfacet.render.procedural_sky`).
    spp : int
        Environment samples per pixel.
    seed : sequence of int
        Seed of the environment samples.

    Returns
    -------
    direct, environment : ndarray
        The two ``(size, size, 3)`` images (0 outside the sphere).

    Examples
    --------
    >>> from microfacet import GGX, MicrofacetBRDF
    >>> direct, lit = render_panel(MicrofacetBRDF(GGX(alpha=0.3)), LIGHT, 8, procedural_sky(8, 16), 1, (0,))
    >>> direct.shape, lit.shape
    ((8, 8, 3), (8, 8, 3))
    >>> bool(direct.max() > 0)
    True
    """
    sphere = _sphere(size)
    direct = shade_directional(brdf, sphere.wo, sphere.to_local(light.w), light.rgb)
    lit = shade_environment(brdf, sphere.wo, sphere.frame, Environment(env_map), spp,
                            np.random.default_rng(list(seed)))
    return sphere.image(direct), sphere.image(lit)


class _Deferred:
    """A task of :class:`_Inline`, run when its result is asked for (like a Future)."""

    def __init__(self, fn, args):
        self.fn, self.args = fn, args

    def result(self):
        if self.args is not None:                  # run once; asked again, the same result
            self.value, self.args = self.fn(*self.args), None
        return self.value


class _Inline:
    """Stand-in for a process pool: tasks run in this process, one at a time."""

    def submit(self, fn, *args) -> _Deferred:
        return _Deferred(fn, args)


def _ignore_sigint(parent: int | None = None) -> None:
    """Worker initializer: Ctrl-C is handled by the parent, which cancels the pool; the
    worker exits when the demo's process ``parent`` ends (``kill -9`` included)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        from .batch.workers import exit_with
        exit_with(parent)


@contextlib.contextmanager
def _pool(workers: int):
    """A pool of ``workers`` fresh (spawned) processes, or :class:`_Inline` for one; on
    exit, tasks not started yet are cancelled (an error or Ctrl-C stops promptly)."""
    if workers <= 1:
        yield _Inline()
        return
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_ignore_sigint, initargs=(os.getpid(),))
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _figure_html(fig: DemoFigure, cells: dict[str, tuple[str, str]], lobes: str, spp: int) -> str:
    rows = []
    d = fig.light.w
    direct = "directional" if fig.light == LIGHT else f"directional from ({d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f})"
    for light, col in ((direct, 0), (f"environment, {spp} spp", 1)):
        for name, row in fig.rows:
            label = f"{name}, {light}" if name else light
            rows.append((label, [(f"{fig.key}/{cells[p.key][col]}", p.caption) for p in row]))
    plane = ("planes of incidence at azimuth " + ", ".join(f"{p:g}°" for p in fig.lobe_planes_deg)
             if len(fig.lobe_planes_deg) > 1 else "plane of incidence at azimuth 0° (xz)")
    lobe_caption = (f"f_r cos θi (luminance) in the {plane} for view angles θo = "
                    + ", ".join(f"{v:g}°" for v in fig.lobe_views_deg)
                    + " (thin lines: view directions); linear radial axis, own scale per panel.")
    return (f'<section id="{fig.key}"><h2>{escape(fig.title)}</h2><p>{escape(fig.caption)}</p>'
            f"{html_grid(rows)}"
            f"{html_figure(f'{fig.key}/{lobes}', lobe_caption, alt=fig.title + ' lobes', css_class='lobes')}"
            "</section>")


def _intro_html(size: int, spp: int, seed: int) -> str:
    d = LIGHT.w
    return (
        "<p>What Figs. 2.2–2.6 of the thesis show, rendered by <code>microfacet demo</code>: "
        "microfacet BRDFs f_r = F D G / (4 cos θi cos θo) (Eq. 2.1) on an orthographic unit "
        f"sphere ({size}×{size} px, 4×4 coverage antialiasing at the silhouette, shaded once per "
        "pixel). Local frame per pixel: z = normal, x = world x (image right) projected on the "
        "tangent plane.</p><ul>"
        f"<li><b>Directional light</b>: L = E f_r cos θi, toward ({d[0]:.3f}, {d[1]:.3f}, {d[2]:.3f}) "
        f"(up-left, 35° from the view, unless a figure says otherwise), E = {LIGHT.irradiance:g}; "
        "exact, no sampling.</li>"
        f"<li><b>Environment</b>: the lat-long map below (sky, ground, a warm key softbox and a cool "
        f"rim light), integrated by importance sampling with the BRDF's own <code>sample</code>: "
        f"L ≈ mean(weight · L_env(wi)), {spp} samples per pixel (Sobol' points, random digital "
        f"shift per pixel), seed {seed}.</li>"
        f"<li><b>Previews</b>: linear radiance × 2^exposure ({EXPOSURE:g} stops), clipped to [0, 1], sRGB "
        "encoded, 8 bit. Each PNG has an EXR (float32, linear) beside it.</li></ul>"
        f"<p>Reproduce: <code>microfacet demo -o DIR --size {size} --spp {spp} --seed {seed}</code> "
        "(the result does not depend on <code>--jobs</code>).</p>"
        + html_figure("environment.png", "Environment (lat-long, 128×64; centre = toward the viewer, "
                      "top = zenith).", css_class="env"))


def default_workers() -> int:
    """Worker processes for the demo: the CPUs this process may use, at most 4.

    Returns
    -------
    int
        Between 1 and 4.

    Examples
    --------
    >>> 1 <= default_workers() <= 4
    True
    """
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(4, cpus))


LEADR_LEVELS = (1, 2, 3, 4, 5)
LEADR_STEPS = 2 * 3 * len(LEADR_LEVELS)   # progress steps of leadr_section (lights x images x levels)
GLINTS_STEPS = 4                           # progress steps of glints_section
MITSUBA_STEPS = 16                         # progress steps of microfacet.mitsuba.demo (tested equal)


def _optional_section(key: str, title: str, install: str, render, errors) -> str:
    """``render()``'s section, or one that says why it is missing (``errors``: a missing
    optional package or system piece), with a warning."""
    try:
        return render()
    except errors as e:
        why = " ".join(str(e).split())
        warnings.warn(f"demo: {title} section skipped: {why}", RuntimeWarning, stacklevel=3)
        return (f'<section id="{key}"><h2>{escape(title)}</h2>'
                f"<p>Skipped on this machine: {escape(why)} ({escape(install)}).</p></section>")


#: Size (px) of the real-time section's 3D shots: three side by side fill the report's
#: 1200 px column at about this width, so larger frames would only be scaled down (and a
#: supersampled reference frame costs seconds per 10^5 pixels in Chromium's SwiftShader).
VIEWER_SCENE_SIZE = (360, 225)


def _viewer_section(out) -> str:
    """The real-time section (WebGL2 viewer in headless Chromium)."""
    def render():
        from .glsl import demo_section
        return demo_section(out, scene_size=VIEWER_SCENE_SIZE)
    return _optional_section("viewer", "Real time: GLSL and the WebGL2 viewer",
                             "make setup installs Chromium and Playwright", render, (ImportError, MicrofacetError))


def _exports_section(out, example: FitExample, fit_file: Path) -> str:
    """One fitted material's best analytic fit rendered by the library, Blender (Cycles),
    three.js and MaterialX (:func:`microfacet.export.consumers.consumer_section`)."""
    def render():
        from .export import choose_model
        from .export.consumers import consumer_section
        name, brdf, _ = choose_model(fit_file)
        return consumer_section(brdf, out / "exports", f"{example.label}: its {name} fit", href="exports/")
    return _optional_section("exports", "Exported materials in Blender, three.js and MaterialX",
                             "make setup-blender, make setup-npm", render, (ImportError, MicrofacetError, OSError))


def _mitsuba_section(out, progress=None, fits=None) -> str:
    """The Mitsuba 3 section (no Mitsuba, or a Mitsuba that cannot run a variant: a note);
    ``fits``: ``[(FitExample, fit file)]`` whose best fits it renders."""
    def render():
        from .mitsuba.demo import demo_section
        return demo_section(out, progress=progress, fits=fits)
    return _optional_section("mitsuba", "Rendering in Mitsuba 3", "pip install 'microfacet[mitsuba]'", render,
                             (ImportError, RuntimeError))


def run_demo(out_dir, size: int = DEFAULT_SIZE, spp: int = DEFAULT_SPP, seed: int = DEFAULT_SEED,
             workers: int = 1, progress: bool = False,
             figures: Sequence[DemoFigure] | None = None,
             fits: Sequence[FitExample] | None = None, leadr: bool = True, glints: bool = True,
             viewer: bool = True, mitsuba: bool = True, exports: bool = True) -> Path:
    """Render every figure into ``out_dir`` and write ``out_dir/index.html`` (last).

    The output depends only on ``size``, ``spp`` and ``seed`` (not on ``workers``): the
    environment samples of panel ``j`` of figure ``i`` come from
    ``default_rng([seed, i, j])``. All or nothing, as ``microfacet fit``: the files are
    rendered into a hidden staging folder inside ``out_dir`` and moved into place only when
    every one is written (``index.html`` last); a demo that fails (a full disk, Ctrl-C)
    leaves ``out_dir`` as it was (:func:`microfacet.io.atomic.staging_folder`).

    Parameters
    ----------
    out_dir : path-like
        Output folder, created if needed; existing demo files in it are replaced.
    size, spp, seed : int
        Sphere image side (pixels), environment samples per pixel, random seed. Below 64
        pixels (quick runs, tests) the LEADR and glints sections use small maps as well.
    workers : int
        Processes rendering panels in parallel (1: all in this process).
    progress : bool
        Show a tqdm progress bar on stderr.
    figures : sequence of DemoFigure, optional
        Defaults to :func:`thesis_figures`.
    fits : sequence of FitExample, optional
        Materials of the fitting section (:func:`fit_section`); defaults to
        :func:`fit_materials` (the shared corpus's :data:`CORPUS_MATERIALS`, else the
        built-in :func:`fit_examples`; below 64 pixels the first one only), an empty
        sequence leaves the section out. The Mitsuba section renders their best fits.
    leadr : bool
        Include the LEADR section (Fig. 5.3: naive MIP vs LEADR against a supersampled
        reference, :func:`microfacet.leadr.figures.leadr_section`).
    glints : bool
        Include the glints section (patch BRDF of a procedural scratched normal map against
        naive per-pixel sampling, :func:`microfacet.glints.figures.glints_section`).
    viewer : bool
        Include the real-time section (the WebGL2 viewer's renders in headless Chromium
        beside the NumPy renders, :func:`microfacet.glsl.demo_section`); where Playwright or
        Chromium is missing the section says so and a warning is printed.
    mitsuba : bool
        Include the Mitsuba 3 section (the ``microfacet.mitsuba`` plugins in scenes,
        :func:`microfacet.mitsuba.demo.demo_section`); where Mitsuba is missing the section
        says so and a warning is printed.
    exports : bool
        Include the exports section: the first fitting material's best fit exported to
        Blender, glTF and MaterialX and rendered by Cycles, three.js and MaterialX beside the library
        (:func:`microfacet.export.consumers.consumer_section`); a consumer that is not
        installed is named with what installs it.

    Returns
    -------
    Path
        The path of ``index.html``.

    Raises
    ------
    ValueError
        Where ``size``, ``spp`` or ``workers`` is not an integer in range.
    MicrofacetError
        Where ``out_dir`` is empty or not a folder.

    Examples
    --------
    >>> run_demo("demo-output", size=48, spp=4)      # doctest: +SKIP
    PosixPath('demo-output/index.html')
    >>> run_demo("demo-output", size=4)
    Traceback (most recent call last):
    ...
    ValueError: size must be an integer >= 8, got 4
    """
    for name, v, lo in (("size", size, 8), ("spp", spp, 1), ("workers", workers, 1)):
        if isinstance(v, bool) or int(v) != v or v < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    size, spp, seed = int(size), int(spp), int(seed)
    if not os.fspath(out_dir).strip():
        raise MicrofacetError("demo output folder: empty name; give a folder (e.g. -o demo-output)")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise MicrofacetError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with staging_folder(out, last="index.html") as stage:
        _render_demo(stage, size, spp, seed, int(workers), progress, figures, fits, leadr, glints, viewer, mitsuba,
                     exports)
    return out / "index.html"


class _Clock:
    """Logs (:data:`log`, INFO) the wall time of each step of the demo and when it ended."""

    def __init__(self):
        self.start = time.perf_counter()

    @contextlib.contextmanager
    def __call__(self, name: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            now = time.perf_counter()
            log.info("demo: %s: %.1f s (ended at %.1f s)", name, now - t, now - self.start)


def _leadr_task(out: Path, size: int) -> tuple[str, float]:
    """The LEADR section (:func:`microfacet.leadr.figures.leadr_section`) of a demo of
    ``size``, as a task of the demo's pool: its HTML and its wall time (s)."""
    from .leadr.figures import leadr_section
    start = time.perf_counter()
    fine = 256 if size >= 64 else 64          # small demos (tests) get a small map
    html = leadr_section(out, size=fine, levels=LEADR_LEVELS, display=2 * size)
    return html, time.perf_counter() - start


def _render_demo(out: Path, size: int, spp: int, seed: int, workers: int, progress: bool, figures, fits,
                 leadr: bool, glints: bool, viewer: bool, mitsuba: bool, exports: bool = False) -> Path:
    """:func:`run_demo`'s files, written into the (staging) folder ``out``."""
    figures = thesis_figures() if figures is None else list(figures)
    env_map = procedural_sky()
    examples, note = fit_materials(quick=size < 64) if fits is None else (list(fits), "")
    work = out / ".fits"                                   # the fit files: not part of the report
    total = (sum(len(f.panels) + 1 for f in figures) + 1 + len(examples) + (LEADR_STEPS if leadr else 0)
             + (GLINTS_STEPS if glints else 0) + (MITSUBA_STEPS if mitsuba else 0))
    clock = _Clock()
    with _pool(int(workers)) as pool, \
            tqdm(total=total, disable=not progress, unit="step", desc="microfacet demo", leave=False) as bar:
        # the pool: the panels (short tasks, wanted first), the fits, the LEADR section; meanwhile
        # this process renders the other sections that need no pool result (the viewer's work
        # is mostly Chromium's), then collects the panels, then the sections that need the fits
        tasks = [[pool.submit(render_panel, p.brdf, f.light, size, env_map, spp, (seed, i, j))
                  for j, p in enumerate(f.panels)] for i, f in enumerate(figures)]
        fit_tasks = [pool.submit(fit_and_picture, ex, work, size) for ex in examples]
        leadr_task = pool.submit(_leadr_task, out, size) if leadr else None   # needed last: after the fits
        _save(out, "environment", env_map)
        bar.update(1)
        later = {}                                        # sections rendered now, placed later
        if viewer:
            with clock("viewer"):
                later["viewer"] = _viewer_section(out)
        if glints:
            from .glints.figures import glints_section
            small = {} if size >= 64 else {"map_size": 128, "width": 64, "reference_spp": 32, "naive_spp": 4}
            with clock("glints"):
                later["glints"] = glints_section(out, progress=bar.update, **small)
        sections = [_intro_html(size, spp, seed)]
        with clock("figures 2.2-2.6 (lobes; panels from the pool)"):
            for fig, fig_tasks in zip(figures, tasks, strict=True):
                (out / fig.key).mkdir(exist_ok=True)
                save_lobe_figure(out / fig.key / "lobes.png", [p.brdf for p in fig.panels],
                                 [f"{name} {p.label}".strip() for name, row in fig.rows for p in row],
                                 fig.lobe_views_deg, fig.lobe_planes_deg,
                                 ncols=max(len(r) for _, r in fig.rows))
                bar.update(1)
                cells = {}
                for panel, task in zip(fig.panels, fig_tasks, strict=True):
                    direct, lit = task.result()
                    cells[panel.key] = (_save(out / fig.key, f"{panel.key}-directional", direct),
                                        _save(out / fig.key, f"{panel.key}-environment", lit))
                    bar.update(1)
                sections.append(_figure_html(fig, cells, "lobes.png", spp))
        if mitsuba:                                       # its scenes without fits first, then it waits for them
            def fitted():
                with clock("waiting for the fits (Mitsuba)"):
                    return [(ex, task.result()["npz"]) for ex, task in zip(examples, fit_tasks, strict=True)]
            with clock("Mitsuba"):
                later["mitsuba"] = _mitsuba_section(out, progress=bar.update, fits=fitted if examples else None)
        if examples:
            with clock("fitting section"):
                sections.append(fit_section(out, size, examples, progress=bar.update, results=fit_tasks, note=note))
        if leadr:
            with clock("waiting for LEADR"):
                later["leadr"], seconds = leadr_task.result()
            log.info("demo: LEADR: %.1f s (in its worker)", seconds)
            bar.update(LEADR_STEPS)
        sections += [later[k] for k in ("leadr", "glints", "mitsuba") if k in later]
        if exports and examples:
            with clock("exports"):
                sections.append(_exports_section(out, examples[0], work / f"{examples[0].key}.npz"))
        if viewer:
            sections.append(later["viewer"])
    shutil.rmtree(work, ignore_errors=True)
    title = "microfacet demo — thesis Figs. 2.2–2.6, fitting (Ch. 4), LEADR (Fig. 5.3) and glints"
    index = write_text(out / "index.html", html_page(title, "\n".join(sections)))
    log.info("demo: all sections: %.1f s", time.perf_counter() - clock.start)
    return index
