"""The viewer in ``make demo``: screenshots of ``microfacet view`` taken by headless
Chromium beside the library's NumPy renders of the same views (thesis Fig. 5.3 setup)."""
from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from ..io import html_grid, write_png
from ..io.atomic import atomic_path
from ..leadr import bake, figures, write_pyramid
from .browser import open_viewer
from .server import load_viewer_data

__all__ = ["demo_section"]

_METHODS = {"naive": 0, "leadr": 1, "reference": 2}
_LABELS = {"naive": "naive MIP", "leadr": "LEADR", "reference": "supersampled reference"}


def _upscale(image, size):
    f = max(1, round(size / image.shape[0]))
    return np.repeat(np.repeat(image, f, axis=0), f, axis=1)


def demo_section(out, size: int = 64, levels=(2, 4), base: float = 0.1, display: int = 128,
                 scene_size: tuple[int, int] = (640, 400)) -> str:
    """Render the viewer section under ``out/viewer/`` and return its HTML.

    A ``size``² map (``figures.default_heightfield``) is baked and served; for each light
    (point, environment), MIP level and method, the browser's render of the patch
    (``mfViewer.renderPatch``) is saved beside ``figures.render_level``'s NumPy render, with
    their mean relative difference; then screenshots of the 3D scene per method, ``scene_size``
    (width, height) pixels, each the frame its time per frame was measured on. Needs
    Playwright and a system Chromium (:func:`microfacet.glsl.browser.chromium_path`).

    Parameters
    ----------
    out : str or os.PathLike
        The demo's folder (``out/viewer/`` is written).
    size : int
        The baked map's size in texels.
    levels : tuple of int
        The MIP levels compared.
    base : float
        The base material's Beckmann alpha.
    display : int
        Size in pixels of the pictures on the page.
    scene_size : (int, int)
        Width and height of the 3D scene's screenshots.

    Returns
    -------
    str
        The HTML section.

    Examples
    --------
    The map it bakes, then the section (Chromium renders it):

    >>> figures.default_heightfield(16, 3).shape
    (16, 16)
    >>> html = demo_section("demo", size=16, levels=(2,), display=64, scene_size=(160, 100))   # doctest: +SKIP
    >>> (Path("demo") / "viewer" / "map.exr").is_file()                                        # doctest: +SKIP
    True
    """
    folder = Path(out) / "viewer"
    folder.mkdir(parents=True, exist_ok=True)
    pyramid = folder / "map.exr"
    write_pyramid(pyramid, bake(figures.default_heightfield(size, 3), 1.0))
    data = load_viewer_data(pyramid, roughness=base)
    scene = figures.PatchScene()
    env = scene.environment()
    blocks = []
    width, height = scene_size
    with open_viewer(data, width, height) as page:
        for light, kind in enumerate(("point", "env")):
            rows = {m: [] for m in _METHODS}
            exposure = None
            for level in levels:
                n = size >> level
                for method, m in _METHODS.items():
                    got = np.array(page.evaluate(f"mfViewer.renderPatch({{method: {m}, level: {level}, "
                                                 f"light: {light}}})")).reshape(n, n, 4)[..., :3]
                    ref = figures.render_level(method, level, data.leadr[0], data.naive, data.leadr, scene, kind, env)
                    if exposure is None:
                        top = float(np.percentile(ref, 99.0))
                        exposure = float(np.log2(1.0 / top)) if top > 0 else 0.0
                    err = float(np.mean(np.abs(got - ref)) / max(np.mean(np.abs(ref)), 1e-300))
                    for who, img in (("browser", got), ("numpy", ref)):
                        write_png(folder / f"{kind}_{method}_level{level}_{who}.png", _upscale(img, display), exposure)
                    rows[method] += [(f"viewer/{kind}_{method}_level{level}_browser.png",
                                      f"browser {n}x{n} (diff {100 * err:.1e}%)"),
                                     (f"viewer/{kind}_{method}_level{level}_numpy.png", f"NumPy {n}x{n}")]
            title = "point light" if kind == "point" else "environment (5 x 5 grid)"
            blocks.append(f"<h3>{escape(title)}</h3>" + html_grid([(_LABELS[m], rows[m]) for m in _METHODS]))
        shots = []
        page.evaluate("() => { for (const id of ['bar', 'help']) document.getElementById(id).style.display = 'none'; }")
        for method, m in _METHODS.items():
            # the canvas keeps the benchmark's last frame (preserveDrawingBuffer): the screenshot
            # is that frame, not drawn again (a reference frame takes seconds in SwiftShader)
            ms = page.evaluate(f"mfViewer.benchmark({{method: {m}, light: 1, supersampling: 4, width: {width}, "
                               f"height: {height}, frames: 1}})")
            page.evaluate(f"() => {{ Object.assign(mfViewer.state, {{method: {m}, light: 1, supersampling: 4}}); }}")
            with atomic_path(folder / f"scene_{method}.png") as tmp:
                page.locator("canvas").screenshot(path=str(tmp), type="png")
            shots.append((f"viewer/scene_{method}.png", f"{_LABELS[method]}, {ms:.0f} ms/frame"))
        errors = list(page.errors)
    blocks.append(f"<h3>3D view (plane + sphere), environment light, 4x4 reference, {width}x{height} px</h3>"
                  + html_grid([("microfacet view", shots)]))
    intro = (f"The WebGL2 viewer ('microfacet view', the package's GLSL ES 3.00 shaders) in headless Chromium "
             f"(SwiftShader), on a {size}x{size} displacement map merged with a Beckmann base (alpha {base:g}, "
             "silver): the patch of the LEADR section rendered per MIP level by naive MIP, LEADR and the "
             "supersampled reference, each beside the library's NumPy render of the same camera and light "
             "(captions: mean relative difference), then the interactive scene."
             + (f" Console errors: {'; '.join(errors)}" if errors else ""))
    return ('<section id="viewer"><h2>Real time: GLSL shaders in the WebGL2 viewer</h2>'
            f"<p>{escape(intro)}</p>" + "".join(blocks) + "</section>")
