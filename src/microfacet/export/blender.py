"""Blender (Cycles) materials of library BRDFs: a ``.blend``, its inverse, and the add-on.

The mapping is :func:`microfacet.export.blender_nodes.closures_of_spec` (every formula is
there and in the user guide "Exports"): each lobe becomes the Blender 4.5 node that holds its
Fresnel term (Metallic BSDF with ``eta, k`` or F82 tint, Principled BSDF for a dielectric,
Glossy + Metallic for Schlick), GGX or Beckmann (never Multiscatter GGX), summed with Add
Shader nodes; a Lambertian base is a Diffuse BSDF. Blender 4.5 as a Python module (``pip install
"bpy==4.5.*"``) pins ``numpy<2``, so the ``.blend`` is written by a separate interpreter that
has ``bpy`` (:func:`blender_python`: ``$MICROFACET_BLENDER_PYTHON``, else the repository's
``.venv-blender`` made by ``make setup-blender``), running ``blender_nodes.py`` in a subprocess.

:class:`BlenderBRDF` evaluates a material description as Cycles does (measured: Cycles renders
of every closure kind within 0.1 % relL1 of it), so the image error of an export is measured
with the library's renderer on what Blender draws.

Examples
--------
>>> import microfacet as mf
>>> desc, lost = blender_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.09), mf.fresnel.Conductor()))
>>> desc["closures"][0]["node"], desc["closures"][0]["fresnel_type"]
('metallic', 'PHYSICAL_CONDUCTOR')
"""
from __future__ import annotations

import json
import os
import subprocess
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from ..brdf import BRDF
from ..errors import MicrofacetError
from . import blender_nodes

__all__ = ["blender_material", "blender_brdf", "BlenderBRDF", "blender_python", "write_blend", "render_cycles",
           "write_addon", "BLENDER_PYTHON_ENV", "ADDON_MODULE"]

#: Environment variable naming the Python interpreter that has ``bpy`` 4.5.
BLENDER_PYTHON_ENV = "MICROFACET_BLENDER_PYTHON"
#: Module (folder) name of the add-on inside its zip.
ADDON_MODULE = "microfacet_blender"
_HERE = Path(__file__).resolve().parent
#: Where ``make setup-blender`` puts the interpreter (the repository of an editable install).
DEFAULT_VENV = _HERE.parents[2] / ".venv-blender"


def blender_material(brdf, name: str = "microfacet") -> tuple[dict, list[str]]:
    """``(description, lost)``: the Blender material of an analytic BRDF tree
    (:func:`~microfacet.export.blender_nodes.closures_of_spec` of its
    :func:`~microfacet.fit.spec.to_spec`) and one line per thing Blender cannot carry.

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree (:func:`~microfacet.export.analysis.analyse`).
    name : str
        The material's name.

    Returns
    -------
    description : dict
        ``{"format", "version", "name", "closures", "coat"}``, JSON-able (written beside the
        ``.blend`` as ``OUT.blender.json``).
    lost : list of str
        What Cycles' nodes could not hold.

    Raises
    ------
    MicrofacetError
        A part no format holds, or one Blender cannot (a coat with a non-dielectric Fresnel).

    Examples
    --------
    A Schlick lobe whose ``f90`` is white is one Metallic BSDF (F82, white Edge Tint):

    >>> import microfacet as mf
    >>> desc, lost = blender_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.16), mf.fresnel.Schlick([0.9, 0.6, 0.5])))
    >>> [(c["node"], c["fresnel_type"], c["base_color"]) for c in desc["closures"]], lost
    ([('metallic', 'F82', [0.9, 0.6, 0.5])], [])
    """
    from ..fit.spec import to_spec
    from .analysis import analyse
    analyse(brdf)                                   # one clear error for what no format holds
    try:
        return blender_nodes.closures_of_spec(to_spec(brdf), name=name)
    except ValueError as e:
        raise MicrofacetError(f"Blender export: {e}") from None


