"""A glint microsurface (``microfacet glints``'s ``.npz``) out of the library: the three.js
material of the glint P-BRDF (Chermain, Claux and Mérillou 2019) in a folder a user serves.

``export_glints(source, "threejs", out)`` writes the folder ``out``
(:func:`microfacet.export.glints_threejs.export_glints_threejs`): ``index.html`` (a plane
under a circling point light), the ES module ``glints-material.js`` (``loadGlintLobes``,
``createGlintMaterial``: the library's ``glints.glsl`` in a ``THREE.ShaderMaterial``),
``lobes.json`` / ``lobes.bin`` (the lobe textures, every MIP level) and, where three.js is
installed (``make setup-npm``), three.js itself in ``three/`` (else the page imports it from
:data:`~microfacet.export.glints_threejs.THREE_URL`). Beside it, the report
``out.export.json`` / ``out.export.md``: what the material does not carry, why no standard
format holds a glint P-BRDF (:data:`NOT_HELD`), and the image error of the three.js render
against the library's own render (:func:`microfacet.glints.figures.render_pbrdf`) of the same
plane, light and pixel footprints, measured at export time in the system Chromium
(:class:`~microfacet.export.glints_threejs.GlintsRenderer`) with the folder's own module; where
Chromium, playwright or three.js are absent the report says so instead of a figure.

Accuracy (the measured figure): float32 rounding (relL1 ~1e-6) where each pixel's lobe
window fits ``max_window`` lobes per axis; footprints wider than that are summed over a coarser
lobe level, an approximation (relL1 ~0.1 on a 1024² map at 64 px; the report names the level).

glTF, MaterialX, USD and Blender cannot hold the P-BRDF: :func:`unsupported_message` says why
in one line and what to use instead.

Examples
--------
>>> import numpy as np, microfacet as mf
>>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((8, 8, 2)))
>>> report = export_glints(ms.save("scratches.npz"), "threejs", "scratches_web", measure=False)
>>> report["file"], report["format"], "lobes.bin" in report["files"]
('scratches_web', 'threejs', True)
>>> is_microsurface("scratches.npz"), is_microsurface("missing.npz")
(True, False)
>>> GLINT_TARGETS, sorted(NOT_HELD), NOT_CARRIED[0].startswith("Fresnel")
(('threejs',), ['blender', 'gltf', 'mtlx', 'usd'], True)
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError

__all__ = ["GLINT_TARGETS", "NOT_HELD", "NOT_CARRIED", "is_microsurface", "unsupported_message", "export_glints",
           "window_level", "measure_threejs", "run_cli"]

#: Targets of a glint microsurface.
GLINT_TARGETS = ("threejs",)

#: Per standard format: why it cannot hold the glint P-BRDF.
NOT_HELD = {
    "gltf": "glTF 2.0 has one GGX lobe per texel (metallicRoughness, KHR_materials_anisotropy) evaluated at the "
            "shading point, and no custom shaders (KHR_techniques_webgl is archived)",
    "mtlx": "MaterialX's BSDF nodes are closed lobes evaluated at the shading point; a custom node would need "
            "shader source per code generator, which other MaterialX consumers do not share",
    "usd": "UsdPreviewSurface has one lobe per texel, and the MaterialX it binds has the same limits",
    "blender": "Cycles and EEVEE closures are fixed lobes (an OSL script composes them and cannot return a BRDF "
               "value per light direction)",
}
_OTHER = {"textures": "engine textures carry one filtered lobe per texel and MIP level (a LEADR pyramid's)",
          "ktx2": "KTX2 MIP chains carry one filtered lobe per texel and MIP level (a LEADR pyramid's)"}
#: The common reason, after each format's own.
_WHY = ("the glint P-BRDF sums a pixel footprint's noncentred Beckmann lobes (Chermain et al. 2019, Eq. 7-17): "
        "it needs the pixel's footprint and the lobe textures at every shading point")
_INSTEAD = ("use --to threejs (a WebGL2 material of the P-BRDF), the Mitsuba plugin mf_glints, or for a standard "
            "format the filtered normal map: 'microfacet bake MAP --normal-map -o PYRAMID.exr' then "
            "'microfacet export PYRAMID.exr --to gltf' (LEADR roughness, no glints)")

#: What the three.js material does not carry (beside the measured image error).
NOT_CARRIED = [
    "Fresnel: ideal mirror facets (F = 1), as the microsurface file holds none; createGlintMaterial's f0 option "
    "sets a Schlick F0",
    "footprints wider than maxWindow lobes per axis are summed over a coarser lobe MIP level (an approximation "
    "the library does not make)",
    "no standard format (glTF, MaterialX, USD) holds a glint P-BRDF: " + _WHY,
]

_MAGIC_NAME = "magic.npy"


def is_microsurface(source) -> bool:
    """Whether ``source`` is a glint microsurface: a
    :class:`~microfacet.glints.microsurface.LobeMixture` (``Microsurface``), or a path to an
    ``.npz`` that ``microfacet glints`` wrote (its ``magic`` entry is
    :data:`microfacet.glints.microsurface.MAGIC`). A missing or unreadable file is not one.

    Parameters
    ----------
    source : str, os.PathLike or object
        What :func:`microfacet.export.export` was given.

    Returns
    -------
    bool

    Examples
    --------
    >>> is_microsurface("nickel.npz"), is_microsurface(3.0)
    (False, False)
    """
    from ..glints.microsurface import MAGIC, LobeMixture
    if isinstance(source, LobeMixture):
        return True
    if not isinstance(source, (str, os.PathLike)) or Path(source).suffix.lower() != ".npz":
        return False
    try:
        with zipfile.ZipFile(source) as zf:
            if _MAGIC_NAME not in zf.namelist():
                return False
            with zf.open(_MAGIC_NAME) as f:
                return str(np.lib.format.read_array(f, allow_pickle=False)) == MAGIC
    except (OSError, zipfile.BadZipFile, ValueError, KeyError):
        return False


def unsupported_message(to: str, label: str = "a glint microsurface") -> str:
    """One line: why format ``to`` cannot hold the glint P-BRDF of ``label``, and what to use
    instead.

    Parameters
    ----------
    to : str
        A format of :func:`microfacet.export.export` other than ``"threejs"``.
    label : str
        The source, as named in the line.

    Returns
    -------
    str

    Examples
    --------
    >>> unsupported_message("gltf", "s.npz").startswith("s.npz: --to gltf cannot hold a glint P-BRDF (glTF 2.0 has")
    True
    """
    own = NOT_HELD.get(to) or _OTHER.get(to, f"{to!r} is not a target of a glint microsurface")
    return f"{label}: --to {to} cannot hold a glint P-BRDF ({own}; {_WHY}); {_INSTEAD}"


def window_level(ms, scene, max_window: int) -> dict:
    """The lobe level the three.js shader sums for the footprints of ``scene`` (all of one
    size, :class:`~microfacet.glints.figures.PlaneScene`): per axis, the widest lobe window
    ``floor(2 c sqrt(s_P^2 + s_k^2) n) + 1`` at level 0 (``c`` the cutoff, ``s_k`` the lobes'
    kernel, ``n`` lobes per axis; ``glints.glsl``'s ``mf_glint_window``) and the first level
    where it is at most ``max_window`` (``mf_glint_level``).

    Parameters
    ----------
    ms : LobeMixture
        The microsurface.
    scene : PlaneScene
        The rendered plane.
    max_window : int
        Lobes per axis summed at one level.

    Returns
    -------
    dict
        ``{"window": [wx, wy] at level 0, "level": k}``.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.glints.figures import PlaneScene
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((8, 8, 2)))
    >>> window_level(ms, PlaneScene(width=64), 48)["level"]
    0
    """
    from ..glints.microsurface import FWHM_PER_SIGMA
    cov = np.diag(scene.pixels()[1])
    first = None
    for k, level in enumerate(ms.mip):
        n = np.array([level.shape[1], level.shape[0]], np.float64)
        ks = 1.0 / (n * FWHM_PER_SIGMA)
        length = np.floor(2.0 * ms.cutoff * np.sqrt(cov + ks * ks) * n) + 1
        first = first or [int(v) for v in length]
        if (length <= max_window).all() or (n == 1).all():
            return {"window": first, "level": k}
    return {"window": first, "level": len(ms.mip) - 1}


def _consumer_missing() -> str | None:
    from .threejs import chromium, npm_modules
    if npm_modules(required=False) is None:
        return "three.js is not installed (make setup-npm)"
    if importlib.util.find_spec("playwright") is None:
        return "playwright is not installed (pip install playwright)"
    if chromium(required=False) is None:
        return "no system Chromium (apt-get install chromium)"
    return None


def measure_threejs(ms, folder, scene, max_window: int) -> dict:
    """The image error of the exported material: ``scene`` rendered in the system Chromium
    with ``folder``'s ``glints-material.js`` and the lobes of ``ms``
    (:class:`~microfacet.export.glints_threejs.GlintsRenderer`) against the library's
    :func:`~microfacet.glints.figures.render_pbrdf` of the same scene (exact patches,
    height-correlated G2, ideal mirror facets).

    Parameters
    ----------
    ms : LobeMixture
        The microsurface.
    folder : str or os.PathLike
        The exported folder (its ``glints-material.js`` is the module rendered).
    scene : PlaneScene
        The plane, light and image size.
    max_window : int
        Lobes per axis summed at one level.

    Returns
    -------
    dict
        ``{"measured": True, "rel_l1", "rel_mean", "correlation", "max_err" (largest
        per-pixel difference over the image's maximum), "size": [w, h], "threejs_revision",
        "seconds": {"threejs", "library"}, "window", "level"}``; or ``{"measured": False,
        "note": why}`` where a consumer is absent.

    Raises
    ------
    MicrofacetError
        The page did not start or reported an error.

    Examples
    --------
    >>> from microfacet.glints.figures import PlaneScene
    >>> e = measure_threejs(ms, "scratches_web", PlaneScene(width=32), 48)   # doctest: +SKIP
    >>> e["rel_l1"] < 1e-4                                                   # doctest: +SKIP
    True
    """
    from ..glints.figures import render_pbrdf
    missing = _consumer_missing()
    where = {"size": [scene.width, scene.height], **window_level(ms, scene, max_window)}
    if missing:
        return {"measured": False, "note": f"not measured: {missing}", **where}
    from .glints_threejs import GlintsRenderer
    t0 = time.perf_counter()
    ref = render_pbrdf(ms, scene)
    t1 = time.perf_counter()
    with GlintsRenderer() as r:
        shutil.copyfile(Path(folder) / "glints-material.js", r.root / "glints-material.js")
        t2 = time.perf_counter()
        img = r.render_scene(ms, scene, max_window=max_window)
        t3 = time.perf_counter()
        if r.errors:
            raise MicrofacetError(f"three.js page error while measuring the export: {r.errors[0]}")
        revision = r.revision
    total = float(np.abs(ref).sum())
    if total <= 0:
        return {"measured": False, "note": "not measured: the library's image is black (light below the plane?)",
                **where}
    return {"measured": True, "rel_l1": float(np.abs(img - ref).sum() / total),
            "rel_mean": float(img.mean() / ref.mean() - 1.0),
            "correlation": float(np.corrcoef(img.ravel(), ref.ravel())[0, 1]),
            "max_err": float(np.abs(img - ref).max() / np.abs(ref).max()),
            "threejs_revision": revision, "seconds": {"threejs": t3 - t2, "library": t1 - t0}, **where}


def _bundle_three(out: Path) -> str | None:
    """Copy three.js (module, core, licence) into ``out/three``; its import-map URL or None."""
    from .threejs import npm_modules
    mods = npm_modules(required=False)
    if mods is None:
        return None
    build = mods / "three" / "build"
    dest = out / "three"
    dest.mkdir(exist_ok=True)
    for name in ("three.module.js", "three.core.js"):
        if (build / name).is_file():
            shutil.copyfile(build / name, dest / name)
    if (mods / "three" / "LICENSE").is_file():
        shutil.copyfile(mods / "three" / "LICENSE", dest / "LICENSE")
    return "./three/three.module.js"


def _markdown(report: dict) -> str:
    e = report["image_error"]
    lines = [f"# Export of {report['source']} (glint microsurface) to three.js", "",
             f"Folder: `{report['file']}` ({', '.join(report['files'])}). Serve it over HTTP and open "
             f"`index.html`: `{report['serve']}` (browsers do not load ES modules from file://).", "",
             "## Image error: three.js against the library's render", ""]
    if e.get("measured"):
        lines += [f"Plane of `PlaneScene` ({e['size'][0]} x {e['size'][1]} px), the library's `render_pbrdf` "
                  f"(float64) and three.js r{e['threejs_revision']} in Chromium (float32), lobe level "
                  f"{e['level']} (footprint window {e['window'][0]} x {e['window'][1]} lobes at level 0):", "",
                  "| rel. L1 | rel. mean | correlation | max err |", "|---|---|---|---|",
                  f"| {e['rel_l1']:.2e} | {e['rel_mean']:+.2e} | {e['correlation']:.6f} | {e['max_err']:.2e} |"]
    else:
        lines += [e["note"] + "."]
    lines += ["", "## Not carried", ""] + [f"- {x}" for x in report["lost"]]
    lines += ["", "## Standard formats", ""] + [f"- {k}: {v}" for k, v in NOT_HELD.items()]
    lines += ["", f"Instead: {_INSTEAD}."]
    return "\n".join(lines) + "\n"


def _scene(width: int, view_deg: float, light, intensity: float):
    from ..glints.figures import PlaneScene
    return PlaneScene(width=int(width), view_deg=float(view_deg), light=tuple(map(float, light)),
                      intensity=float(intensity))


def export_glints(source, to: str, out, *, width: int = 512, check_width: int = 128, view_deg: float = 50.0,
                  light=(0.0, 0.35, 0.9), intensity: float = 1.0, max_window: int | None = None,
                  measure: bool = True, mesh: str = "plane") -> dict:
    """Export a glint microsurface to ``to="threejs"``: the folder ``out`` and the report
    ``out.export.json`` / ``.export.md`` beside it (module docstring); returns the report.

    Parameters
    ----------
    source : str, os.PathLike or LobeMixture
        A microsurface file of ``microfacet glints`` or a ``Microsurface``.
    to : str
        ``"threejs"``; any other format raises with :func:`unsupported_message`.
    out : str or os.PathLike
        The folder to write (created; files of the same names replaced).
    width : int
        The page's image width in pixels.
    check_width : int
        Width of the image-error render (the page's scene at this size).
    view_deg, light, intensity
        The page's plane, camera elevation and point light
        (:class:`~microfacet.glints.figures.PlaneScene`).
    max_window : int, optional
        Lobes per axis summed at one level (default
        :data:`~microfacet.export.glints_threejs.MAX_WINDOW`).
    measure : bool
        Measure the image error (needs Chromium, playwright and three.js; else a note).
    mesh : {"plane", "sphere"}
        The page's mesh (:func:`~microfacet.export.glints_threejs.export_glints_threejs`); the
        image error is measured on the plane.

    Returns
    -------
    dict
        ``{"format", "file", "files", "source", "lost", "not_held", "image_error",
        "three", "serve", "page"}``.

    Raises
    ------
    MicrofacetError
        ``to`` is not ``"threejs"`` (one line: why, and what to use), the file is not a
        microsurface, ``out`` is a file, or the measuring page failed.
    ValueError
        A scene parameter out of range.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((8, 8, 2)))
    >>> export_glints(ms, "gltf", "x")
    Traceback (most recent call last):
    ...
    microfacet.errors.MicrofacetError: a glint microsurface: --to gltf cannot hold a glint P-BRDF ...
    >>> export_glints(ms, "threejs", "web", measure=False)["image_error"]["note"]
    'not measured: measure=False'
    """
    from ..glints import Microsurface
    from .glints_threejs import MAX_WINDOW, THREE_URL, export_glints_threejs
    label = str(source) if isinstance(source, (str, os.PathLike)) else "a glint microsurface"
    if to not in GLINT_TARGETS:
        raise MicrofacetError(unsupported_message(to, label))
    max_window = MAX_WINDOW if max_window is None else max_window
    page, check = _scene(width, view_deg, light, intensity), _scene(check_width, view_deg, light, intensity)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MicrofacetError(f"{out}: exists and is not a folder (--to threejs writes a folder)")
    ms = Microsurface.load(source) if isinstance(source, (str, os.PathLike)) else source
    out.mkdir(parents=True, exist_ok=True)
    three = _bundle_three(out)
    export_glints_threejs(ms, out, width=page.width, view_deg=page.view_deg, light=page.light,
                          intensity=page.intensity, three_url=three or THREE_URL, max_window=max_window,
                          mesh=mesh)
    if measure:
        image = measure_threejs(ms, out, check, max_window)
    else:
        image = {"measured": False, "note": "not measured: measure=False", "size": [check.width, check.height],
                 **window_level(ms, check, max_window)}
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    report = {"format": to, "file": str(out), "files": files, "source": label, "lost": list(NOT_CARRIED),
              "not_held": {k: f"{v}; {_WHY}" for k, v in NOT_HELD.items()}, "instead": _INSTEAD,
              "image_error": image, "three": three or THREE_URL,
              "serve": f"python -m http.server -d {out} 8000",
              "page": {"width": page.width, "height": page.height, "view_deg": page.view_deg,
                       "light": list(page.light), "intensity": page.intensity, "max_window": max_window,
                       "mesh": mesh},
              "map": [int(v) for v in ms.resolution], "lobes": [int(ms.mip[0].shape[1]), int(ms.mip[0].shape[0])]}
    stem = str(out).rstrip("/\\")
    Path(stem + ".export.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    Path(stem + ".export.md").write_text(_markdown(report))
    return report


def run_cli(args) -> int:
    """``microfacet export GLINTS.npz --to threejs -o OUT`` (called by :mod:`microfacet.cli.export`
    for a glint microsurface): the folder, the report and one summary line; another ``--to``
    is one error line (:func:`unsupported_message`).

    Parameters
    ----------
    args : argparse.Namespace
        ``fit`` (the microsurface), ``to``, ``output``, ``model``, ``base_roughness``.

    Returns
    -------
    int
        0 (errors raise).

    Examples
    --------
    >>> import argparse
    >>> run_cli(argparse.Namespace(fit="scratches.npz", to="threejs", output="web", model="best",
    ...                            base_roughness=None))                    # doctest: +SKIP
    web: glint P-BRDF as a three.js material (8 x 8 lobes); three.js vs library relL1 ... ; report web.export.md
    0
    """
    from ..cli.common import check_output_name
    source = Path(args.fit)
    if args.to not in GLINT_TARGETS:
        raise MicrofacetError(unsupported_message(args.to, str(source)))
    if getattr(args, "model", "best") != "best":
        raise MicrofacetError("--model applies to fit files, not to a glint microsurface")
    if getattr(args, "base_roughness", None) is not None:
        raise MicrofacetError("--base-roughness applies to a LEADR pyramid, not to a glint microsurface")
    out = Path(check_output_name(args.output).rstrip("/\\") or args.output)
    report = export_glints(source, args.to, out, mesh=getattr(args, "mesh", None) or "plane")
    e = report["image_error"]
    figure = (f"three.js vs library relL1 {e['rel_l1']:.2e} at {e['size'][0]} px (lobe level {e['level']})"
              if e["measured"] else e["note"])
    print(f"{report['file']}: glint P-BRDF as a three.js material ({report['lobes'][0]} x {report['lobes'][1]} "
          f"lobes); {figure}; report {report['file']}.export.md; serve: {report['serve']}")
    for line in report["lost"][:2]:
        print(f"  not carried: {line}", file=sys.stderr)
    return 0
