"""A LEADR pyramid level as a Blender (Cycles) and a MaterialX (OpenPBR) material, and in USD.

The engines' textures of :mod:`microfacet.export.leadr_textures` carry a level's slope
covariance as glTF's roughness and ``KHR_materials_anisotropy``. Blender and OpenPBR
parameterise the anisotropic GGX lobe differently, so each consumer gets its textures converted
from the level's Beckmann ellipse ``alpha1 >= alpha2`` at ``phi`` (``alpha^2 = 2 sigma^2``,
Dupuy 2015 Eq. 3.5-3.9; GGX takes the Beckmann alphas, equal peak ``D(0)``;
:func:`~microfacet.export.leadr_textures.level_parameters`), never from glTF's strength:

* **normal** (both): the mean slope ``(x, y)`` as ``n = (-x, -y, 1)/|.|``, 8-bit ``(n + 1)/2``,
  +Y up the image (:func:`microfacet.leadr.encode_normal_map`): Blender's Normal Map node
  (tangent space), MaterialX's ``normalmap``;
* **Blender 4.5 Principled BSDF** (``alpha_x = r^2/sqrt(1 - 0.9 a)``, ``alpha_y = r^2 sqrt(1 - 0.9
  a)``, :mod:`microfacet.export.blender_nodes`): ``roughness`` R = ``r = (alpha1 alpha2)^(1/4)``,
  ``anisotropy`` B = ``a = (1 - alpha2/alpha1)/0.9`` clipped to 1 (``alpha1/alpha2 <= 10``; beyond,
  ``alpha1 alpha2`` is kept), ``Anisotropic Rotation = phi / 2 pi``;
* **OpenPBR** (``alpha_t = r^2 sqrt(2/(1 + (1 - a)^2))``, ``alpha_b = (1 - a) alpha_t``):
  ``roughness`` R = ``r = sqrt(alpha1 / sqrt(2/(1 + (1 - a)^2)))``, ``anisotropy`` B =
  ``a = 1 - alpha2/alpha1``, the direction the geometry tangent turned by ``phi`` about the
  normal (``rotate3d`` by ``-phi`` degrees: MaterialX turns the other way);
* the **direction** (both): R, G = ``((cos 2 phi + 1)/2, (sin 2 phi + 1)/2)``, the doubled angle
  of the ellipse's axis (``phi`` and ``phi + pi`` are one ellipse), decoded in the shading graph as
  ``phi = atan2(2G - 1, 2R - 1)/2``: bilinear filtering between texels never flips the axis
  (glTF's ``(cos phi, sin phi)`` with ``cos phi >= 0`` does, at 90 degrees).

Alphas are clipped to ``[1e-3, 1]``; 8-bit storage of ``r`` and ``a``. The **naive** level
(:func:`level_ellipses` with ``naive=True``) is what an engine's ``generateMipmap`` makes of
the level-0 textures: the encoded normals box-filtered and renormalised, roughness, strength and
direction averaged, i.e. the base roughness only (:func:`~microfacet.export.leadr_textures.naive_textures`).

Renders (:func:`render_leadr_blender`, :func:`render_leadr_mtlx`) draw the textured plane
``[-1, 1]^2`` of :class:`LeadrPlane` from straight above (orthographic, so that the view and the
sun are one direction for every pixel) with ``tiles`` repeats of the map: at
:func:`plane_for_level` one texel of the chosen level covers one pixel, so a level's texture is
read at its own resolution. The reference is level 0 supersampled (Cycles: ``spp`` uniform
samples in each pixel, box filter; MaterialX: rendered ``k`` times larger and box-downsampled).
Measured errors are in ``experiments/results/leadr_consumers.md``.

Examples
--------
>>> import microfacet as mf
>>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.3, seed=1), roughness=0.05)
>>> tex = level_textures(pyramid, 2, "blender")
>>> sorted(tex), tex["roughness"].shape
(['anisotropy', 'normal', 'roughness'], (4, 4, 3))
>>> plane_for_level(pyramid, 2, size=32).tiles
8.0
>>> CONSUMERS, NOT_CARRIED[0][:15]
(('blender', 'mtlx'), 'Beckmann lobe: ')
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from ..io.png import write_png_data

__all__ = ["LeadrPlane", "plane_for_level", "level_ellipses", "level_textures", "write_level_textures",
           "leadr_blend", "render_leadr_blender", "leadr_mtlx_document", "leadr_mtlx", "MtlxPlaneRenderer",
           "render_leadr_mtlx", "leadr_usd", "compare_leadr", "run_cli", "CONSUMERS", "TEXTURES",
           "NOT_CARRIED"]

#: The consumers of :func:`level_textures` (and ``microfacet export PYRAMID.exr --to``).
CONSUMERS = ("blender", "mtlx")
#: The three textures of a level, as written (``<name>.png``).
TEXTURES = ("normal", "roughness", "anisotropy")
#: Largest ``alpha1/alpha2`` of Blender's anisotropy (``a = 1``).
BLENDER_MAX_RATIO = 10.0
#: What the Blender and MaterialX materials of a level cannot carry.
NOT_CARRIED = [
    "Beckmann lobe: Cycles' Principled BSDF and OpenPBR are GGX; they take the Beckmann alphas (equal peak D(0))",
    "filtering in the moments: the renderers interpolate the encoded r, a, direction and normal bilinearly "
    "(exact at texel centres only)",
    "8-bit storage of r, a and the doubled-angle direction",
    "alpha > 1 clipped to 1; Blender: alpha1/alpha2 > 10 clipped to 10 keeping alpha1 alpha2",
    "MaterialX: its anisotropic Smith term uses sqrt(alpha1 alpha2)",
    "USD: UsdPreviewSurface is isotropic: roughness (alpha1 alpha2)^(1/4), no anisotropy (the OpenPBR "
    "material with its direction is in the .mtlx)",
]
_HERE = Path(__file__).resolve().parent
_MIN_ALPHA = 1e-3


@dataclasses.dataclass(frozen=True)
class LeadrPlane:
    """The view of a LEADR level's render: the plane ``[-1, 1]^2`` (normal +z, tangent +x, UV
    ``(x + 1)/2, (y + 1)/2`` times ``tiles``) seen from straight above by an orthographic camera
    over exactly that square, ``size`` pixels square; a sun of irradiance 1 from ``light``
    (direction toward it, normalised); the material metal (``metallic``) of ``base_color``.

    Parameters
    ----------
    size : int
        Image side in pixels.
    tiles : float
        Repeats of the map across the plane (:func:`plane_for_level`).
    light : (3,) tuple of float
        Direction toward the sun.
    base_color : float
        Grey base colour (linear).
    metallic : float
        Metalness in ``[0, 1]``.
    interpolation : str
        Texture filtering within a level: ``"Linear"`` (bilinear, as engines) or ``"Closest"``.
    spp : int
        Cycles samples per pixel (each a uniform point of the pixel).

    Examples
    --------
    >>> LeadrPlane(tiles=4.0).light
    (0.5, 0.3, 0.8124)
    """
    size: int = 96
    tiles: float = 1.0
    light: tuple = (0.5, 0.3, 0.8124)
    base_color: float = 0.9
    metallic: float = 1.0
    interpolation: str = "Linear"
    spp: int = 16

    def scene(self) -> dict:
        """The plane as the JSON scene of :mod:`microfacet.export.leadr_bpy` (no textures yet).

        Returns
        -------
        dict

        Examples
        --------
        >>> LeadrPlane(size=32).scene()["size"]
        32
        """
        w = np.asarray(self.light, float)
        return {"size": int(self.size), "tiles": float(self.tiles), "light": (w / np.linalg.norm(w)).tolist(),
                "base_color": [float(self.base_color)] * 3, "metallic": float(self.metallic),
                "interpolation": self.interpolation, "spp": int(self.spp)}


def _levels(pyramid) -> list[np.ndarray]:
    from ..leadr import read_pyramid
    if isinstance(pyramid, (str, os.PathLike)):
        path = Path(pyramid)
        if not path.is_file():
            raise MicrofacetError(f"{path}: no such pyramid file (a moment pyramid EXR from 'microfacet bake')")
        return read_pyramid(path)
    levels = [np.asarray(lv, dtype=np.float64) for lv in pyramid]
    if not levels or any(lv.ndim != 3 or lv.shape[2] != 5 for lv in levels):
        raise ValueError("pyramid must be a non-empty list of (H, W, 5) moment levels")
    return levels


def _level(levels, level: int) -> int:
    if int(level) != level or not 0 <= level < len(levels):
        raise ValueError(f"level must be an integer in [0, {len(levels) - 1}] for this pyramid, got {level!r}")
    return int(level)


def plane_for_level(pyramid, level: int, size: int = 96, **kwargs) -> LeadrPlane:
    """The :class:`LeadrPlane` of ``size`` pixels on which one texel of ``level`` covers one
    pixel: ``tiles = size / width of the level``.

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The level whose texels match the pixels.
    size : int
        Image side in pixels.
    **kwargs
        Other fields of :class:`LeadrPlane`.

    Returns
    -------
    LeadrPlane

    Raises
    ------
    ValueError
        ``level`` out of range.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((64, 64), 0.3, seed=1))
    >>> plane_for_level(pyramid, 3, size=96).tiles
    12.0
    """
    levels = _levels(pyramid)
    width = levels[_level(levels, level)].shape[1]
    return LeadrPlane(size=int(size), tiles=float(size) / width, **kwargs)


def level_ellipses(pyramid, level: int, base_roughness=None, naive: bool = False) -> dict:
    """Mean slopes and Beckmann ellipses of one level: ``slopes (H, W, 2)``, ``alpha1``,
    ``alpha2``, ``phi`` ``(H, W)``. LEADR: the level's moments
    (:func:`~microfacet.export.leadr_textures.level_parameters`). ``naive``: what an engine's
    MIP generation makes of the level-0 textures at that level
    (:func:`~microfacet.export.leadr_textures.naive_textures`, decoded as an engine reads them:
    box-filtered normals, the base roughness).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR (``microfacet bake``).
    level : int
        The MIP level (0: full resolution).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level (leave None when the pyramid was baked with it).
    naive : bool
        The naive level instead of LEADR's.

    Returns
    -------
    dict
        ``slopes``, ``alpha1``, ``alpha2`` (``>= 1e-3``), ``phi`` (radians, ``alpha1``'s axis
        from the tangent towards the bitangent).

    Raises
    ------
    ValueError
        ``level`` out of range or levels not ``(H, W, 5)``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((32, 32), 0.4, seed=2), roughness=0.05)
    >>> leadr, naive = level_ellipses(pyramid, 3), level_ellipses(pyramid, 3, naive=True)
    >>> bool(leadr["alpha1"].mean() > 3 * naive["alpha1"].mean())    # the bumps' variance kept
    True
    """
    from .leadr_textures import decode_level, encode_level, level_parameters, naive_textures
    levels = _levels(pyramid)
    level = _level(levels, level)
    if naive:
        d = decode_level(naive_textures(encode_level(level_parameters(levels[0], base_roughness)))[level])
        a1, a2, phi = d["alpha_t"], d["alpha_b"], d["phi"]
        slopes = d["slopes"]
    else:
        p = level_parameters(levels[level], base_roughness)
        a1, a2, phi, slopes = p["alpha1"], p["alpha2"], p["phi"], p["slopes"]
    a1, a2 = np.clip(a1, _MIN_ALPHA, 1.0), np.clip(a2, _MIN_ALPHA, 1.0)
    return {"slopes": np.asarray(slopes, float), "alpha1": np.maximum(a1, a2), "alpha2": np.minimum(a1, a2),
            "phi": np.asarray(phi, float)}


def _u8(v) -> np.ndarray:
    return np.rint(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8)


def _consumer_parameters(e: dict, consumer: str) -> tuple[np.ndarray, np.ndarray]:
    """``(r, a)`` of the ellipses ``e`` for ``consumer`` (module docstring)."""
    a1, a2 = e["alpha1"], e["alpha2"]
    if consumer == "blender":
        return np.sqrt(np.sqrt(a1 * a2)), np.clip((1.0 - a2 / a1) / 0.9, 0.0, 1.0)
    if consumer == "mtlx":
        a = 1.0 - a2 / a1
        return np.sqrt(a1 / np.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))), a
    raise ValueError(f"consumer must be one of {', '.join(CONSUMERS)}, got {consumer!r}")


def level_textures(pyramid, level: int, consumer: str, base_roughness=None, naive: bool = False) -> dict:
    """The three ``(H, W, 3)`` uint8 textures (:data:`TEXTURES`) of one level for ``consumer``
    (``"blender"`` or ``"mtlx"``; formulas in the module docstring).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The MIP level.
    consumer : str
        One of :data:`CONSUMERS`.
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    naive : bool
        The naive level (:func:`level_ellipses`).

    Returns
    -------
    dict
        ``normal`` (RGB ``(n + 1)/2``), ``roughness`` (``r`` in R, G, B), ``anisotropy`` (R, G:
        the doubled angle; B: ``a``).

    Raises
    ------
    ValueError
        Unknown ``consumer`` or ``level`` out of range.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.4, 0.1, seed=1))
    >>> tex = level_textures(pyramid, 1, "mtlx")
    >>> tex["anisotropy"].shape, tex["anisotropy"].dtype.name
    ((8, 8, 3), 'uint8')
    """
    from ..leadr import encode_normal_map
    e = level_ellipses(pyramid, level, base_roughness, naive)
    r, a = _consumer_parameters(e, consumer)
    two = 2.0 * e["phi"]
    aniso = np.stack([_u8(0.5 * np.cos(two) + 0.5), _u8(0.5 * np.sin(two) + 0.5), _u8(a)], axis=-1)
    return {"normal": encode_normal_map(e["slopes"], np.uint8), "roughness": np.repeat(_u8(r)[..., None], 3, -1),
            "anisotropy": aniso}


def write_level_textures(textures: dict, folder) -> dict:
    """Write ``folder/<name>.png`` (8-bit RGB) for each of :data:`TEXTURES`.

    Parameters
    ----------
    textures : dict
        :func:`level_textures`.
    folder : str or os.PathLike
        The folder (created).

    Returns
    -------
    dict
        Texture name -> its path.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> paths = write_level_textures(level_textures(pyramid, 1, "blender"), "level1")
    >>> paths["normal"].as_posix()
    'level1/normal.png'
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return {k: write_png_data(folder / f"{k}.png", np.ascontiguousarray(textures[k])) for k in TEXTURES}


