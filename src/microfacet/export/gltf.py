"""glTF 2.0 materials of library BRDFs, their inverse, and a ``.glb`` sphere that carries one.

Mapping (docs/export.md has every formula): the dominant lobe's slope ellipse ``alpha1 >=
alpha2`` at azimuth ``phi`` (:mod:`microfacet.export.analysis`) becomes
``roughness r = sqrt(alpha2)`` and, when anisotropic, ``KHR_materials_anisotropy`` with
``anisotropyStrength s = sqrt((alpha1 - alpha2) / (1 - alpha2))`` and
``anisotropyRotation = phi``, so that glTF's ``alpha_t = mix(r^2, 1, s^2) = alpha1``,
``alpha_b = r^2 = alpha2`` (KHR_materials_anisotropy, "Implementation"). Its Fresnel:
a metal (Schlick ``f90 = 1``, F82 tint, conductor, ideal; no base) is ``metallic = 1``,
``baseColor = F(0 deg)``; anything else is the dielectric form of KHR_materials_specular
and KHR_materials_ior, ``F = s F0c + (s - s F0c)(1 - c)^5`` with ``F0c = min(((ior - 1)/(ior + 1))^2
specularColor, 1)`` and ``s = specularFactor``: Schlick ``(f0, f90)`` is exact for a grey
``f90 >= max(f0)``. A Lambertian base is the dielectric ``baseColor``, divided by glTF's
mean diffuse weight ``1 - s max(F0c + (1 - F0c)/21)``; a coat is ``KHR_materials_clearcoat``
(index 1.5 fixed by glTF).

:class:`GltfBRDF` evaluates a glTF material as the specification defines it
(glTF 2.0 Appendix B, ``fresnel_mix``; KHR_materials_specular/ior/anisotropy/clearcoat)
with the library's GGX (height-correlated Smith), so the image error of an export is
measured against what a conforming renderer draws.

Examples
--------
>>> import microfacet as mf
>>> mat, lost = gltf_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.09), mf.fresnel.Schlick([0.9, 0.6, 0.5])))
>>> mat["pbrMetallicRoughness"]["roughnessFactor"], mat["pbrMetallicRoughness"]["metallicFactor"]
(0.3, 1.0)
"""
from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..brdf import BRDF
from .analysis import analyse, schlick_of

__all__ = ["gltf_material", "gltf_brdf", "GltfBRDF", "write_glb", "sphere_mesh", "roughness_anisotropy",
           "alphas_of", "read_material"]

#: glTF's default dielectric F0 (index 1.5).
F0_15 = 0.04
#: Largest ``F0c`` written (``ior`` ~ 4e3): glTF cannot reach ``F0c = 1`` with a finite index.
MAX_F0 = 0.999


def roughness_anisotropy(alpha1: float, alpha2: float) -> tuple[float, float, list[str]]:
    """``(roughness, anisotropyStrength, lost)`` with ``alpha_t = mix(r^2, 1, s^2) = alpha1``,
    ``alpha_b = r^2 = alpha2`` (KHR_materials_anisotropy); ``alpha1 > 1`` is clipped to 1.

    Parameters
    ----------
    alpha1, alpha2 : float
        Radii of the GGX slope ellipse, ``alpha1 >= alpha2``.

    Returns
    -------
    roughness : float
        glTF's ``roughnessFactor``, ``sqrt(alpha2)``.
    strength : float
        ``anisotropyStrength`` ``sqrt((alpha1 - alpha2) / (1 - alpha2))`` (0: isotropic).
    lost : list of str
        One line when ``alpha1 > 1`` was clipped.

    Examples
    --------
    >>> r, s, lost = roughness_anisotropy(0.25, 0.09)
    >>> round(r, 3), round(s, 3), lost
    (0.3, 0.419, [])
    >>> [round(a, 3) for a in alphas_of(r, s)]          # the inverse
    [0.25, 0.09]
    """
    lost = []
    a2 = min(alpha2, 1.0)
    a1 = min(alpha1, 1.0)
    if alpha1 > 1.0:
        lost.append(f"alpha1 {alpha1:.3g} > 1 clipped to 1 (glTF's alpha_t <= 1)")
    s = 0.0 if a2 >= 1.0 else float(np.sqrt(max(a1 - a2, 0.0) / (1.0 - a2)))
    return float(np.sqrt(a2)), s, lost


