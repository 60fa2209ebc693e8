"""One material rendered by the library and by the real consumers of its exports, side by side.

:func:`consumer_renders` draws an analytic BRDF tree on the comparison sphere (orthographic,
one directional light of irradiance 1; :class:`microfacet.render.Sphere` at the pixel centres)
with the library, with Blender's Cycles (the exported ``.blend``: :mod:`.blender`), with
three.js in Chromium (the exported ``.glb``: :mod:`.threejs`) and with MaterialX's
``GlslRenderer`` under Xvfb (the exported ``.mtlx``: :mod:`.mtlx_render`), each consumer that
is installed, and measures each image's relL1 (``sum |a - b| / sum |b|`` over ``r < 0.95``) against the
library's. :func:`consumer_section` writes the PNGs and returns an HTML section for a demo page.

Examples
--------
>>> CONSUMERS                                   # the names consumer_renders(consumers=...) takes
('Blender (Cycles)', 'three.js', 'MaterialX')
>>> import microfacet as mf
>>> renders, errors, missing = consumer_renders(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)))   # doctest: +SKIP
>>> errors["Blender (Cycles)"] < 0.005                                                  # doctest: +SKIP
True
"""
from __future__ import annotations

import html
import tempfile
from pathlib import Path

import numpy as np

from .._colour import LUMINANCE
from .comparison import LIGHT, library_render, rel_l1

__all__ = ["consumer_renders", "consumer_section", "CONSUMERS"]

#: The consumers :func:`consumer_renders` can render with, by name.
CONSUMERS = ("Blender (Cycles)", "three.js", "MaterialX")


def consumer_renders(brdf, size: int = 64, spp: int = 4, light=LIGHT, three=None,
                     consumers=CONSUMERS) -> tuple[dict, dict, dict]:
    """``(images, errors, missing)``: ``{"microfacet": ..., "Blender (Cycles)": ...,
    "three.js": ..., "MaterialX": ...}`` renders, each consumer's relL1 against the library's, and
    ``{consumer: why it was not rendered}`` for those not installed (one line each).
    ``images`` also holds ``"glTF as held"``: the library's render of the glTF material
    as exported (one lobe + base: what the format can hold), against which three.js's
    own fidelity is ``errors["three.js vs glTF as held"]``; MaterialX's, against the library's
    render of what its pbrlib graph holds (:func:`~.mtlx_render.mtlx_as_held`), is
    ``errors["MaterialX vs graph as held"]``. ``three``: an open
    :class:`~microfacet.export.threejs.ThreeRenderer` to use (Playwright's sync API runs one
    browser session per thread), else one is opened and closed here.

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree.
    size : int
        Image width and height in pixels.
    spp : int
        Cycles samples per pixel.
    light : (3,) sequence
        Direction toward the light.
    three : ThreeRenderer, optional
        An open renderer to reuse.
    consumers : sequence of str
        Which of :data:`CONSUMERS` to render with (default all).

    Returns
    -------
    images : dict
        Name -> ``(size, size, 3)`` linear radiance.
    errors : dict
        Name -> relL1 (:func:`~microfacet.export.comparison.rel_l1`) against the library's image.
    missing : dict
        Consumer -> why it was not rendered.

    Examples
    --------
    Blender, three.js and MaterialX must be installed (``make setup-blender``, ``make setup-npm``,
    ``make setup``):

    >>> import microfacet as mf
    >>> images, errors, missing = consumer_renders(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), size=32)  # doctest: +SKIP
    >>> sorted(errors)                                                                            # doctest: +SKIP
    ['Blender (Cycles)', 'MaterialX', 'MaterialX vs graph as held', 'glTF as held', 'three.js', 'three.js vs glTF as held']
    """
    from .blender import blender_material, blender_python, render_cycles, write_blend
    from .gltf import gltf_brdf, gltf_material, write_glb
    from .threejs import ThreeRenderer, chromium, npm_modules
    unknown = sorted(set(consumers) - set(CONSUMERS))
    if unknown:
        raise ValueError(f"consumers: unknown {unknown}; choose from {list(CONSUMERS)}")
    images = {"microfacet": library_render(brdf, size, light)}
    missing = {}
    with tempfile.TemporaryDirectory() as tmp:
        if "Blender (Cycles)" not in consumers:
            pass
        elif blender_python(required=False) is None:
            missing["Blender (Cycles)"] = "bpy absent: make setup-blender"
        else:
            desc, _ = blender_material(brdf)
            blend = write_blend(desc, Path(tmp) / "m.blend")
            images["Blender (Cycles)"] = render_cycles(blend, size=size, spp=spp)
        if "three.js" not in consumers:
            pass
        elif npm_modules(required=False) is None or chromium(required=False) is None:
            missing["three.js"] = "three.js or Chromium absent: make setup-npm, apt-get install chromium"
        else:
            mat, _ = gltf_material(brdf)
            glb = write_glb(mat, Path(tmp) / "m.glb")
            if three is not None:
                images["three.js"] = three.render(glb, size, light)
            else:
                with ThreeRenderer() as r:
                    images["three.js"] = r.render(glb, size, light)
            images["glTF as held"] = library_render(gltf_brdf(mat), size, light)
    held = _materialx(brdf, size, light, images, missing) if "MaterialX" in consumers else None
    errors = {k: rel_l1(v, images["microfacet"]) for k, v in images.items() if k != "microfacet"}
    if "three.js" in images:
        errors["three.js vs glTF as held"] = rel_l1(images["three.js"], images["glTF as held"])
    if held is not None:
        errors["MaterialX vs graph as held"] = rel_l1(images["MaterialX"], held)
    return images, errors, missing