# --------------------------------------------------------------------------- Blender
def _run_leadr_bpy(scene: dict, blend=None, exr=None, timeout: float = 600.0) -> None:
    from .blender import blender_python
    py = blender_python()
    with tempfile.TemporaryDirectory() as tmp:
        desc = Path(tmp) / "scene.json"
        desc.write_text(json.dumps(scene))
        cmd = [str(py), str(_HERE / "leadr_bpy.py"), "--scene", str(desc)]
        cmd += ["--blend", str(blend)] if blend else []
        cmd += ["--exr", str(exr)] if exr else []
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise MicrofacetError(f"Blender ({py}) did not finish in {timeout:g} s") from None
    if r.returncode != 0:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]
        raise MicrofacetError(f"Blender ({py}) failed: {tail[0]}")


def leadr_blend(pyramid, level: int, out, plane: LeadrPlane | None = None, base_roughness=None,
                naive: bool = False, timeout: float = 300.0) -> Path:
    """Write ``out`` (``.blend``): the plane of ``plane`` (default :func:`plane_for_level`)
    whose Principled BSDF (GGX) takes the Blender textures of ``level`` (:func:`level_textures`,
    packed into the file; also written as PNGs in ``<out>.textures/``): Normal Map node, roughness,
    Anisotropic and Anisotropic Rotation (:mod:`microfacet.export.leadr_bpy`), with its camera
    and sun. Needs the interpreter with ``bpy`` (:func:`microfacet.export.blender.blender_python`).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The MIP level.
    out : str or os.PathLike
        The ``.blend`` to write (``.blend`` added if missing).
    plane : LeadrPlane, optional
        The scene.
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    naive : bool
        The naive level instead (:func:`level_ellipses`).
    timeout : float
        Seconds the ``bpy`` subprocess may take.

    Returns
    -------
    Path
        ``out``, absolute.

    Raises
    ------
    MicrofacetError
        No interpreter with ``bpy``, or Blender failed.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((64, 64), 0.4, seed=1), roughness=0.05)
    >>> leadr_blend(pyramid, 3, "bumps_l3.blend").name                  # doctest: +SKIP
    'bumps_l3.blend'
    """
    out = Path(out)
    if out.suffix.lower() != ".blend":
        out = out.with_name(out.name + ".blend")
    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    plane = plane or plane_for_level(pyramid, level)
    paths = write_level_textures(level_textures(pyramid, level, "blender", base_roughness, naive),
                                 out.with_name(out.stem + ".textures"))
    scene = dict(plane.scene(), textures={k: str(p.resolve()) for k, p in paths.items()},
                 name=f"leadr_level{level}" + ("_naive" if naive else ""))
    _run_leadr_bpy(scene, blend=out, timeout=timeout)
    return out