def _closure_brdf(c: dict):
    """``(brdf, weight)`` of one closure of a description."""
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..distributions import GGX, Beckmann
    if c["node"] == "diffuse":
        return Lambertian(np.clip(c["color"], 0.0, None)), 1.0
    family = Beckmann if c.get("distribution") == "BECKMANN" else GGX
    a1, a2, phi = blender_nodes.node_ellipse(c)
    dist = family(alpha=a1) if abs(a1 - a2) <= 1e-12 * a1 else family.from_ellipse(a1, a2, phi)
    if c["node"] == "glossy":
        color = np.asarray(c["color"], float)
        return MicrofacetBRDF(dist, fr.Schlick(color, color)), 1.0
    if c["node"] == "principled":
        return MicrofacetBRDF(dist, fr.Dielectric(float(c["ior"]))), float(c.get("weight", 1.0))
    if c.get("fresnel_type") == "PHYSICAL_CONDUCTOR":
        f = fr.Conductor(c["ior"], c["extinction"])
    else:
        f = fr.F82Tint(c["base_color"], c["edge_tint"])
    return MicrofacetBRDF(dist, f), float(c.get("weight", 1.0))


class BlenderBRDF(BRDF):
    """A Blender material description evaluated as Cycles does: ``f = sum_j w_j f_j`` over its
    closures (Metallic BSDF: conductor or F82-tint Fresnel; Principled BSDF with a black base:
    the dielectric Fresnel; Glossy BSDF: its colour; Diffuse BSDF roughness 0: Lambert), GGX
    or Beckmann with height-correlated Smith, the ellipse of
    :func:`~microfacet.export.blender_nodes.node_ellipse`. ``eval_cos`` only (image errors).

    Parameters
    ----------
    description : dict
        A material description (:func:`blender_material`).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> lobe = mf.MicrofacetBRDF(mf.GGX(alpha=0.16), mf.fresnel.Conductor())
    >>> b = BlenderBRDF(blender_material(lobe)[0])
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.6, 0.0, 0.8])
    >>> bool(np.allclose(b.eval_cos(wi, wo), lobe.eval_cos(wi, wo)))
    True
    """

    def __init__(self, description: dict):
        self.parts = [_closure_brdf(c) for c in description["closures"]]

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        f = sum(w * np.nan_to_num(np.asarray(b.eval_cos(wi, wo), float)) for b, w in self.parts)
        if out is not None:
            out[...] = f
            return out
        return f


def blender_brdf(description: dict) -> BlenderBRDF:
    """The library BRDF of a Blender material description (the inverse mapping).

    Parameters
    ----------
    description : dict
        A material description (:func:`blender_material`, or ``OUT.blender.json``).

    Returns
    -------
    BlenderBRDF
        The sum of its closures as Cycles evaluates them.

    Examples
    --------
    >>> import microfacet as mf
    >>> b = blender_brdf(blender_material(mf.Lambertian([0.5, 0.5, 0.5]))[0])
    >>> [(type(brdf).__name__, weight) for brdf, weight in b.parts]
    [('Lambertian', 1.0)]
    """
    return BlenderBRDF(description)


def blender_python(required: bool = True) -> Path | None:
    """The Python interpreter that has ``bpy`` 4.5: ``$MICROFACET_BLENDER_PYTHON``, else
    :data:`DEFAULT_VENV` ``/bin/python``; when neither exists, ``None`` or (``required``) a
    :class:`MicrofacetError` saying in one line what to do.

    Parameters
    ----------
    required : bool
        Raise instead of returning None.

    Returns
    -------
    Path or None
        The interpreter.

    Examples
    --------
    :data:`BLENDER_PYTHON_ENV` names it first:

    >>> import os, sys
    >>> from pathlib import Path
    >>> os.environ[BLENDER_PYTHON_ENV] = sys.executable
    >>> blender_python() == Path(sys.executable)
    True
    >>> del os.environ[BLENDER_PYTHON_ENV]
    """
    env = os.environ.get(BLENDER_PYTHON_ENV)
    for candidate in ([Path(env)] if env else []) + [DEFAULT_VENV / "bin" / "python", Path.cwd() / ".venv-blender"
                                                     / "bin" / "python"]:
        if candidate.is_file():
            return candidate
    if required:
        raise MicrofacetError(f"Blender export needs a Python with bpy 4.5 (it pins numpy<2): run 'make setup-blender' "
                              f"(or python3.11 -m venv .venv-blender && .venv-blender/bin/pip install 'bpy==4.5.*') "
                              f"or set {BLENDER_PYTHON_ENV}")
    return None


