"""Blender (Cycles) materials of microfacet fit specs: the mapping, and the node graph built in bpy.

Standalone on purpose (Python + NumPy, no ``microfacet`` import, ``bpy`` only inside the
functions that build): the same file runs in the library (:mod:`microfacet.export.blender`),
in the separate interpreter that has ``bpy`` (Blender 4.5 pins ``numpy<2``; ``python
blender_nodes.py --help``) and inside the Blender add-on that imports a fit file.

:func:`closures_of_spec` maps a BRDF spec (:mod:`microfacet.fit.spec`: ``microfacet``,
``lambertian``, ``sum``, ``layered``) to a list of closures that Cycles sums with Add Shader
nodes, each one exact where the node has the lobe's Fresnel term (docs/export.md, "Blender"):

* conductor ``(eta, k)``: Metallic BSDF, ``fresnel_type = PHYSICAL_CONDUCTOR``;
* F82 tint ``(f0, f82)``: Metallic BSDF, ``F82`` (Hoffman 2019), Base Color ``f0``, Edge Tint ``f82``;
* Schlick ``(f0, f90)`` with ``f90 >= f0``: ``F = X + w (Y + (1 - Y)(1 - c)^5)``, a Glossy BSDF
  of colour ``X = f90 - w`` plus ``w`` (a Mix Shader factor) times a Metallic BSDF F82 of Base
  Color ``Y = 1 - (f90 - f0)/w`` and white Edge Tint, ``w = min(f90)``; a constant Fresnel
  (``f0 = f90``) is a Glossy BSDF alone; ``f90 < f0``, tables and other terms: their
  least-squares Schlick (said in ``lost``);
* dielectric ``eta`` (GGX): Principled BSDF, ``distribution = GGX``, Base Color black,
  ``IOR = eta`` (its Fresnel is the exact dielectric one); Beckmann: as Schlick;
* ideal: Glossy BSDF, white;
* Lambertian: Diffuse BSDF, roughness 0;
* a coat (``layered``): a Principled BSDF dielectric lobe added over the base scaled by the
  coat's normal-incidence transmittance ``(1 - F(1))^2`` (Cycles has no layering node).

Roughness (Cycles 4.5, measured against the library's GGX): a lobe's slope ellipse ``alpha1 >=
alpha2`` at azimuth ``phi`` (from its ``alpha_x, alpha_y, rho``) becomes ``Roughness r = (alpha1
alpha2)^(1/4)`` and, Principled and Metallic BSDF, ``Anisotropy a = (1 - alpha2/alpha1)/0.9``
(``alpha_x = r^2/sqrt(1 - 0.9 a)``, ``alpha_y = r^2 sqrt(1 - 0.9 a)``, so ``alpha1/alpha2 <= 10``),
``Rotation = phi / 2 pi`` (turning the tangent towards the bitangent ``n x t``); Glossy BSDF,
whose long axis is the bitangent (``alpha_x = r^2 (1 - a)``, ``alpha_y = r^2/(1 - a)``),
``a = 1 - sqrt(alpha2/alpha1)`` and ``Rotation = phi / 2 pi + 1/4``. Every microfacet node has
``distribution = GGX`` or ``BECKMANN``, never ``MULTI_GGX`` (its multiple-scattering boost is
not the library's single-scattering lobe). The tangent is the mesh's UV tangent (a Tangent
node, UV Map mode), as glTF's.

Examples
--------
>>> spec = {"type": "microfacet", "distribution": {"type": "ggx", "alpha_x": 0.09, "alpha_y": 0.09, "rho": 0.0},
...         "fresnel": {"type": "conductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2]}}
>>> desc, lost = closures_of_spec(spec)
>>> desc["closures"][0]["node"], round(desc["closures"][0]["roughness"], 3), lost
('metallic', 0.3, [])
"""
from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

__all__ = ["closures_of_spec", "alphas_of", "roughness_anisotropy", "ellipse_of", "build_material",
           "build_scene", "render", "node_ellipse", "MAX_RATIO", "FORMAT"]