def render_leadr_blender(pyramid, level: int, plane: LeadrPlane, base_roughness=None, naive: bool = False,
                         threads: int = 1, seed: int = 0, timeout: float = 600.0) -> np.ndarray:
    """``(size, size, 3)`` linear radiance of ``level``'s Blender material on ``plane``, rendered
    by Cycles on the CPU (``plane.spp`` samples per pixel, box filter) and read back from
    OpenEXR. The reference of a level ``L`` is ``level = 0`` on the plane of ``L`` with many
    samples.

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The MIP level whose textures are drawn.
    plane : LeadrPlane
        The scene (:func:`plane_for_level`).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    naive : bool
        The naive level instead.
    threads : int
        Cycles' CPU threads.
    seed : int
        Cycles' sampling seed.
    timeout : float
        Seconds the ``bpy`` subprocess may take.

    Returns
    -------
    (size, size, 3) ndarray
        Row 0 at the top (+y).

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((32, 32), 0.4, seed=1), roughness=0.05)
    >>> image = render_leadr_blender(pyramid, 2, plane_for_level(pyramid, 2, size=32))   # doctest: +SKIP
    >>> image.shape                                                                     # doctest: +SKIP
    (32, 32, 3)
    """
    from ..io import read_exr
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_level_textures(level_textures(pyramid, level, "blender", base_roughness, naive), tmp)
        scene = dict(plane.scene(), textures={k: str(p) for k, p in paths.items()}, threads=int(threads),
                     seed=int(seed))
        exr = Path(tmp) / "render.exr"
        _run_leadr_bpy(scene, exr=exr, timeout=timeout)
        return np.asarray(read_exr(exr), float)[..., :3]