def _run_bpy(description: dict | None, args: list[str], timeout: float) -> None:
    py = blender_python()
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [str(py), str(_HERE / "blender_nodes.py"), *args]
        if description is not None:
            desc_path = Path(tmp) / "material.json"
            desc_path.write_text(json.dumps(description))
            cmd += ["--desc", str(desc_path)]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise MicrofacetError(f"Blender ({py}) did not finish in {timeout:g} s") from None
    if r.returncode != 0:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]
        raise MicrofacetError(f"Blender ({py}) failed: {tail[0]}")


def write_blend(description: dict, path, timeout: float = 120.0) -> Path:
    """Write ``path`` (``.blend``): the material of ``description`` on a unit sphere (UV
    tangent = world x projected, the library's frame) with the comparison camera and sun of
    :func:`~microfacet.export.blender_nodes.build_scene`, by the ``bpy`` interpreter.

    Parameters
    ----------
    description : dict
        A material description (:func:`blender_material`).
    path : str or os.PathLike
        The ``.blend`` to write (its folder is created).
    timeout : float
        Seconds the ``bpy`` subprocess may take.

    Returns
    -------
    Path
        ``path``, absolute.

    Raises
    ------
    MicrofacetError
        No interpreter with ``bpy`` (:func:`blender_python`), or Blender failed.

    Examples
    --------
    >>> import microfacet as mf
    >>> desc, _ = blender_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Conductor()))
    >>> write_blend(desc, "chrome.blend").name                     # doctest: +SKIP
    'chrome.blend'
    """
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    _run_bpy(description, ["--blend", str(path)], timeout)
    return path


def render_cycles(source, size: int = 64, spp: int = 4, light=(-0.5, 0.5, 1.0),
                  timeout: float = 120.0) -> np.ndarray:
    """``(size, size, 3)`` linear radiance rendered by Cycles on the CPU and read back from
    OpenEXR: ``source`` a ``.blend`` path (its scene as saved, e.g. by :func:`write_blend`) or a
    material description on the comparison sphere (orthographic, sun of irradiance 1 from
    ``light``, no bounces; the view of :class:`microfacet.render.Sphere`).

    Parameters
    ----------
    source : str, os.PathLike or dict
        A ``.blend`` file or a material description (:func:`blender_material`).
    size : int
        Image width and height in pixels.
    spp : int
        Cycles samples per pixel.
    light : (3,) sequence
        Direction toward the sun (a description only).
    timeout : float
        Seconds the ``bpy`` subprocess may take.

    Returns
    -------
    (size, size, 3) ndarray
        Linear radiance, row 0 at the top.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.export.comparison import library_render, rel_l1
    >>> lobe = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Conductor())
    >>> blend = write_blend(blender_material(lobe)[0], "lobe.blend")         # doctest: +SKIP
    >>> image = render_cycles(blend, size=32)                                # doctest: +SKIP
    >>> image.shape, rel_l1(image, library_render(lobe, 32)) < 0.01          # doctest: +SKIP
    ((32, 32, 3), True)
    """
    from ..io import read_exr
    with tempfile.TemporaryDirectory() as tmp:
        exr = Path(tmp) / "render.exr"
        args = ["--exr", str(exr), "--size", str(int(size)), "--spp", str(int(spp))]
        if isinstance(source, dict):
            _run_bpy(source, args + ["--light=" + ",".join(str(float(v)) for v in light)], timeout)
        else:
            _run_bpy(None, args + ["--open", str(Path(source).resolve())], timeout)
        return np.asarray(read_exr(exr), float)[..., :3]


def write_addon(path) -> Path:
    """Write the installable Blender add-on zip ``path`` (``microfacet_blender/__init__.py`` =
    :mod:`~microfacet.export.blender_addon`, and ``blender_nodes.py``): File > Import >
    microfacet fit (.npz/.json). Install: Edit > Preferences > Add-ons > Install from Disk.

    Parameters
    ----------
    path : str or os.PathLike
        The zip to write (its folder is created).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import zipfile
    >>> with zipfile.ZipFile(write_addon("microfacet_blender.zip")) as z:
    ...     sorted(z.namelist())
    ['microfacet_blender/__init__.py', 'microfacet_blender/blender_nodes.py']
    >>> ADDON_MODULE
    'microfacet_blender'
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(_HERE / "blender_addon.py", f"{ADDON_MODULE}/__init__.py")
        z.write(_HERE / "blender_nodes.py", f"{ADDON_MODULE}/blender_nodes.py")
    return path

