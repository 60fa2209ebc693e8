"""Materials leave the library: a fit or an analytic BRDF as glTF 2.0, MaterialX and USD.

``export(source, to, out)`` maps the analytic model of a fit file (``microfacet fit``'s
``OUT.npz``; ``model="best"``: the best fit by image error, or when that is the tabulated
fit the analytic fit of least image error) or any analytic BRDF tree
(:class:`~microfacet.MicrofacetBRDF` GGX/Beckmann, :class:`~microfacet.fit.SumBRDF`,
:class:`~microfacet.Lambertian`, :class:`~microfacet.layered.LayeredBRDF`) to

* ``"gltf"``: a ``.glb`` with a UV sphere and the material (:mod:`.gltf`);
* ``"mtlx"``: a ``.mtlx`` with an exact pbrlib graph and an ``open_pbr_surface`` (:mod:`.mtlx`);
* ``"usd"``: a ``.usda`` with a UsdPreviewSurface and the OpenPBR surface bound to a sphere
  (:mod:`.usd`);
* ``"blender"``: a ``.blend`` (Cycles material on a sphere, written by the interpreter that has
  ``bpy`` 4.5), its description ``OUT.blender.json`` and the add-on ``microfacet_blender.zip``
  that imports fit files (:mod:`.blender`);

and writes beside ``out`` the report ``out + ".export.json"`` / ``".export.md"``: what the
format could not carry, and the image error (:class:`microfacet.metrics.ImageError`,
Bieron & Peers 2020) of the exported material — re-read from the written file and rebuilt as
a library BRDF by the inverse mapping — against the library's fit, measured at export time
(and, for a fit file, against its tabulated fit, the closest stand-in for the data, with
the same figure for every other analytic fit of the file). The user guide "Exports" has every formula.

Examples
--------
>>> import microfacet as mf
>>> report = export(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)), "gltf", "sphere.glb")
>>> report["file"], report["image_error"]["exported_vs_fit"]["gltf"] < 1e-6
('sphere.glb', True)
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import MicrofacetError
from .analysis import Analysis, Lobe, analyse, schlick_of
from .gltf import GltfBRDF, alphas_of, gltf_brdf, gltf_material, read_material, roughness_anisotropy, write_glb
from .blender import (BlenderBRDF, blender_brdf, blender_material, blender_python, render_cycles, write_addon,
                      write_blend)
from .consumers import consumer_renders, consumer_section
from .mtlx import mtlx_document, openpbr_brdf, openpbr_inputs, pbrlib_brdf
from .leadr_textures import export_leadr, leadr_textures
from .glints_export import GLINT_TARGETS, export_glints, is_microsurface

__all__ = ["export", "choose_model", "FORMATS", "SUFFIXES", "Analysis", "Lobe", "analyse", "schlick_of",
           "GltfBRDF", "alphas_of", "gltf_brdf", "gltf_material", "read_material", "roughness_anisotropy",
           "write_glb", "mtlx_document", "openpbr_brdf", "openpbr_inputs", "pbrlib_brdf", "BlenderBRDF", "blender_brdf",
           "blender_material", "blender_python", "render_cycles", "write_addon", "write_blend", "consumer_renders",
           "consumer_section", "export_leadr", "leadr_textures", "is_pyramid",
           "export_glints", "is_microsurface", "GLINT_TARGETS"]

#: Formats of :func:`export` and the suffix of each one's file.
SUFFIXES = {"gltf": ".glb", "mtlx": ".mtlx", "usd": ".usda", "blender": ".blend"}
FORMATS = tuple(SUFFIXES)
#: Size (px) of the image-error renders measured at export time.
IMAGE_SIZE = 32


def _fit_file_models(path: Path) -> tuple[dict, dict, str]:
    """``({name: BRDF} of the analytic fits, {name: metrics} from OUT.json or {}, best)``."""
    from ..fit import fit_names, load
    names, best = fit_names(path)
    fits = {n: load(path, model=n) for n in names if n != "tabulated"}
    errors = {}
    summary = path.with_suffix(".json")
    if summary.is_file():
        try:
            data = json.loads(summary.read_text())
            errors = {n: dict(v["metrics"]) for n, v in data.get("fits", {}).items()
                      if isinstance(v, dict) and {"image", "log"} <= set(v.get("metrics", {}))}
        except (ValueError, KeyError, TypeError, AttributeError):
            errors = {}
    return fits, errors, best


def choose_model(path, model: str = "best") -> tuple[str, object, dict]:
    """``(name, brdf, image errors)`` of the fit to export from the fit file ``path``: ``model``
    by name, or for ``"best"`` the file's best fit, and when that is the tabulated fit the
    analytic fit that :func:`microfacet.fit.outputs.best_fit` chooses (metrics from
    ``OUT.json`` beside it, else measured here against the tabulated fit). ``image
    errors``: ``{name: error}`` of the analytic fits.

    Parameters
    ----------
    path : str or os.PathLike
        A fit file of ``microfacet fit`` (``OUT.npz``).
    model : str
        ``"best"`` or the name of one of the file's analytic fits.

    Returns
    -------
    name : str
        The chosen fit's name.
    brdf : BRDF
        Its library BRDF (an analytic tree).
    errors : dict
        ``{name: image error}`` of the file's analytic fits against its tabulated fit
        (:class:`microfacet.metrics.ImageError`; empty when ``model`` names a fit and no
        ``OUT.json`` is beside the file).

    Raises
    ------
    MicrofacetError
        The file holds no analytic fit, or ``model`` is ``"tabulated"`` or unknown.

    Examples
    --------
    A fit file holding the tabulated fit (the best) and one analytic fit, ``ggx``:

    >>> import microfacet as mf
    >>> from microfacet.fit.spec import to_spec
    >>> lobe = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.9))
    >>> data = mf.fit.fit(lobe, resolution=8).to_bytes(fits={"ggx": to_spec(lobe)}, best="tabulated")
    >>> _ = open("fit.npz", "wb").write(data)
    >>> name, brdf, errors = choose_model("fit.npz")
    >>> name, type(brdf).__name__, sorted(errors)
    ('ggx', 'MicrofacetBRDF', ['ggx'])
    """
    from ..fit import load
    path = Path(path)
    fits, metrics, best = _fit_file_models(path)
    errors = {n: float(m["image"]) for n, m in metrics.items()}
    if not fits:
        raise MicrofacetError(f"{path}: the fit file holds no analytic fit to export (only the tabulated one)")
    if model not in ("best",):
        if model == "tabulated":
            raise MicrofacetError(f"{path}: the tabulated fit does not export (no format holds a tabulated NDF); "
                                  f"choose one of: best, {', '.join(fits)}")
        if model not in fits:
            raise MicrofacetError(f"{path}: no fit named {model!r}; the file has: best, {', '.join(fits)}")
        return model, fits[model], errors
    if best in fits:
        return best, fits[best], errors
    if not all(n in metrics for n in fits):
        from ..metrics import ImageError, LogError
        reference = load(path)
        image, log = ImageError(reference, size=IMAGE_SIZE), LogError(reference)
        metrics = {n: {**image.details(b), "log": log(b)} for n, b in fits.items()}
        errors = {n: float(m["image"]) for n, m in metrics.items()}
    from ..fit.outputs import best_fit
    name = best_fit({n: metrics[n] for n in fits})
    return name, fits[name], errors


def _gltf(brdf, out: Path, options: dict):
    mat, lost = gltf_material(brdf, name=options.get("name", "microfacet"))
    write_glb(mat, out, mesh=options.get("mesh", True))
    back = read_material(out)
    return {"gltf": gltf_brdf(back)}, lost, {"material": back}


def _mtlx(brdf, out: Path, options: dict):
    from .mtlx import validate, write_mtlx
    from .mtlx_render import mtlx_as_held
    doc, lost = mtlx_document(brdf)
    problems = validate(doc)
    if problems:
        raise MicrofacetError(f"MaterialX rejected the exported document: {problems[0]}")
    write_mtlx(doc, out)
    inputs, _ = openpbr_inputs(brdf)
    return ({"pbrlib": mtlx_as_held(brdf), "open_pbr_surface": openpbr_brdf(inputs)}, lost,
            {"open_pbr_surface": inputs})


def _usd(brdf, out: Path, options: dict):
    from .usd import preview_brdf, read_bound_inputs, write_usda
    mtlx_file = options.get("mtlx_file")
    _, lost = write_usda(brdf, out, mtlx_file=mtlx_file)
    inputs = read_bound_inputs(out)
    return {"UsdPreviewSurface": preview_brdf(inputs)}, lost, {"UsdPreviewSurface": inputs}


def _blender(brdf, out: Path, options: dict):
    desc, lost = blender_material(brdf, name=options.get("name", "microfacet"))
    write_blend(desc, out)
    material = out.with_suffix(".blender.json")
    material.write_text(json.dumps(desc, indent=1) + "\n")
    addon = write_addon(out.parent / "microfacet_blender.zip")
    back = json.loads(material.read_text())
    return ({"blender": blender_brdf(back)}, lost,
            {"material": back, "material_file": str(material), "addon": str(addon)})


_WRITERS = {"gltf": _gltf, "mtlx": _mtlx, "usd": _usd, "blender": _blender}


def _markdown(report: dict) -> str:
    e = report["image_error"]
    lines = [f"# Export of {report['source']} ({report['model']}) to {report['format']}", "",
             f"File: `{report['file']}`", "", "## Image error (rendered spheres, Bieron & Peers 2020)", "",
             "| exported material | vs the library's fit | vs the tabulated fit |", "|---|---|---|"]
    for k, v in e["exported_vs_fit"].items():
        t = e.get("exported_vs_tabulated", {}).get(k)
        lines.append(f"| {k} | {v:.4f} | {'' if t is None else f'{t:.4f}'} |")
    if "fit_vs_tabulated" in e:
        lines += ["", f"The library's fit itself scores {e['fit_vs_tabulated']:.4f} against the tabulated fit."]
    if report.get("other_models"):
        lines += ["", "Other analytic fits of the file, exported the same way, against the tabulated fit:", ""]
        lines += [f"- {k}: {v:.4f}" for k, v in report["other_models"].items()]
    lines += ["", "## Not carried", ""] + ([f"- {x}" for x in report["lost"]] or ["- nothing"])
    return "\n".join(lines) + "\n"


def is_pyramid(source) -> bool:
    """Whether ``source`` is a LEADR moment pyramid: a path ending in ``.exr`` or a list of levels.

    Parameters
    ----------
    source : str, os.PathLike, list or object
        What :func:`export` was given.

    Returns
    -------
    bool
        True for a ``.exr`` path or a list/tuple of moment levels (exported by
        :func:`~microfacet.export.leadr_textures.export_leadr`).

    Examples
    --------
    >>> is_pyramid("bumps.exr"), is_pyramid("nickel.npz"), is_pyramid([])
    (True, False, True)
    """
    if isinstance(source, (str, os.PathLike)):
        return Path(source).suffix.lower() == ".exr"
    return isinstance(source, (list, tuple))


def export(source, to: str, out, model: str = "best", compare_models: bool = True, **options) -> dict:
    """Export ``source`` (a fit file path or an analytic BRDF tree) to format ``to``
    (:data:`FORMATS`) at ``out`` (its suffix added if missing), write the report beside it
    (module docstring) and return the report dict: ``{"format", "file", "source", "model",
    "lost", "image_error": {"exported_vs_fit": {material: e}, "exported_vs_tabulated",
    "fit_vs_tabulated"}, "other_models", "mapping"}``. ``options``: ``name`` (glTF material),
    ``mesh`` (glTF: False for the material only), ``mtlx_file`` (USD: the ``.mtlx`` to note);
    ``name`` is also the Blender material's name.
    ``compare_models``: for a fit file, also export every other analytic fit in memory and
    measure it against the tabulated fit (``other_models``).
    A LEADR pyramid (a ``.exr`` path or a list of moment levels) exports ``to="textures"`` or
    ``"gltf"`` through :func:`~microfacet.export.leadr_textures.export_leadr` (``options``:
    ``base_roughness``, ``tiles``, ``metallic``, ``base_color``), which returns its own report.
    A glint microsurface (``microfacet glints``'s ``.npz`` or a ``Microsurface``) exports
    ``to="threejs"``, a folder, through :func:`~microfacet.export.glints_export.export_glints`
    (``options``: its keywords), which returns its own report; other formats raise one line
    saying why they cannot hold a glint P-BRDF.

    Parameters
    ----------
    source : str, os.PathLike or BRDF
        A fit file (``OUT.npz`` of ``microfacet fit``), an analytic BRDF tree, or a LEADR
        pyramid (a ``.exr`` path or a list of ``(H, W, 5)`` moment levels).
    to : str
        One of :data:`FORMATS` (``"gltf"``, ``"mtlx"``, ``"usd"``, ``"blender"``), or
        ``"textures"`` for a pyramid.
    out : str or os.PathLike
        The file to write; the format's suffix (:data:`SUFFIXES`) is added if missing.
    model : str
        For a fit file: ``"best"`` or the name of an analytic fit (:func:`choose_model`).
    compare_models : bool
        For a fit file exported to glTF: also measure every other analytic fit.
    **options
        ``name``, ``mesh``, ``mtlx_file`` (above); for a pyramid, those of
        :func:`~microfacet.export.leadr_textures.export_leadr`.

    Returns
    -------
    dict
        The report, also written as ``out + ".export.json"`` and ``".export.md"``.

    Raises
    ------
    ValueError
        ``to`` is not a format.
    MicrofacetError
        The BRDF has a part no format holds (a tabulated NDF, a second coat), or a
        consumer (bpy for Blender) is missing.

    Examples
    --------
    >>> import microfacet as mf
    >>> FORMATS, SUFFIXES["usd"]
    (('gltf', 'mtlx', 'usd', 'blender'), '.usda')
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.3, alpha_y=0.1), mf.fresnel.Schlick([0.9, 0.6, 0.5]))
    >>> report = export(brdf, "mtlx", "brass")
    >>> report["file"], sorted(report["image_error"]["exported_vs_fit"])
    ('brass.mtlx', ['open_pbr_surface', 'pbrlib'])
    >>> import os; os.path.exists("brass.mtlx.export.md")
    True
    """
    from ..metrics import ImageError
    if is_microsurface(source):                     # glint microsurfaces: three.js (glints_export)
        return export_glints(source, to, out, **options)
    if to in GLINT_TARGETS:
        raise ValueError(f"--to {to} exports a glint microsurface (GLINTS.npz from 'microfacet glints'); "
                         "a fit or BRDF exports --to gltf (three.js loads .glb)")
    if is_pyramid(source) or to in ("textures", "ktx2"):   # LEADR pyramids: textures per MIP level (leadr_textures)
        if not is_pyramid(source):
            raise ValueError(f"--to {to} exports a LEADR pyramid (PYRAMID.exr from 'microfacet bake'), "
                             f"got {source if isinstance(source, (str, os.PathLike)) else type(source).__name__}")
        return export_leadr(source, to, out, **options)
    if to not in _WRITERS:
        raise ValueError(f"to must be one of {', '.join(FORMATS)}, got {to!r}")
    if to == "blender":                             # one line saying what to do, before any work
        blender_python()
    if to == "usd":                                 # before any kernel compiles in the background (usd.import_pxr)
        from .usd import import_pxr
        import_pxr()
    out = Path(out)
    if out.suffix.lower() != SUFFIXES[to]:
        out = out.with_name(out.name + SUFFIXES[to])
    tabulated, errors = None, {}
    if isinstance(source, (str, os.PathLike)):
        from ..fit import load
        path = Path(source)
        name, brdf, errors = choose_model(path, model)
        tabulated = load(path)
        label = str(path)
    else:
        brdf, name, label = source, type(source).__name__, "a library BRDF"
    analyse(brdf)                                   # one clear error before any file is written
    inverse, lost, mapping = _WRITERS[to](brdf, out, options)
    err_fit = ImageError(brdf, size=IMAGE_SIZE)
    image = {"exported_vs_fit": {k: err_fit(b) for k, b in inverse.items()}}
    other = {}
    if tabulated is not None:
        err_tab = ImageError(tabulated, size=IMAGE_SIZE)
        image["exported_vs_tabulated"] = {k: err_tab(b) for k, b in inverse.items()}
        image["fit_vs_tabulated"] = err_tab(brdf)
        if compare_models and to == "gltf":
            fits, _, _ = _fit_file_models(path)
            for n, b in fits.items():
                if n != name:
                    try:
                        other[n] = err_tab(gltf_brdf(gltf_material(b)[0]))
                    except MicrofacetError:
                        continue
    report = {"format": to, "file": str(out), "source": label, "model": name, "lost": lost,
              "image_error": image, "image_size": IMAGE_SIZE, "other_models": other, "mapping": mapping,
              "fit_image_errors": errors}
    Path(str(out) + ".export.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    Path(str(out) + ".export.md").write_text(_markdown(report))
    return report