# --------------------------------------------------------------------------- MaterialX
def leadr_mtlx_document(textures: dict, plane: LeadrPlane | None = None, name: str = "leadr"):
    """A MaterialX document with the material ``M_<name>``: an ``open_pbr_surface`` (metal of
    ``plane``'s base colour) whose ``geometry_normal`` is a ``normalmap`` of the ``normal``
    texture, ``specular_roughness`` the ``roughness`` texture's R, ``specular_roughness_anisotropy``
    the ``anisotropy`` B, and ``geometry_tangent`` the world tangent turned about the normal by
    ``-atan2(2G - 1, 2R - 1)/2`` (``rotate3d``, degrees; module docstring). Every texture is a
    ``tiledimage`` (``vector3``, raw: no colour space) of ``uvtiling = plane.tiles``.

    Parameters
    ----------
    textures : dict
        Texture name -> file name as written into the document (relative to the ``.mtlx``).
    plane : LeadrPlane, optional
        Its ``tiles``, ``base_color`` and ``metallic``.
    name : str
        Material name suffix.

    Returns
    -------
    MaterialX.Document

    Examples
    --------
    >>> from microfacet.export.mtlx import validate
    >>> doc = leadr_mtlx_document({k: f"tex/{k}.png" for k in TEXTURES}, LeadrPlane(tiles=4.0))
    >>> validate(doc), [m.getName() for m in doc.getMaterialNodes()]
    ([], ['M_leadr'])
    """
    import MaterialX as mx
    plane = plane or LeadrPlane()
    doc = mx.createDocument()
    graph = doc.addNodeGraph(f"NG_{name}")
    t = float(plane.tiles)
    tex = {}
    for k in TEXTURES:
        n = graph.addNode("tiledimage", f"{k}_image", "vector3")
        n.setInputValue("file", textures[k], "filename")
        n.setInputValue("uvtiling", mx.Vector2(t, t))
        n.setInputValue("filtertype", "closest" if plane.interpolation.lower() == "closest" else "linear")
        tex[k] = n
    nmap = graph.addNode("normalmap", "normal_map", "vector3")
    nmap.setConnectedNode("in", tex["normal"])
    rough = graph.addNode("extract", "roughness_r", "float")
    rough.setConnectedNode("in", tex["roughness"])
    rough.setInputValue("index", 0)
    chans = {}
    for i, k in enumerate(("cos2", "sin2", "aniso")):
        e = graph.addNode("extract", f"anisotropy_{k}", "float")
        e.setConnectedNode("in", tex["anisotropy"])
        e.setInputValue("index", i)
        chans[k] = e
    signed = {}
    for k in ("cos2", "sin2"):
        m = graph.addNode("multiply", f"{k}_x2", "float")
        m.setConnectedNode("in1", chans[k])
        m.setInputValue("in2", 2.0)
        s = graph.addNode("subtract", f"{k}_signed", "float")
        s.setConnectedNode("in1", m)
        s.setInputValue("in2", 1.0)
        signed[k] = s
    at = graph.addNode("atan2", "two_phi", "float")
    at.setConnectedNode("iny", signed["sin2"])
    at.setConnectedNode("inx", signed["cos2"])
    deg = graph.addNode("multiply", "minus_phi_degrees", "float")
    deg.setConnectedNode("in1", at)
    deg.setInputValue("in2", -90.0 / math.pi)            # -phi in degrees: rotate3d turns the other way
    tangent = graph.addNode("tangent", "tangent", "vector3")
    tangent.setInputValue("space", "world")
    normal = graph.addNode("normal", "geometric_normal", "vector3")
    normal.setInputValue("space", "world")
    rot = graph.addNode("rotate3d", "rotated_tangent", "vector3")
    rot.setConnectedNode("in", tangent)
    rot.setConnectedNode("axis", normal)
    rot.setConnectedNode("amount", deg)
    outs = {}
    for k, node, kind in (("normal_out", nmap, "vector3"), ("roughness_out", rough, "float"),
                          ("anisotropy_out", chans["aniso"], "float"), ("tangent_out", rot, "vector3")):
        o = graph.addOutput(k, kind)
        o.setConnectedNode(node)
        outs[k] = o
    sh = doc.addNode("open_pbr_surface", f"SR_{name}", "surfaceshader")
    sh.setInputValue("base_color", mx.Color3(*[float(plane.base_color)] * 3))
    sh.setInputValue("base_metalness", float(plane.metallic))
    sh.setInputValue("specular_color", mx.Color3(1.0, 1.0, 1.0))
    for inp, out, kind in (("geometry_normal", "normal_out", "vector3"),
                           ("specular_roughness", "roughness_out", "float"),
                           ("specular_roughness_anisotropy", "anisotropy_out", "float"),
                           ("geometry_tangent", "tangent_out", "vector3")):
        sh.addInput(inp, kind).setConnectedOutput(outs[out])
    doc.addMaterialNode(f"M_{name}", sh)
    return doc