#: Format name of a material description (the JSON written beside a ``.blend``).
FORMAT = "microfacet-blender-material"
#: Largest ``alpha1 / alpha2`` of Blender 4's anisotropy (``a = 1``: ``1 / (1 - 0.9)``).
MAX_RATIO = 10.0
#: Largest Anisotropy of the Glossy BSDF (Cycles clamps it to 0.99).
GLOSSY_MAX_ANISOTROPY = 0.99
#: Node names of the tangent feeding every anisotropic node.
TANGENT_NODE = "microfacet tangent"


# --------------------------------------------------------------------------- mapping
def ellipse_of(alpha_x: float, alpha_y: float, rho: float) -> tuple[float, float, float]:
    """``(alpha1, alpha2, phi)``: the radii ``alpha1 >= alpha2`` and azimuth of the slope
    ellipse of ``(alpha_x, alpha_y, rho)`` (thesis Eq. 2.29-2.34: the eigen-decomposition of
    ``[[ax^2, rho ax ay], [rho ax ay, ay^2]]``).

    Parameters
    ----------
    alpha_x, alpha_y : float
        Roughness along the tangent and the bitangent.
    rho : float
        Slope correlation in ``(-1, 1)``.

    Returns
    -------
    alpha1, alpha2, phi : float
        The radii and the ``alpha1`` axis's azimuth (radians, from the tangent towards the
        bitangent).

    Examples
    --------
    >>> [round(v, 4) for v in ellipse_of(0.1, 0.3, 0.0)]
    [0.3, 0.1, 1.5708]
    """
    xx, yy, xy = alpha_x * alpha_x, alpha_y * alpha_y, rho * alpha_x * alpha_y
    mean, half = (xx + yy) / 2.0, math.hypot((xx - yy) / 2.0, xy)
    phi = 0.5 * math.atan2(2.0 * xy, xx - yy) if half > 0 else 0.0
    return math.sqrt(mean + half), math.sqrt(max(mean - half, 0.0)), phi


def roughness_anisotropy(alpha1: float, alpha2: float, node: str = "metallic") -> tuple[float, float, list]:
    """``(Roughness, Anisotropy, lost)`` of a Blender 4.5 node for the radii ``alpha1 >= alpha2``,
    ``r = (alpha1 alpha2)^(1/4)`` and, Principled and Metallic BSDF, ``a = (1 - alpha2/alpha1)/0.9``
    (ratio at most :data:`MAX_RATIO`), Glossy BSDF ``a = 1 - sqrt(alpha2/alpha1)`` (``a <= 0.99``);
    beyond, the ratio is clipped keeping ``alpha1 alpha2`` (said in ``lost``), ``alpha`` clipped
    to ``[1e-4, 1]``.

    Parameters
    ----------
    alpha1, alpha2 : float
        Radii of the slope ellipse, ``alpha1 >= alpha2``.
    node : str
        ``"metallic"`` or ``"principled"`` (one mapping) or ``"glossy"``.

    Returns
    -------
    roughness, anisotropy : float
        The node's ``Roughness`` and ``Anisotropy`` inputs.
    lost : list of str
        One line per clipping.

    Examples
    --------
    >>> r, a, lost = roughness_anisotropy(0.4, 0.1)
    >>> round(r, 4), round(a, 4), lost
    (0.4472, 0.8333, [])
    >>> [round(v, 4) for v in alphas_of(r, a)]                # the inverse
    [0.4, 0.1]
    >>> r, a, lost = roughness_anisotropy(1.0, 0.01)          # a ratio beyond MAX_RATIO
    >>> MAX_RATIO, lost[0]
    (10.0, "anisotropy alpha1/alpha2 = 100 clipped to 10 (Blender's largest Anisotropy): alpha_x alpha_y kept")
    """
    lost = []
    a1, a2 = min(max(alpha1, 1e-4), 1.0), min(max(alpha2, 1e-4), 1.0)
    if alpha1 > 1.0:
        lost.append(f"alpha1 {alpha1:.3g} > 1 clipped to 1 (Blender's Roughness <= 1)")
    top = MAX_RATIO if node != "glossy" else 1.0 / (1.0 - GLOSSY_MAX_ANISOTROPY) ** 2
    if a1 / a2 > top:
        lost.append(f"anisotropy alpha1/alpha2 = {a1 / a2:.3g} clipped to {top:g} (Blender's largest Anisotropy): "
                    "alpha_x alpha_y kept")
        g = math.sqrt(a1 * a2)
        a1, a2 = g * math.sqrt(top), g / math.sqrt(top)
    r = (a1 * a2) ** 0.25
    if node == "glossy":
        return r, min(1.0 - math.sqrt(a2 / a1), GLOSSY_MAX_ANISOTROPY), lost
    return r, min((1.0 - a2 / a1) / 0.9, 1.0), lost