def alphas_of(roughness: float, strength: float) -> tuple[float, float]:
    """``(alpha_t, alpha_b) = (mix(r^2, 1, s^2), r^2)``, the inverse of :func:`roughness_anisotropy`
    (KHR_materials_anisotropy, "Implementation").

    Parameters
    ----------
    roughness : float
        glTF's ``roughnessFactor`` ``r``.
    strength : float
        ``anisotropyStrength`` ``s`` in ``[0, 1]``.

    Returns
    -------
    alpha_t, alpha_b : float
        GGX alphas along the anisotropy direction and across it.

    Examples
    --------
    >>> alphas_of(0.5, 0.0), alphas_of(0.5, 1.0)
    ((0.25, 0.25), (1.0, 0.25))
    """
    r2 = roughness * roughness
    return r2 + strength * strength * (1.0 - r2), r2


def _f0_to_ior(f0: float) -> float:
    """``ior`` with ``((ior - 1)/(ior + 1))^2 = f0``."""
    q = np.sqrt(min(f0, MAX_F0))
    return float((1.0 + q) / (1.0 - q))


def metal_f0(fresnel) -> np.ndarray | None:
    """``F(0 deg)`` of a Fresnel term that is a metal's (F(90 deg) = 1), else None."""
    from .. import fresnel as fr
    if isinstance(fresnel, fr.Ideal):
        return np.ones(3)
    if isinstance(fresnel, (fr.F82Tint, fr.Conductor)):
        return np.asarray(fresnel(1.0), float).reshape(3)
    if isinstance(fresnel, fr.Schlick) and np.all(np.abs(fresnel.f90 - 1.0) < 1e-3):
        return np.array(fresnel.f0, float)
    return None


def _rgb(v) -> list[float]:
    return [float(x) for x in np.asarray(v, float).reshape(3)]