def leadr_mtlx(pyramid, level: int, out, plane: LeadrPlane | None = None, base_roughness=None,
               naive: bool = False) -> Path:
    """Write ``out`` (``.mtlx``) holding ``M_leadr`` (:func:`leadr_mtlx_document`) and its three
    textures of ``level`` (:func:`level_textures`, ``"mtlx"``) in ``<out stem>.textures/``,
    referenced relative to the ``.mtlx``. The document passes
    :func:`microfacet.export.mtlx.validate` (checked here: a :class:`MicrofacetError` otherwise).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The MIP level.
    out : str or os.PathLike
        The ``.mtlx`` to write (``.mtlx`` added if missing).
    plane : LeadrPlane, optional
        Its ``tiles`` (default :func:`plane_for_level`), base colour and metalness.
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    naive : bool
        The naive level instead.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    MicrofacetError
        The document does not validate.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.4, seed=1), roughness=0.05)
    >>> path = leadr_mtlx(pyramid, 2, "bumps_l2.mtlx")
    >>> path.name, sorted(p.name for p in Path("bumps_l2.textures").iterdir())
    ('bumps_l2.mtlx', ['anisotropy.png', 'normal.png', 'roughness.png'])
    """
    import MaterialX as mx

    from .mtlx import validate
    out = Path(out)
    if out.suffix.lower() != ".mtlx":
        out = out.with_name(out.name + ".mtlx")
    out.parent.mkdir(parents=True, exist_ok=True)
    plane = plane or plane_for_level(pyramid, level)
    folder = out.with_name(out.stem + ".textures")
    paths = write_level_textures(level_textures(pyramid, level, "mtlx", base_roughness, naive), folder)
    doc = leadr_mtlx_document({k: f"{folder.name}/{p.name}" for k, p in paths.items()}, plane)
    problems = validate(doc)
    if problems:
        raise MicrofacetError(f"{out}: the LEADR MaterialX document does not validate: {problems[0]}")
    mx.writeToXmlFile(doc, str(out))
    return out