def alphas_of(roughness: float, anisotropy: float, node: str = "metallic") -> tuple[float, float]:
    """``(alpha_x, alpha_y)`` along a Blender 4.5 node's rotated tangent and bitangent for its
    ``Roughness`` and ``Anisotropy`` (measured against the library's GGX in Cycles): Principled
    and Metallic BSDF ``aspect = sqrt(1 - 0.9 a)``, ``alpha_x = r^2/aspect``,
    ``alpha_y = r^2 aspect``; Glossy BSDF ``alpha_x = r^2 (1 - a)``, ``alpha_y = r^2/(1 - a)``
    (its long axis along the bitangent).

    Parameters
    ----------
    roughness, anisotropy : float
        The node's ``Roughness`` and ``Anisotropy`` inputs.
    node : str
        ``"metallic"``, ``"principled"`` or ``"glossy"``.

    Returns
    -------
    alpha_x, alpha_y : float
        GGX alphas along the node's (rotated) tangent and bitangent.

    Examples
    --------
    >>> [round(v, 4) for v in alphas_of(0.5, 1.0)], [round(v, 4) for v in alphas_of(0.5, 0.5, "glossy")]
    ([0.7906, 0.0791], [0.125, 0.5])
    """
    r2 = roughness * roughness
    if node == "glossy":
        a = min(max(anisotropy, 0.0), GLOSSY_MAX_ANISOTROPY)
        return r2 * (1.0 - a), r2 / (1.0 - a)
    aspect = math.sqrt(1.0 - 0.9 * min(max(anisotropy, 0.0), 1.0))
    return r2 / aspect, r2 * aspect


def node_ellipse(closure: dict) -> tuple[float, float, float]:
    """``(alpha1, alpha2, phi)``: the slope ellipse of a closure of :func:`closures_of_spec`
    (the inverse of the mapping: :func:`alphas_of` turned by ``Rotation``).

    Parameters
    ----------
    closure : dict
        A closure with ``node``, ``roughness``, ``anisotropy`` and ``rotation``.

    Returns
    -------
    alpha1, alpha2, phi : float
        The slope ellipse (radii ``alpha1 >= alpha2``, azimuth in radians).

    Examples
    --------
    >>> spec = {"type": "microfacet", "distribution": {"type": "ggx", "alpha_x": 0.1, "alpha_y": 0.3, "rho": 0.0},
    ...         "fresnel": {"type": "ideal"}}
    >>> closure = closures_of_spec(spec)[0]["closures"][0]
    >>> a1, a2, phi = node_ellipse(closure)
    >>> closure["node"], round(a1, 4), round(a2, 4), round(phi % math.pi, 4)     # an axis: phi modulo pi
    ('glossy', 0.3, 0.1, 1.5708)
    """
    ax, ay = alphas_of(float(closure["roughness"]), float(closure["anisotropy"]), closure["node"])
    phi = 2.0 * math.pi * float(closure["rotation"])
    return (ax, ay, phi) if ax >= ay else (ay, ax, phi + math.pi / 2.0)


def _rgb(v) -> list:
    return [float(x) for x in np.broadcast_to(np.asarray(v, float), (3,))]