def gltf_material(brdf, name: str = "microfacet") -> tuple[dict, list[str]]:
    """``(material, lost)``: the glTF 2.0 material object (JSON dict, with its extensions)
    of a library BRDF tree (module docstring) and one line for each thing it could not carry.

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree (:func:`~microfacet.export.analysis.analyse`).
    name : str
        The material's ``name``.

    Returns
    -------
    material : dict
        The glTF material object, ``extensions`` holding ``KHR_materials_specular``,
        ``_ior``, ``_anisotropy`` and ``_clearcoat`` where used.
    lost : list of str
        What glTF could not hold (second lobes, F82 tints, coat index, ...).

    Examples
    --------
    A dielectric lobe over a red Lambertian base:

    >>> import microfacet as mf
    >>> from microfacet.fit import SumBRDF
    >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.3, alpha_y=0.1), mf.fresnel.Dielectric(1.5)),
    ...                mf.Lambertian([0.5, 0.1, 0.1]))
    >>> mat, lost = gltf_material(brdf, name="red")
    >>> sorted(mat["extensions"]), round(mat["extensions"]["KHR_materials_ior"]["ior"], 6)
    (['KHR_materials_anisotropy', 'KHR_materials_ior', 'KHR_materials_specular'], 1.5)
    >>> round(mat["pbrMetallicRoughness"]["roughnessFactor"], 4), lost
    (0.3162, [])
    """
    from .. import fresnel as fr
    a = analyse(brdf)
    lost: list[str] = list(a.notes)
    pbr = {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}
    ext: dict = {}
    mat = {"name": name, "pbrMetallicRoughness": pbr, "extensions": ext}
    if a.lobes:
        lobe = a.lobes[0]
        if lobe.family != "ggx":
            lost.append(f"Beckmann lobe exported as GGX of the same alpha ({lobe.alpha1:.4g}, {lobe.alpha2:.4g})")
        if max(abs(v) for v in lobe.mean_slope) > 1e-6:
            lost.append(f"mean slope {tuple(round(v, 4) for v in lobe.mean_slope)} dropped (glTF has none)")
        total = sum(lb.albedo for lb in a.lobes)
        gain = total / lobe.albedo if lobe.albedo > 0 else 1.0
        for other in a.lobes[1:]:
            lost.append(f"second lobe (alpha {other.alpha1:.4g}, {other.albedo / max(total, 1e-300):.1%} of the "
                        "lobes' albedo at normal incidence) folded into the first: its Fresnel scaled by "
                        f"{gain:.3f}")
        r, s_aniso, why = roughness_anisotropy(lobe.alpha1, lobe.alpha2)
        lost += why
        pbr["roughnessFactor"] = r
        if s_aniso > 0:
            ext["KHR_materials_anisotropy"] = {"anisotropyStrength": s_aniso, "anisotropyRotation": lobe.phi}
        metal = None if a.base is not None or len(a.lobes) > 1 else metal_f0(lobe.fresnel)
        if metal is not None:
            pbr["metallicFactor"] = 1.0
            pbr["baseColorFactor"] = _rgb(metal) + [1.0]
            if isinstance(lobe.fresnel, fr.F82Tint) and np.any(lobe.fresnel.f82 < 1.0 - 1e-6):
                lost.append(f"F82 tint {np.round(lobe.fresnel.f82, 3).tolist()} dropped (glTF metals are Schlick)")
            if isinstance(lobe.fresnel, fr.Conductor):
                lost.append("conductor Fresnel (eta, k) exported as Schlick through F(0 deg)")
        else:
            if isinstance(lobe.fresnel, fr.Dielectric):      # Schlick through the same F0: ior = eta
                f0, f90 = ((lobe.fresnel.eta - 1.0) / (lobe.fresnel.eta + 1.0)) ** 2, np.ones(3)
            else:
                f0, f90 = schlick_of(lobe.fresnel)
            f0, f90 = np.clip(f0 * gain, 0.0, 1.0), np.clip(f90 * gain, 0.0, 1.0)
            if isinstance(lobe.fresnel, fr.Tabulated):
                lost.append("Fresnel table exported as its least-squares Schlick (f0, f90) "
                            f"f0 {np.round(f0, 3).tolist()}, f90 {np.round(f90, 3).tolist()}")
            elif not isinstance(lobe.fresnel, (fr.Schlick, fr.Dielectric)):
                lost.append(f"{type(lobe.fresnel).__name__} Fresnel exported as its least-squares Schlick")
            s = float(max(np.mean(f90), np.max(f0), 1e-6))
            if np.ptp(f90) > 1e-3:
                lost.append(f"coloured f90 {np.round(f90, 3).tolist()} exported as grey {s:.3f}")
            elif np.max(f0) > np.mean(f90) + 1e-6:
                lost.append(f"f90 {np.mean(f90):.3f} below f0 raised to {s:.3f} (glTF's F90 >= F0)")
            f0c = np.clip(f0 / s, 0.0, MAX_F0)
            top = float(np.max(f0c))
            ior = 1.5 if top <= F0_15 else _f0_to_ior(top)
            color = f0c / (((ior - 1.0) / (ior + 1.0)) ** 2)
            ext["KHR_materials_specular"] = {"specularFactor": s, "specularColorFactor": _rgb(color)}
            ext["KHR_materials_ior"] = {"ior": ior}
            if a.base is not None:
                weight = 1.0 - s * (top + (1.0 - top) / 21.0)
                base = a.base / max(weight, 1e-6)
                if np.any(base > 1.0):
                    lost.append("base colour compensated for glTF's Fresnel weighting exceeds 1: clipped")
                pbr["baseColorFactor"] = _rgb(np.clip(base, 0.0, 1.0)) + [1.0]
    else:                                             # a Lambertian only
        ext["KHR_materials_specular"] = {"specularFactor": 0.0, "specularColorFactor": [1.0, 1.0, 1.0]}
        pbr["baseColorFactor"] = _rgb(a.base) + [1.0]
    if a.coat is not None:
        c = a.coat
        eta = float(np.mean(getattr(c.fresnel, "eta", 1.5)))
        if abs(eta - 1.5) > 1e-3:
            lost.append(f"coat index {eta:.3f} exported as glTF's fixed 1.5")
        if not c.isotropic:
            lost.append("anisotropic coat exported isotropic (sqrt(alpha1 alpha2))")
        ext["KHR_materials_clearcoat"] = {"clearcoatFactor": 1.0,
                                          "clearcoatRoughnessFactor": float(np.sqrt(np.sqrt(c.alpha1 * c.alpha2)))}
        lost.append("coat layering: glTF scales the base by 1 - F_coat(n.v), the library by (1 - E_c(i))(1 - E_c(o))")
    if not ext:
        del mat["extensions"]
    return mat, lost


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class GltfBRDF(BRDF):
    """A glTF 2.0 material (``KHR_materials_specular``, ``_ior``, ``_anisotropy``,
    ``_clearcoat``) evaluated as the specification defines it: ``f = (1 - c F_cc(n.v))
    [ (1 - m) ((1 - s max F_d(v.h)) baseColor/pi) + spec ] + c f_cc`` with ``spec`` the GGX lobe
    (height-correlated Smith) and Schlick's ``F = mix(s F0c, baseColor, m) + (mix(s, 1, m) -
    ...)(1 - v.h)^5``. ``eval_cos`` only (for the image error); ``wo`` is the view.

    Parameters
    ----------
    material : dict
        A glTF material object (:func:`gltf_material`, :func:`read_material`).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> lobe = mf.MicrofacetBRDF(mf.GGX(alpha=0.09), mf.fresnel.Schlick([0.9, 0.6, 0.5]))
    >>> g = GltfBRDF(gltf_material(lobe)[0])
    >>> g.metallic, g.base.tolist()
    (1.0, [0.9, 0.6, 0.5])
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.6, 0.0, 0.8])
    >>> bool(np.allclose(g.eval_cos(wi, wo), lobe.eval_cos(wi, wo)))
    True
    """

    def __init__(self, material: dict):
        from .. import fresnel as fr
        from ..brdf import MicrofacetBRDF
        from ..distributions import GGX
        pbr = material.get("pbrMetallicRoughness", {})
        ext = material.get("extensions", {})
        self.metallic = float(pbr.get("metallicFactor", 1.0))
        self.base = np.asarray(pbr.get("baseColorFactor", [1, 1, 1, 1]), float)[:3]
        r = float(pbr.get("roughnessFactor", 1.0))
        spec = ext.get("KHR_materials_specular", {})
        self.s = float(spec.get("specularFactor", 1.0))
        color = np.asarray(spec.get("specularColorFactor", [1, 1, 1]), float)
        ior = float(ext.get("KHR_materials_ior", {}).get("ior", 1.5))
        self.f0c = np.minimum(((ior - 1.0) / (ior + 1.0)) ** 2 * color, 1.0)
        an = ext.get("KHR_materials_anisotropy", {})
        at, ab = alphas_of(r, float(an.get("anisotropyStrength", 0.0)))
        at, ab = max(at, 1e-4), max(ab, 1e-4)
        dist = GGX(alpha=at) if at == ab else GGX.from_ellipse(at, ab, float(an.get("anisotropyRotation", 0.0)))
        m = self.metallic
        f0 = (1 - m) * self.s * self.f0c + m * self.base
        f90 = (1 - m) * self.s + m * 1.0
        self.lobe = MicrofacetBRDF(dist, fr.Schlick(np.clip(f0, 0, 1), np.clip(f90, 0, 1)))
        cc = ext.get("KHR_materials_clearcoat")
        self.cc = float(cc.get("clearcoatFactor", 0.0)) if cc else 0.0
        if self.cc > 0:
            rc = float(cc.get("clearcoatRoughnessFactor", 0.0))
            self.coat = MicrofacetBRDF(GGX(alpha=max(rc * rc, 1e-4)), fr.Schlick(F0_15, 1.0))

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        wi, wo = np.broadcast_arrays(wi, wo)
        f = np.nan_to_num(np.asarray(self.lobe.eval_cos(wi, wo), float))
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        if self.metallic < 1.0 and np.any(self.base > 0):
            h = _unit(wi + wo + 1e-300)
            c = np.clip(np.sum(wo * h, -1), 0.0, 1.0)
            fr = np.max(self.f0c) + (1.0 - np.max(self.f0c)) * (1.0 - c) ** 5
            w = (1.0 - self.metallic) * (1.0 - self.s * fr) * np.where(ok, wi[..., 2], 0.0) / np.pi
            f = f + w[..., None] * self.base
        if self.cc > 0:
            fcc = F0_15 + (1.0 - F0_15) * (1.0 - np.clip(wo[..., 2], 0, 1)) ** 5
            f = (1.0 - self.cc * fcc)[..., None] * f + self.cc * np.nan_to_num(np.asarray(self.coat.eval_cos(wi, wo)))
        if out is not None:
            out[...] = f
            return out
        return f