class MtlxPlaneRenderer:
    """A process that renders LEADR levels with MaterialX's ``GlslRenderer``
    (:func:`~microfacet.export.mtlx_render.render_xml` on a plane): spawned on entering (a GLX
    context cannot share a process with another OpenGL context), with a private Xvfb when no display is set
    (:func:`~microfacet.export.mtlx_render.xvfb_display`), ended on exit and with this process.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((32, 32), 0.4, seed=1), roughness=0.05)
    >>> with MtlxPlaneRenderer() as r:                                                       # doctest: +SKIP
    ...     image = r.render(pyramid, 2, plane_for_level(pyramid, 2, size=32))
    """

    def __enter__(self):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from ..batch.workers import exit_with
        self.executor = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=exit_with,
                                            initargs=(os.getpid(),))
        return self

    def __exit__(self, *exc):
        self.executor.shutdown()
        return False

    def render(self, pyramid, level: int, plane: LeadrPlane, base_roughness=None, naive: bool = False,
               supersample: int = 1) -> np.ndarray:
        """``(size, size, 3)`` linear radiance of ``level``'s MaterialX material on ``plane``,
        rendered ``supersample`` times larger and box-downsampled.

        Parameters
        ----------
        pyramid : list of (H, W, 5) arrays, str or os.PathLike
            A moment pyramid or its EXR.
        level : int
            The MIP level.
        plane : LeadrPlane
            The scene.
        base_roughness : None, float, (float, float) or Beckmann
            A base lobe added to every level.
        naive : bool
            The naive level instead.
        supersample : int
            Rendered ``supersample x supersample`` pixels per pixel.

        Returns
        -------
        (size, size, 3) ndarray
        """
        import MaterialX as mx

        from .mtlx_render import render_xml
        k = int(supersample)
        if k < 1:
            raise ValueError(f"supersample must be an integer >= 1, got {supersample!r}")
        with tempfile.TemporaryDirectory() as tmp:
            paths = write_level_textures(level_textures(pyramid, level, "mtlx", base_roughness, naive), tmp)
            doc = leadr_mtlx_document({n: p.name for n, p in paths.items()}, plane)
            big = self.executor.submit(render_xml, mx.writeToXmlString(doc), "M_leadr", int(plane.size) * k,
                                       tuple(float(v) for v in plane.light), mesh="plane", folder=tmp).result()
        n = int(plane.size)
        return big.reshape(n, k, n, k, 3).mean(axis=(1, 3)).astype(np.float64)


def render_leadr_mtlx(pyramid, level: int, plane: LeadrPlane, base_roughness=None, naive: bool = False,
                      supersample: int = 1) -> np.ndarray:
    """:meth:`MtlxPlaneRenderer.render` in a render process of its own (started and ended here).

    Parameters
    ----------
    pyramid, level, plane, base_roughness, naive, supersample
        As :meth:`MtlxPlaneRenderer.render`.

    Returns
    -------
    (size, size, 3) ndarray

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((32, 32), 0.4, seed=1), roughness=0.05)
    >>> render_leadr_mtlx(pyramid, 2, plane_for_level(pyramid, 2, size=32)).shape      # doctest: +SKIP
    (32, 32, 3)
    """
    with MtlxPlaneRenderer() as r:
        return r.render(pyramid, level, plane, base_roughness, naive, supersample)