def _least_squares_schlick(cos_theta, values) -> tuple[np.ndarray, np.ndarray]:
    """Schlick ``(f0, f90)`` of least squares to RGB ``values`` at ``cos_theta`` (the library's
    ``microfacet.export.schlick_of`` on a table)."""
    c = np.asarray(cos_theta, float)
    y = np.asarray(values, float).reshape(len(c), -1)
    m = (1.0 - c) ** 5
    coef, *_ = np.linalg.lstsq(np.stack([1.0 - m, m], -1), y, rcond=None)
    return np.clip(np.broadcast_to(coef[0], (3,)), 0, 1), np.clip(np.broadcast_to(coef[1], (3,)), 0, 1)


def _fresnel_values(fs: dict, c: np.ndarray) -> np.ndarray:
    """RGB values of a Fresnel spec at cosines ``c`` (schlick, tabulated, dielectric, conductor,
    f82tint, ideal), for the least-squares Schlick of a term no node holds."""
    kind = fs["type"]
    c = c[:, None]
    if kind == "tabulated":
        t = np.asarray(fs["cos_theta_d"], float)
        v = np.asarray(fs["rgb"], float).reshape(len(t), -1)
        return np.stack([np.interp(c[:, 0], t, v[:, min(i, v.shape[1] - 1)]) for i in range(3)], -1)
    if kind == "dielectric":
        eta = np.broadcast_to(np.asarray(fs["eta"], float), (3,))
        g2 = eta * eta - 1.0 + c * c
        g = np.sqrt(np.maximum(g2, 0.0))
        a, b = (g - c) / (g + c), (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        return np.where(g2 > 0, 0.5 * a * a * (1.0 + b * b), 1.0)
    if kind == "schlick":
        f0, f90 = np.asarray(_rgb(fs["f0"])), np.asarray(_rgb(fs.get("f90", 1.0)))
        return f0 + (f90 - f0) * (1.0 - c) ** 5
    raise ValueError(f"no Fresnel values for {kind!r}")


def _lobe(spec: dict, weight: float, lost: list) -> list:
    """The closures of one ``microfacet`` spec (module docstring), scaled by ``weight``."""
    d, fs = spec["distribution"], spec["fresnel"]
    family = d.get("type", "ggx")
    if family not in ("ggx", "beckmann"):
        raise ValueError(f"distribution {family!r} does not export (GGX or Beckmann)")
    distribution = "GGX" if family == "ggx" else "BECKMANN"
    if any(abs(float(v)) > 1e-6 for v in d.get("mean_slope", (0.0, 0.0))):
        lost.append(f"mean slope {tuple(round(float(v), 4) for v in d['mean_slope'])} dropped (Blender has none)")
    if spec.get("gaf", "smith") != "smith" or not spec.get("shadowing", True):
        lost.append(f"shadowing {spec.get('gaf')!r}/{spec.get('shadowing')} exported as Cycles' height-correlated Smith")
    a1, a2, phi = ellipse_of(float(d["alpha_x"]), float(d["alpha_y"]), float(d.get("rho", 0.0)))
    r, aniso, why = roughness_anisotropy(a1, a2)
    lost += why
    geo = {"distribution": distribution, "roughness": r, "anisotropy": aniso,
           "rotation": (phi / (2.0 * math.pi)) % 1.0}
    rg, ag, why_g = roughness_anisotropy(a1, a2, "glossy")
    glossy = dict(geo, roughness=rg, anisotropy=ag, rotation=(phi / (2.0 * math.pi) + 0.25) % 1.0)
    kind = fs["type"]
    if kind == "conductor":
        return [dict(geo, node="metallic", fresnel_type="PHYSICAL_CONDUCTOR", ior=_rgb(fs["eta"]),
                     extinction=_rgb(fs["k"]), weight=weight)]
    if kind == "f82tint":
        return [dict(geo, node="metallic", fresnel_type="F82", base_color=_rgb(fs["f0"]), edge_tint=_rgb(fs["f82"]),
                     weight=weight)]
    if kind == "ideal":
        return [dict(glossy, node="glossy", color=_rgb(weight))]
    if kind == "dielectric" and family == "ggx":
        eta = np.asarray(fs["eta"], float)
        if np.ptp(eta) > 1e-6:
            lost.append(f"RGB dielectric index {np.round(eta, 4).tolist()} exported as its mean {float(eta.mean()):.4f}")
        return [dict(geo, node="principled", ior=float(eta.mean()), weight=weight)]
    if kind == "schlick":
        f0, f90 = np.asarray(_rgb(fs["f0"])), np.asarray(_rgb(fs.get("f90", 1.0)))
    else:
        c = np.cos(np.linspace(0.0, np.pi / 2, 64))
        f0, f90 = _least_squares_schlick(c, _fresnel_values(fs, c))
        lost.append(f"{kind} Fresnel exported as its least-squares Schlick f0 {np.round(f0, 3).tolist()}, "
                    f"f90 {np.round(f90, 3).tolist()}" + (" (Principled has no Beckmann)" if kind == "dielectric" else ""))
    if np.any(f90 < f0 - 1e-9):
        lost.append(f"Schlick f90 {np.round(f90, 3).tolist()} below f0 {np.round(f0, 3).tolist()} raised to f0 "
                    "(Blender's nodes have no Fresnel falling towards grazing)")
        f90 = np.maximum(f90, f0)
    out = []
    w = float(f90.min())
    if float(np.max(f90 - f0)) <= 1e-9 or w <= 1e-9:          # constant term (or f90 = 0 somewhere)
        if float(np.max(f90 - f0)) > 1e-9:
            lost.append("Schlick term with f90 = 0 in a channel exported as constant f0")
        return [dict(glossy, node="glossy", color=_rgb(f0 * weight))]
    x = f90 - w
    y = 1.0 - (f90 - f0) / w
    if np.any(x > 1e-9):
        out.append(dict(glossy, node="glossy", color=_rgb(x * weight)))
    out.append(dict(geo, node="metallic", fresnel_type="F82", base_color=_rgb(np.clip(y, 0, 1)),
                    edge_tint=[1.0, 1.0, 1.0], weight=w * weight))
    return out


def _walk(spec: dict, weight: float, lost: list, closures: list) -> None:
    kind = spec.get("type")
    if kind == "microfacet":
        closures += _lobe(spec, weight, lost)
    elif kind == "lambertian":
        closures.append({"node": "diffuse", "color": _rgb(np.asarray(spec["reflectance"], float) * weight)})
    elif kind == "transmitted_lambertian":
        from ..diffuse import TransmittedLambertian
        from .analysis import equivalent_lambertian
        r = equivalent_lambertian(TransmittedLambertian(spec["reflectance"], spec.get("eta", 1.5)))
        closures.append({"node": "diffuse", "color": _rgb(r * weight)})
        lost.append("diffuse seen through its surface (darker at grazing angles) exported as a Diffuse BSDF of the "
                    "same mean albedo")
    elif kind == "sum":
        for p in spec["parts"]:                   # a sum's "weights" are sampling weights: f = sum f_j
            _walk(p, weight, lost, closures)
    elif kind == "layered":
        raise ValueError("a coat over a coated base does not export (one coat only)")
    else:
        raise ValueError(f"BRDF spec type {kind!r} does not export (microfacet, lambertian, transmitted_lambertian, sum, "
                         "layered)")


def closures_of_spec(spec: dict, name: str = "microfacet") -> tuple[dict, list]:
    """``(description, lost)``: the Blender material of a BRDF spec (module docstring) as a
    JSON-able dict ``{"format", "name", "closures": [...], "coat"}`` (each closure: ``node``
    ``metallic|principled|glossy|diffuse``, its inputs, ``weight`` a Mix Shader factor) and one
    line per thing it could not carry.

    Parameters
    ----------
    spec : dict
        A BRDF spec (:func:`microfacet.fit.spec.to_spec`): ``microfacet``, ``lambertian``,
        ``transmitted_lambertian``, ``sum``, or ``layered`` (one dielectric coat).
    name : str
        The material's name.

    Returns
    -------
    description : dict
        ``{"format": FORMAT, "version", "name", "closures", "coat"}``.
    lost : list of str
        What Cycles' nodes could not hold.

    Raises
    ------
    ValueError
        A spec type, distribution or coat that does not export.

    Examples
    --------
    A Schlick lobe whose ``f90`` is not white: a Glossy BSDF plus a Metallic BSDF (module
    docstring), over a Diffuse BSDF:

    >>> lobe = {"type": "microfacet", "distribution": {"type": "ggx", "alpha_x": 0.2, "alpha_y": 0.2, "rho": 0.0},
    ...         "fresnel": {"type": "schlick", "f0": [0.2, 0.2, 0.2], "f90": [0.8, 0.8, 0.8]}}
    >>> spec = {"type": "sum", "parts": [lobe, {"type": "lambertian", "reflectance": [0.5, 0.1, 0.1]}]}
    >>> desc, lost = closures_of_spec(spec)
    >>> [c["node"] for c in desc["closures"]], desc["format"], lost
    (['metallic', 'diffuse'], 'microfacet-blender-material', [])
    """
    lost: list = []
    closures: list = []
    coat = None
    if spec.get("type") == "layered":
        cs = spec["coat"]
        if cs.get("fresnel", {}).get("type") != "dielectric":
            raise ValueError("a coat exports only with a dielectric Fresnel term")
        coat_lobe = _lobe(dict(cs, distribution=dict(cs["distribution"], type="ggx")), 1.0, lost)
        eta = float(np.mean(cs["fresnel"]["eta"]))
        t = (1.0 - ((eta - 1.0) / (eta + 1.0)) ** 2) ** 2
        coat = {"closures": coat_lobe, "base_weight": t}
        lost.append(f"coat layering: Cycles has no layering node: the base is scaled by the coat's normal-incidence "
                    f"transmittance (1 - F(0 deg))^2 = {t:.4f}, not by the library's (1 - E_c(i))(1 - E_c(o))")
        if cs["distribution"].get("type") != "ggx":
            lost.append("Beckmann coat exported as GGX (Principled has no Beckmann)")
        _walk(spec["base"], t, lost, closures)
        closures = coat_lobe + closures
    else:
        _walk(spec, 1.0, lost, closures)
    for c in closures:
        if c.get("weight", 1.0) > 1.0 + 1e-9:
            lost.append(f"{c['node']} weight {c['weight']:.3f} > 1 clipped to 1 (a Mix Shader factor)")
            c["weight"] = 1.0
    if not closures:
        raise ValueError("nothing to export")
    return {"format": FORMAT, "version": 1, "name": name, "closures": closures, "coat": coat is not None}, lost


# --------------------------------------------------------------------------- bpy
def _set(node, socket: str, value) -> None:
    s = node.inputs[socket]
    if isinstance(value, (list, tuple)) and len(s.default_value) == 4:
        value = list(value) + [1.0]
    s.default_value = value


def _closure_node(nt, c: dict, tangent):
    kind = c["node"]
    types = {"metallic": "ShaderNodeBsdfMetallic", "principled": "ShaderNodeBsdfPrincipled",
             "glossy": "ShaderNodeBsdfGlossy", "diffuse": "ShaderNodeBsdfDiffuse"}
    if kind not in types:
        raise ValueError(f"unknown closure node {kind!r}")
    n = nt.nodes.new(types[kind])
    if kind == "diffuse":
        _set(n, "Color", c["color"])
        _set(n, "Roughness", 0.0)
        return n
    n.distribution = c["distribution"]
    _set(n, "Roughness", float(c["roughness"]))
    if kind == "principled":
        _set(n, "Base Color", [0.0, 0.0, 0.0])
        _set(n, "Metallic", 0.0)
        _set(n, "IOR", float(c["ior"]))
        _set(n, "Specular IOR Level", 0.5)
        _set(n, "Specular Tint", [1.0, 1.0, 1.0])
        _set(n, "Anisotropic", float(c["anisotropy"]))
        _set(n, "Anisotropic Rotation", float(c["rotation"]))
    else:
        _set(n, "Anisotropy", float(c["anisotropy"]))
        _set(n, "Rotation", float(c["rotation"]))
    if kind == "glossy":
        _set(n, "Color", c["color"])
    if kind == "metallic":
        n.fresnel_type = c["fresnel_type"]
        if c["fresnel_type"] == "F82":
            _set(n, "Base Color", c["base_color"])
            _set(n, "Edge Tint", c["edge_tint"])
        else:
            _set(n, "IOR", c["ior"])
            _set(n, "Extinction", c["extinction"])
    nt.links.new(tangent.outputs["Tangent"], n.inputs["Tangent"])
    return n


def build_material(bpy, desc: dict, name: str | None = None, uv_map: str = ""):
    """Create and return a ``bpy.types.Material`` from a :func:`closures_of_spec` description:
    one node per closure, a Mix Shader (``Fac = weight``, other input empty) where the weight
    is not 1, Add Shader nodes summing them, and one Tangent node (UV Map mode, ``uv_map``;
    the active map when empty) feeding every anisotropic input.

    Parameters
    ----------
    bpy : module
        Blender's ``bpy`` (Blender 4.5).
    desc : dict
        A description (:func:`closures_of_spec`).
    name : str, optional
        The material's name (default: the description's).
    uv_map : str
        The UV map of the tangent.

    Returns
    -------
    bpy.types.Material
        The material, its description kept as the custom property ``"microfacet"``.

    Raises
    ------
    ValueError
        ``desc`` is not a description.

    Examples
    --------
    >>> spec = {"type": "lambertian", "reflectance": [0.8, 0.8, 0.8]}
    >>> desc, _ = closures_of_spec(spec, name="white")
    >>> import bpy                                                  # doctest: +SKIP
    >>> build_material(bpy, desc).name                              # doctest: +SKIP
    'white'
    """
    if desc.get("format") != FORMAT:
        raise ValueError(f"not a {FORMAT} description (format {desc.get('format')!r})")
    mat = bpy.data.materials.new(name or desc.get("name", "microfacet"))
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    tangent = nt.nodes.new("ShaderNodeTangent")
    tangent.name = TANGENT_NODE
    tangent.direction_type = "UV_MAP"
    tangent.uv_map = uv_map
    shader = None
    for i, c in enumerate(desc["closures"]):
        n = _closure_node(nt, c, tangent)
        n.location = (-600, -250 * i)
        sock = n.outputs[0]
        w = float(c.get("weight", 1.0))
        if abs(w - 1.0) > 1e-12:
            mix = nt.nodes.new("ShaderNodeMixShader")
            mix.inputs["Fac"].default_value = w
            nt.links.new(sock, mix.inputs[2])
            sock = mix.outputs[0]
        if shader is None:
            shader = sock
        else:
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(shader, add.inputs[0])
            nt.links.new(sock, add.inputs[1])
            shader = add.outputs[0]
    nt.links.new(shader, out.inputs["Surface"])
    mat["microfacet"] = json.dumps(desc)
    return mat


def _sphere(bpy, segments: int = 256, rings: int = 128):
    """A smooth unit UV sphere whose UV ``u`` is world ``x`` and ``v`` the angle about x, so
    its UV tangent is world x projected on the surface (the library's tangent frame)."""
    import bmesh
    mesh = bpy.data.meshes.new("sphere")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=1.0)
    uv = bm.loops.layers.uv.new("UVMap")
    for f in bm.faces:
        f.smooth = True
        for loop in f.loops:
            x, y, z = loop.vert.co
            loop[uv].uv = (x, math.atan2(z, y) / (2 * math.pi))
    bm.to_mesh(mesh)
    bm.free()
    return mesh