def gltf_brdf(material: dict) -> GltfBRDF:
    """The library BRDF of a glTF material (the inverse mapping, :class:`GltfBRDF`).

    Parameters
    ----------
    material : dict
        A glTF material object.

    Returns
    -------
    GltfBRDF
        The material as a conforming renderer evaluates it.

    Examples
    --------
    >>> mat = {"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 1.0,
    ...                                 "roughnessFactor": 0.5}}
    >>> b = gltf_brdf(mat)
    >>> float(b.lobe.distribution.alpha_x)          # GGX alpha = roughness^2
    0.25
    """
    return GltfBRDF(material)


def sphere_mesh(n_theta: int = 64, n_phi: int = 128):
    """``(positions, normals, tangents, uvs, indices)`` of a unit UV sphere whose poles lie on
    world x, so its tangent (world x projected on the surface, ``w = +1``: bitangent
    ``n x t``) is smooth on the hemisphere seen from +z.

    Parameters
    ----------
    n_theta, n_phi : int
        Rings from pole to pole and segments around the x axis.

    Returns
    -------
    positions, normals : (V, 3) float32
        Vertices on the unit sphere (normals equal positions).
    tangents : (V, 4) float32
        glTF tangents (``w = 1``).
    uvs : (V, 2) float32
        ``(phi / 2 pi, theta / pi)``.
    indices : (3 T,) uint32
        Counter-clockwise triangles seen from outside (degenerate ones at the poles dropped).

    Examples
    --------
    >>> pos, nrm, tan, uv, idx = sphere_mesh(4, 8)
    >>> pos.shape, tan.shape, idx.size // 3
    ((45, 3), (45, 4), 48)
    """
    th = np.linspace(0.0, np.pi, n_theta + 1)
    ph = np.linspace(0.0, 2 * np.pi, n_phi + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    n = np.stack([np.cos(T), np.sin(T) * np.cos(P), np.sin(T) * np.sin(P)], -1).reshape(-1, 3)
    x = np.array([1.0, 0.0, 0.0])
    t = x - n[:, :1] * n
    tn = np.linalg.norm(t, axis=-1, keepdims=True)
    fallback = np.cross(n, [0.0, 0.0, 1.0]) + 1e-12
    t = np.where(tn > 1e-6, t / np.maximum(tn, 1e-12), _unit(fallback))
    tangents = np.concatenate([t, np.ones((len(t), 1))], -1)
    uv = np.stack([P / (2 * np.pi), T / np.pi], -1).reshape(-1, 2)
    i = np.arange(n_theta)[:, None] * (n_phi + 1) + np.arange(n_phi)[None, :]
    a, b, c, d = i, i + 1, i + n_phi + 1, i + n_phi + 2
    idx = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    # outward winding: counter-clockwise seen from outside
    p0, p1, p2 = n[idx[:, 0]], n[idx[:, 1]], n[idx[:, 2]]
    flip = np.sum(np.cross(p1 - p0, p2 - p0) * (p0 + p1 + p2), -1) < 0
    idx[flip] = idx[flip][:, [0, 2, 1]]
    area = np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=-1)
    idx = idx[area > 1e-12]
    return (n.astype(np.float32), n.astype(np.float32), tangents.astype(np.float32), uv.astype(np.float32),
            idx.astype(np.uint32).ravel())