# --------------------------------------------------------------------------- USD
def leadr_usd(pyramid, level: int, out, plane: LeadrPlane | None = None, base_roughness=None, naive: bool = False,
              mtlx_file: str | None = None) -> Path:
    """Write ``out`` (``.usda``): the plane ``/Root/Plane`` (a ``Mesh``, uv ``primvars:st``)
    bound to ``/Root/Materials/Leadr``, a UsdPreviewSurface (metallic ``plane.metallic``,
    ``diffuseColor`` the base colour) whose ``normal`` is a ``UsdUVTexture`` of the level's
    normal map (raw, ``scale 2, bias -1``) and ``roughness`` the R of the Blender roughness
    texture, ``(alpha1 alpha2)^(1/4)`` (UsdPreviewSurface is isotropic: ``alpha = roughness^2``,
    the ellipse's geometric mean, equal peak ``D(0)``), both through a ``UsdTransform2d`` of scale
    ``plane.tiles``; the textures in ``<out stem>.preview_textures/``. ``mtlx_file`` (the level's
    ``.mtlx``, :func:`leadr_mtlx`, which carries the anisotropy) is noted in the material's
    ``customData``. ``pxr.UsdValidation`` reports no error (:func:`microfacet.export.usd.validation_errors`).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The MIP level.
    out : str or os.PathLike
        The ``.usda`` to write (``.usda`` added if missing).
    plane : LeadrPlane, optional
        Its ``tiles`` (default :func:`plane_for_level`), base colour and metalness.
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    naive : bool
        The naive level instead.
    mtlx_file : str, optional
        The level's ``.mtlx`` to note.

    Returns
    -------
    Path
        ``out``.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.export.usd import validation_errors
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.4, seed=1), roughness=0.05)
    >>> validation_errors(leadr_usd(pyramid, 2, "bumps_l2.usda"))
    []
    """
    from .usd import import_pxr
    import_pxr()
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade
    out = Path(out)
    if out.suffix.lower() not in (".usda", ".usd"):
        out = out.with_name(out.name + ".usda")
    out.parent.mkdir(parents=True, exist_ok=True)
    plane = plane or plane_for_level(pyramid, level)
    folder = out.with_name(out.stem + ".preview_textures")    # not the .mtlx's (another roughness)
    tex = level_textures(pyramid, level, "blender", base_roughness, naive)
    paths = write_level_textures(tex, folder)
    stage = Usd.Stage.CreateNew(str(out))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    mesh = UsdGeom.Mesh.Define(stage, "/Root/Plane")
    mesh.GetPointsAttr().Set([Gf.Vec3f(-1, -1, 0), Gf.Vec3f(1, -1, 0), Gf.Vec3f(1, 1, 0), Gf.Vec3f(-1, 1, 0)])
    mesh.GetFaceVertexCountsAttr().Set([4])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    mesh.GetNormalsAttr().Set([Gf.Vec3f(0, 0, 1)] * 4)
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.GetSubdivisionSchemeAttr().Set(UsdGeom.Tokens.none)
    mesh.GetExtentAttr().Set([Gf.Vec3f(-1, -1, 0), Gf.Vec3f(1, 1, 0)])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([Gf.Vec2f(0, 0), Gf.Vec2f(1, 0), Gf.Vec2f(1, 1), Gf.Vec2f(0, 1)])
    base = "/Root/Materials/Leadr"
    material = UsdShade.Material.Define(stage, base)
    surf = UsdShade.Shader.Define(stage, base + "/PreviewSurface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(plane.metallic))
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*[float(plane.base_color)] * 3))
    reader = UsdShade.Shader.Define(stage, base + "/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tiling = UsdShade.Shader.Define(stage, base + "/tiling")
    tiling.CreateIdAttr("UsdTransform2d")
    tiling.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    tiling.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(float(plane.tiles), float(plane.tiles)))
    for name in ("normal", "roughness"):
        t = UsdShade.Shader.Define(stage, f"{base}/{name}_texture")
        t.CreateIdAttr("UsdUVTexture")
        t.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{folder.name}/{paths[name].name}")
        t.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(tiling.ConnectableAPI(), "result")
        t.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        t.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
        t.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
        if name == "normal":
            t.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(2, 2, 2, 1))
            t.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(-1, -1, -1, 0))
            t.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
            surf.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(t.ConnectableAPI(), "rgb")
        else:
            t.CreateOutput("r", Sdf.ValueTypeNames.Float)
            surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).ConnectToSource(t.ConnectableAPI(), "r")
    material.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    material.GetPrim().SetCustomDataByKey("microfacet:leadr_level", int(level))
    if mtlx_file:
        material.GetPrim().SetCustomDataByKey("microfacet:mtlx", str(mtlx_file))
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    stage.GetRootLayer().Save()
    return out