def _materialx(brdf, size: int, light, images: dict, missing: dict):
    """MaterialX's render of the exported pbrlib graph into ``images["MaterialX"]`` and the
    library's render of what the graph holds (returned), or why not into ``missing``."""
    try:
        import MaterialX  # noqa: F401
        import MaterialX.PyMaterialXRenderGlsl  # noqa: F401
    except ImportError:
        missing["MaterialX"] = "MaterialX absent: pip install 'microfacet[export]'"
        return None
    from .mtlx import mtlx_document
    from .mtlx_render import mtlx_as_held, render_mtlx, xvfb_available
    if not xvfb_available():
        missing["MaterialX"] = "no DISPLAY and no Xvfb: apt-get install xvfb"
        return None
    doc, _ = mtlx_document(brdf)
    try:
        images["MaterialX"] = render_mtlx(doc, size, light=light)
    except RuntimeError as e:                 # no X display after all, or OpenGL failed
        missing["MaterialX"] = " ".join(str(e).split())
        return None
    return library_render(mtlx_as_held(brdf), size, light)


def consumer_section(brdf, out, label: str, size: int = 64, spp: int = 4, href: str = "", three=None,
                     consumers=CONSUMERS) -> str:
    """Render :func:`consumer_renders`, write ``consumers_<n>.png`` under ``out`` (one exposure
    for all, :func:`microfacet.io.write_png`) and return an HTML ``<section>`` with the
    pictures (``href``: the prefix of their links, e.g. ``"exports/"`` for a page one folder
    up) and each consumer's error against the library (``three``: as :func:`consumer_renders`).

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree.
    out : str or os.PathLike
        Folder of the PNGs (created).
    label : str
        The material's name in the section's title.
    size, spp : int
        As :func:`consumer_renders`.
    href : str
        Prefix of the pictures' links.
    three : ThreeRenderer, optional
        As :func:`consumer_renders`.
    consumers : sequence of str
        As :func:`consumer_renders`.

    Returns
    -------
    str
        The HTML ``<section id="consumers">``.

    Examples
    --------
    >>> import microfacet as mf
    >>> html = consumer_section(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), "exports", "GGX 0.2")   # doctest: +SKIP
    >>> html.startswith('<section id="consumers">')                                          # doctest: +SKIP
    True
    """
    from ..io import write_png
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    images, errors, missing = consumer_renders(brdf, size, spp, three=three, consumers=consumers)
    lum = images["microfacet"] @ LUMINANCE
    top = float(np.percentile(lum[lum > 0], 99.5)) if np.any(lum > 0) else 1.0
    exposure = float(np.log2(1.0 / top)) if top > 0 else 0.0
    cells = []
    for i, (name, img) in enumerate(images.items()):
        stem = f"consumers_{i}.png"
        write_png(out / stem, img, exposure)
        note = "reference" if name == "microfacet" else f"relL1 {100 * errors[name]:.2f} %"
        if name == "three.js":
            note += f" ({100 * errors['three.js vs glTF as held']:.2f} % against the glTF material as held)"
        if name == "MaterialX":
            note += f" ({100 * errors['MaterialX vs graph as held']:.4f} % against the pbrlib graph as held)"
        cells.append(f'<figure><img src="{href}{stem}" alt="{html.escape(name)}"><figcaption>{html.escape(name)}: '
                     f"{note}</figcaption></figure>")
    cells += [f"<p>{html.escape(k)}: not rendered ({html.escape(v)})</p>" for k, v in missing.items()]
    return (f'<section id="consumers"><h2>{html.escape(label)} in Blender, three.js and MaterialX</h2>'
            "<p>The exported material (.blend, .glb, .mtlx) rendered by each consumer under one directional light, "
            "multiple-scattering boosts off, against the library's render of the fit. \"glTF as held\" is the library's "
            "render of what a glTF material can hold (one lobe and a base): its difference from the fit is the export's own, "
            "not three.js's. MaterialX renders the exact pbrlib graph (every lobe, each Fresnel table as its "
            "least-squares Schlick pair); its error against what that graph holds is MaterialX's own.</p>" + "".join(cells) + "</section>")