def write_glb(material: dict, path, mesh: bool = True) -> Path:
    """Write ``path`` (``.glb``): one material and, with ``mesh``, a unit sphere node using it
    (POSITION, NORMAL, TANGENT, TEXCOORD_0); without, the material alone.

    Parameters
    ----------
    material : dict
        A glTF material object (:func:`gltf_material`).
    path : str or os.PathLike
        The ``.glb`` to write (its folder is created).
    mesh : bool
        Include the sphere (:func:`sphere_mesh`, 64 x 128).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> mat, _ = gltf_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.04)), name="chrome")
    >>> write_glb(mat, "chrome.glb").name
    'chrome.glb'
    >>> read_material("chrome.glb")["name"]
    'chrome'
    """
    import pygltflib as g
    path = Path(path)
    used = sorted(material.get("extensions", {}))
    gl = g.GLTF2(asset=g.Asset(version="2.0", generator="microfacet.export"), extensionsUsed=used)
    gl.materials = [g.Material(name=material.get("name"),
                               pbrMetallicRoughness=g.PbrMetallicRoughness(**material["pbrMetallicRoughness"]),
                               extensions=material.get("extensions", {}))]
    blob = b""
    if mesh:
        pos, nrm, tan, uv, idx = sphere_mesh()
        arrays = [(pos, g.FLOAT, "VEC3", g.ARRAY_BUFFER), (nrm, g.FLOAT, "VEC3", g.ARRAY_BUFFER),
                  (tan, g.FLOAT, "VEC4", g.ARRAY_BUFFER), (uv, g.FLOAT, "VEC2", g.ARRAY_BUFFER),
                  (idx, g.UNSIGNED_INT, "SCALAR", g.ELEMENT_ARRAY_BUFFER)]
        for k, (arr, ctype, kind, target) in enumerate(arrays):
            data = arr.tobytes()
            gl.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
            acc = g.Accessor(bufferView=k, componentType=ctype, count=len(arr) if arr.ndim > 1 else arr.size,
                             type=kind)
            if k == 0:
                acc.min, acc.max = arr.min(axis=0).tolist(), arr.max(axis=0).tolist()
            gl.accessors.append(acc)
            blob += data + b"\0" * (-len(data) % 4)
        gl.buffers = [g.Buffer(byteLength=len(blob))]
        gl.meshes = [g.Mesh(name="sphere", primitives=[g.Primitive(
            attributes=g.Attributes(POSITION=0, NORMAL=1, TANGENT=2, TEXCOORD_0=3), indices=4, material=0)])]
        gl.nodes = [g.Node(mesh=0, name="sphere")]
        gl.scenes = [g.Scene(nodes=[0])]
        gl.scene = 0
        gl.set_binary_blob(blob)
    path.parent.mkdir(parents=True, exist_ok=True)
    if mesh:
        gl.save_binary(str(path))
    else:                                           # a JSON chunk only: an empty BIN chunk is a validator error
        text = gl.to_json(separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        header = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text))
        path.write_bytes(header + struct.pack("<I4s", len(text), b"JSON") + text)
    return path


def read_material(path) -> dict:
    """The first material of a ``.gltf``/``.glb`` file as a JSON dict (pygltflib).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.gltf`` or ``.glb`` file with at least one material.

    Returns
    -------
    dict
        The material object as its JSON holds it.

    Examples
    --------
    >>> import microfacet as mf
    >>> mat, _ = gltf_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.16)))
    >>> path = write_glb(mat, "material.glb", mesh=False)
    >>> read_material(path)["pbrMetallicRoughness"]["roughnessFactor"]
    0.4
    """
    import pygltflib as g
    gl = g.GLTF2().load(str(path))
    return json.loads(gl.to_json())["materials"][0]