# --------------------------------------------------------------------------- measurement
def compare_leadr(pyramid, level: int, consumer: str, plane: LeadrPlane | None = None, base_roughness=None,
                  reference: int = 256, renderer: MtlxPlaneRenderer | None = None, noise: bool = False) -> dict:
    """Render, in ``consumer``'s own renderer, (a) ``level``'s LEADR textures, (b) its naive
    textures and (c) the reference, level 0 supersampled (Blender: ``reference`` samples per
    pixel; MaterialX: ``reference`` = the supersampling factor ``k``, ``k x k`` pixels per pixel),
    and return the relative L1 errors ``sum |x - c| / sum c`` of (a) and (b).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    level : int
        The coarse level (>= 1).
    consumer : str
        ``"blender"`` or ``"mtlx"``.
    plane : LeadrPlane, optional
        The scene (default :func:`plane_for_level` at 96 px).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    reference : int
        Blender: samples per pixel of the reference; MaterialX: its supersampling factor.
    renderer : MtlxPlaneRenderer, optional
        A running MaterialX render process (else one is started and ended here).
    noise : bool
        Also render a second reference (Blender: another seed; MaterialX: half the factor) and
        return its error against the first, the floor under (a) and (b).

    Returns
    -------
    dict
        ``leadr``, ``naive`` (relL1 against the reference), ``noise`` (or None), the images
        ``leadr_image``, ``naive_image``, ``reference_image``, and ``plane``.

    Raises
    ------
    ValueError
        Unknown ``consumer``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((32, 32), 0.4, 0.15, 0.6, seed=1), roughness=0.05)
    >>> r = compare_leadr(pyramid, 2, "blender", plane_for_level(pyramid, 2, size=32), reference=64)  # doctest: +SKIP
    >>> r["leadr"] < r["naive"]                                                                    # doctest: +SKIP
    True
    """
    if consumer not in CONSUMERS:
        raise ValueError(f"consumer must be one of {', '.join(CONSUMERS)}, got {consumer!r}")
    plane = plane or plane_for_level(pyramid, level)
    levels = _levels(pyramid)
    if consumer == "blender":
        def draw(lv, naive=False, spp=None, seed=0):
            return render_leadr_blender(levels, lv, dataclasses.replace(plane, spp=spp or plane.spp), base_roughness,
                                        naive, seed=seed)
        ref = draw(0, spp=int(reference))
        second = draw(0, spp=int(reference), seed=1) if noise else None
        leadr, naive = draw(level), draw(level, naive=True)
    else:
        with contextlib.ExitStack() as stack:
            r = renderer or stack.enter_context(MtlxPlaneRenderer())
            ref = r.render(levels, 0, plane, base_roughness, supersample=int(reference))
            second = r.render(levels, 0, plane, base_roughness, supersample=max(1, int(reference) // 2)) \
                if noise else None
            leadr, naive = r.render(levels, level, plane, base_roughness), r.render(levels, level, plane,
                                                                                     base_roughness, naive=True)
    from .leadr_threejs import relative_l1
    return {"leadr": relative_l1(leadr, ref), "naive": relative_l1(naive, ref),
            "noise": None if second is None else relative_l1(second, ref), "leadr_image": leadr, "naive_image": naive,
            "reference_image": ref, "plane": plane}


def run_cli(args) -> int:
    """``microfacet export PYRAMID.exr --to blender|mtlx|usd -o OUT [--level L] [--base-roughness A]``
    (called by :mod:`microfacet.cli.export` for a pyramid): level ``L`` (default 0) as a ``.blend``
    (:func:`leadr_blend`), a ``.mtlx`` (:func:`leadr_mtlx`) or a ``.usda`` (:func:`leadr_usd`, with
    the ``.mtlx`` beside it), its textures in ``OUT.textures/``; one line per error.

    Parameters
    ----------
    args : argparse.Namespace
        ``fit`` (the pyramid EXR), ``to``, ``output``, ``level``, ``base_roughness``, ``model``.

    Returns
    -------
    int
        0 (errors raise): prints one line naming what was written.

    Raises
    ------
    MicrofacetError
        No such pyramid, or an option that does not apply.

    Examples
    --------
    >>> import argparse, microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.3, seed=1)))
    >>> run_cli(argparse.Namespace(fit="bumps.exr", to="mtlx", output="bumps_l2", level=2, base_roughness=0.05,
    ...                            model="best"))
    bumps_l2.mtlx: LEADR level 2 (4x4 texels) as an OpenPBR material; textures in bumps_l2.textures
    0
    """
    from ..cli.common import check_output_name
    source = Path(args.fit)
    if getattr(args, "model", "best") != "best":
        raise MicrofacetError("--model applies to fit files, not to a LEADR pyramid")
    if args.to not in ("blender", "mtlx", "usd"):
        raise MicrofacetError(f"{source}: leadr_consumers exports --to blender, mtlx or usd, not --to {args.to}")
    base = getattr(args, "base_roughness", None)
    if base is not None and not (np.isfinite(base) and base >= 0):
        raise ValueError(f"--base-roughness must be a finite alpha >= 0, got {base}")
    levels = _levels(source)
    level = getattr(args, "level", None) or 0
    if int(level) != level or not 0 <= level < len(levels):
        raise MicrofacetError(f"--level must be in [0, {len(levels) - 1}] for {source}, got {level}")
    out = Path(check_output_name(args.output))
    h, w = levels[level].shape[:2]
    if args.to == "blender":
        path, what = leadr_blend(levels, level, out, base_roughness=base), "a Cycles material (.blend)"
    elif args.to == "mtlx":
        path, what = leadr_mtlx(levels, level, out, base_roughness=base), "an OpenPBR material"
    else:
        mt = leadr_mtlx(levels, level, out.with_suffix(".mtlx") if out.suffix else Path(str(out) + ".mtlx"),
                        base_roughness=base)
        path = leadr_usd(levels, level, out, base_roughness=base, mtlx_file=mt.name)
        what = f"a UsdPreviewSurface (isotropic; the anisotropy in {mt.name})"
    shown = out.with_name(path.name)
    print(f"{shown}: LEADR level {level} ({w}x{h} texels) as {what}; "
          f"textures in {shown.with_name(path.stem + ('.preview_textures' if args.to == 'usd' else '.textures'))}")
    return 0