def build_scene(bpy, mat, size: int = 64, spp: int = 4, light=(-0.5, 0.5, 1.0), irradiance: float = 1.0):
    """Set the current scene to the library's comparison: a unit sphere at the origin with
    ``mat``, an orthographic camera looking down ``-z`` (x right, y up, ``[-1, 1]^2``), a sun
    of irradiance ``irradiance`` from ``light`` (angle 0), no world light, Cycles on the CPU
    (``spp`` samples, pixel filter 0.01, no bounces), view transform Standard.

    Parameters
    ----------
    bpy : module
        Blender's ``bpy``.
    mat : bpy.types.Material
        The sphere's material (:func:`build_material`).
    size : int
        Image width and height in pixels.
    spp : int
        Cycles samples per pixel.
    light : (3,) sequence
        Direction toward the sun.
    irradiance : float
        The sun's strength.

    Returns
    -------
    bpy.types.Scene
        The current scene, set up.

    Examples
    --------
    >>> desc, _ = closures_of_spec({"type": "lambertian", "reflectance": [0.8, 0.8, 0.8]})
    >>> import bpy                                                                  # doctest: +SKIP
    >>> scene = build_scene(bpy, build_material(bpy, desc), size=32, spp=4)         # doctest: +SKIP
    >>> scene.render.engine, scene.render.resolution_x                              # doctest: +SKIP
    ('CYCLES', 32)
    """
    from mathutils import Vector
    scene = bpy.context.scene
    for ob in list(scene.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    sphere = bpy.data.objects.new("sphere", _sphere(bpy))
    sphere.data.materials.append(mat)
    scene.collection.objects.link(sphere)
    cam = bpy.data.cameras.new("camera")
    cam.type = "ORTHO"
    cam.ortho_scale = 2.0
    cam_ob = bpy.data.objects.new("camera", cam)
    cam_ob.location = (0.0, 0.0, 5.0)
    scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = float(irradiance)
    sun.angle = 0.0
    sun_ob = bpy.data.objects.new("sun", sun)
    sun_ob.rotation_euler = Vector(light).normalized().to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun_ob)
    world = scene.world or bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = int(spp)
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.filter_width = 0.01
    scene.cycles.max_bounces = 0
    scene.cycles.seed = 0
    scene.render.resolution_x = scene.render.resolution_y = int(size)
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 1
    return scene


def render(bpy, scene, path: str) -> None:
    """Render ``scene`` with Cycles into the linear float OpenEXR ``path``.

    Parameters
    ----------
    bpy : module
        Blender's ``bpy``.
    scene : bpy.types.Scene
        The scene (:func:`build_scene`).
    path : str
        The EXR to write (32-bit float).

    Examples
    --------
    >>> desc, _ = closures_of_spec({"type": "lambertian", "reflectance": [0.8, 0.8, 0.8]})
    >>> import bpy                                                                  # doctest: +SKIP
    >>> render(bpy, build_scene(bpy, build_material(bpy, desc), 32), "white.exr")   # doctest: +SKIP
    """
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)


def main(argv=None) -> int:
    """Command line of the interpreter that has bpy: build the material of ``--desc`` (a
    description JSON) on the comparison scene, or ``--open`` a ``.blend``; save ``--blend``,
    render ``--exr``."""
    p = argparse.ArgumentParser(description="Build a microfacet material in Blender (bpy) from its description JSON, "
                                            "or open a .blend, and save or render it")
    p.add_argument("--desc", help="material description (closures_of_spec) as JSON")
    p.add_argument("--open", help="open this .blend instead (its scene as saved)")
    p.add_argument("--blend", help="write this .blend")
    p.add_argument("--exr", help="render the scene with Cycles into this EXR")
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--light", default="-0.5,0.5,1.0", help="direction toward the sun, x,y,z")
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args(argv)
    if bool(a.desc) == bool(a.open):
        p.error("give one of --desc and --open")
    import bpy
    if a.open:
        bpy.ops.wm.open_mainfile(filepath=a.open)
        scene = bpy.context.scene
        scene.render.resolution_x = scene.render.resolution_y = a.size
        scene.cycles.samples = a.spp
    else:
        with open(a.desc) as f:
            desc = json.load(f)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        mat = build_material(bpy, desc)
        scene = build_scene(bpy, mat, a.size, a.spp, tuple(float(v) for v in a.light.split(",")))
    scene.render.threads = max(1, a.threads)
    if a.blend:
        bpy.ops.wm.save_as_mainfile(filepath=a.blend, compress=True)
    if a.exr:
        render(bpy, scene, a.exr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
