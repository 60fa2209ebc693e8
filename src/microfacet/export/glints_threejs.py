"""The glint P-BRDF (Chermain, Claux and Mérillou 2019) as a three.js material.

A :class:`~microfacet.glints.Microsurface` (a normal map's mixture of Beckmann lobes) leaves
the library as lobe textures and a ``THREE.ShaderMaterial`` whose fragment shader is the
library's ``glints.glsl`` (:func:`microfacet.glsl.source`): per pixel, the footprint of a
Gaussian pixel filter (``pixelSigma`` pixels, from the screen derivatives of ``uv``), its lobe
window and weights (Eq. 9), the P-NDF and the patch areas (Eq. 13-17) and
``eval_cos = F D_P G2 / (4 A_P(o))`` (Eq. 7) for each three.js ``PointLight`` (its
``color * intensity / d^2``: ``decay`` 2, ``distance`` 0), as
:func:`microfacet.glints.pbrdf.eval_cos_footprints` computes it, on any mesh with normals and
``uv`` (``u`` along the map's columns, ``v = 0`` its first row, wrapped): the shading frame of a
fragment is its interpolated normal ``N`` and tangent ``T`` (a ``tangent`` attribute, xyz and
handedness ``w``: ``computeTangents()`` or glTF ``TANGENT``; else ``dP/du`` from the screen
derivatives of position and uv), Gram-Schmidt orthonormalized, ``B = cross(N, T) w``; light and
view are taken into that frame. On a plane (``THREE.PlaneGeometry``) this frame is its ``x, y, z``.

- :func:`lobe_textures`: per MIP level of the lobe grid, the central moments
  ``(E[x~], E[y~], Var x~, Var y~)`` (RGBA32F) and ``Cov(x~, y~)`` (R32F), float32.
- :func:`fragment_shader`, :func:`vertex_shader`: the GLSL ES 3.00 of the material.
- :func:`material_module`: the ES module ``glints-material.js`` (``loadGlintLobes(THREE, url)``,
  ``createGlintMaterial(THREE, lobes, options)``).
- :func:`export_glints_threejs`: a folder with the module, ``lobes.bin``/``lobes.json`` and a
  demo page (a plane or a sphere under a point light).
- :class:`GlintsRenderer`: the same material rendered in the system Chromium (the headless
  harness of :mod:`microfacet.export.threejs`), for tests against the library: a plane
  (:meth:`GlintsRenderer.render_scene`) or a sphere (:class:`SphereScene`,
  :meth:`GlintsRenderer.render_sphere`, which also reads back the shader's per-pixel inputs,
  :class:`ShaderInputs`, from its ``debug`` outputs :data:`DEBUG_OUTPUTS`).
- :func:`pbrdf_at_inputs`: the library's image at those inputs; :func:`sphere_inputs`,
  :func:`sphere_frame`, :func:`sphere_hits`: the exact sphere's (ray-traced, analytic frame and
  footprints).

Accuracy: float32 throughout (the library sums in float64); at the footprints where the
window fits (:data:`MAX_WINDOW` lobes per axis) the sums are the library's (on a curved mesh at
the inputs the shader computes: interpolated uv and frame, one-pixel ``dFdx``/``dFdy``
footprints, which approximate the smooth surface's as its tessellation does). Larger footprints
are summed over the first coarser lobe level where they fit (the lobes' MIP levels, Sec.
4.2.2): an approximation the library does not make.

Examples
--------
>>> import numpy as np, microfacet as mf
>>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((4, 4, 2)))
>>> sorted(p.name for p in export_glints_threejs(ms, "glints_web").iterdir())
['glints-material.js', 'index.html', 'lobes.bin', 'lobes.json']
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..glsl import source
from .threejs import ThreeRenderer

__all__ = ["lobe_textures", "vertex_shader", "fragment_shader", "material_module", "export_glints_threejs",
           "GlintsRenderer", "write_lobes", "MAX_WINDOW", "LOBES_FORMAT", "DEBUG_OUTPUTS", "MESHES", "SphereScene",
           "ShaderInputs", "sphere_frame", "sphere_hits", "sphere_inputs", "pbrdf_at_inputs"]

#: Most lobes per axis summed at one level (``MF_GLINT_MAX_WINDOW``).
MAX_WINDOW = 48
#: three.js of the demo page's import map (the revision the tests render with).
THREE_URL = "https://unpkg.com/three@0.187.0/build/three.module.js"
#: Meshes of the demo page (:func:`export_glints_threejs`).
MESHES = ("plane", "sphere")
#: Tag of ``lobes.json``.
LOBES_FORMAT = "microfacet.glints.threejs/1"
#: The material's ``debug`` outputs (RGBA per mode): the inputs of the P-BRDF at each pixel as the
#: shader sees them (``uv`` scaled by ``uvScale``, its screen derivatives, ``I / d^2`` of the
#: first point light, local-frame ``wo``/``wi``, the shading frame and position in world space).
DEBUG_OUTPUTS = {1: ("u", "v", "du/dx", "dv/dx"), 2: ("du/dy", "dv/dy", "irradiance", "1"),
                 3: ("wo.x", "wo.y", "wo.z", "1"), 4: ("wi.x", "wi.y", "wi.z", "1"),
                 5: ("T.x", "T.y", "T.z", "1"), 6: ("B.x", "B.y", "B.z", "1"),
                 7: ("N.x", "N.y", "N.z", "1"), 8: ("x", "y", "z", "1")}


def lobe_textures(ms) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per MIP level ``k`` of the lobe grid (``ms.mip[k]``: level 0 the lobes, each further
    level the average of the raw moments, Sec. 4.2.2, down to 1 x 1): ``(a, b)`` float32 with
    ``a (ny_k, nx_k, 4) = (E[x~], E[y~], Var x~, Var y~)`` and ``b (ny_k, nx_k, 1) = Cov(x~, y~)``,
    central moments computed in float64 (float32 raw moments would cancel), row 0 = ``v`` near 0.

    Parameters
    ----------
    ms : Microsurface
        A lobe mixture (:class:`~microfacet.glints.Microsurface`).

    Returns
    -------
    list of (ndarray, ndarray)
        ``(a, b)`` per MIP level, level 0 first.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> slopes = 0.1 * np.random.default_rng(0).standard_normal((4, 4, 2))     # a 4 x 4 normal map's slopes
    >>> ms = mf.glints.Microsurface.from_slopes(slopes)
    >>> [(a.shape, b.shape) for a, b in lobe_textures(ms)]
    [((4, 4, 4), (4, 4, 1)), ((2, 2, 4), (2, 2, 1)), ((1, 1, 4), (1, 1, 1))]
    """
    out = []
    for k in range(len(ms.mip)):
        E = np.asarray(ms.mip[k], dtype=np.float64)
        mx, my = E[..., 0], E[..., 1]
        a = np.stack([mx, my, E[..., 2] - mx * mx, E[..., 3] - my * my], -1).astype(np.float32)
        b = (E[..., 4] - mx * my)[..., None].astype(np.float32)
        out.append((np.ascontiguousarray(a), np.ascontiguousarray(b)))
    return out


def vertex_shader() -> str:
    """Vertex shader of the material (three.js ``ShaderMaterial``): ``uv * mfUvScale``,
    the view-space position and the object axes in view space.

    Returns
    -------
    str
        GLSL ES 3.00 without its ``#version`` line (three.js adds it and its prefix).

    Examples
    --------
    >>> "uniform vec2 mfUvScale;" in vertex_shader(), "void main()" in vertex_shader()
    (True, True)
    """
    return """uniform vec2 mfUvScale;
#ifndef USE_TANGENT
in vec4 tangent;
#endif
out vec2 vMfUv;
out vec3 vMfViewPos;
out vec3 vMfN;
out vec4 vMfT;
void main() {
    vMfUv = uv * mfUvScale;
    vec4 mv = modelViewMatrix * vec4(position, 1.0);
    vMfViewPos = mv.xyz;
    vMfN = normalMatrix * normal;
    vMfT = vec4(mat3(modelViewMatrix) * tangent.xyz, tangent.w);
    gl_Position = projectionMatrix * mv;
}
"""


_MAIN = """
uniform highp sampler2D mfGlintA;
uniform highp sampler2D mfGlintB;
uniform float mfCutoff;
uniform float mfPixelSigma;
uniform vec3 mfF0;
uniform bool mfExact;
uniform bool mfSeparable;
uniform float mfBitangentSign;
uniform int mfDebug;
in vec2 vMfUv;
in vec3 vMfViewPos;
in vec3 vMfN;
in vec4 vMfT;

// The shading frame (view space) of a fragment: N the interpolated normal (the geometric one
// where the mesh has none), T the interpolated tangent Gram-Schmidt orthogonalized against N, or
// where the mesh has none (or it is parallel to N) dP/du from the screen derivatives of the
// position and uv; B = cross(N, T) w s (w the tangent's handedness or the sign of dP/dv along it,
// s = mfBitangentSign), so that (T, B) follow the map's (u, v).
mat3 mf_glint_frame(vec3 dpx, vec3 dpy, vec2 dx, vec2 dy) {
    vec3 ng = cross(dpx, dpy);
    float nn = dot(vMfN, vMfN);
    vec3 N = nn > 0.0 ? vMfN * inversesqrt(nn) : normalize(ng);
    vec3 T = vMfT.xyz - N * dot(N, vMfT.xyz);
    float w = vMfT.w < 0.0 ? -1.0 : 1.0;
    float tt = dot(T, T);
    if (!(tt > 1e-8 * dot(vMfT.xyz, vMfT.xyz))) {
        float s = (dx.x * dy.y - dy.x * dx.y) < 0.0 ? -1.0 : 1.0;
        vec3 tu = s * (dpx * dy.y - dpy * dx.y);           // dP/du (det of the uv Jacobian)
        vec3 tv = s * (dpy * dx.x - dpx * dy.x);           // dP/dv
        T = tu - N * dot(N, tu);
        tt = dot(T, T);
        w = dot(cross(N, T), tv) < 0.0 ? -1.0 : 1.0;
    }
    T *= inversesqrt(tt);
    return mat3(T, cross(N, T) * (w * mfBitangentSign), N);
}

void main() {
    // Gaussian pixel filter of mfPixelSigma pixels mapped to uv: Sigma_P = s^2 J J^T
    vec2 dx = dFdx(vMfUv), dy = dFdy(vMfUv);
    vec3 dpx = dFdx(vMfViewPos), dpy = dFdy(vMfViewPos);
    mat3 F = mf_glint_frame(dpx, dpy, dx, dy);
    vec3 v = isOrthographic ? vec3(0.0, 0.0, 1.0) : normalize(-vMfViewPos);
    vec3 wo = v * F;                                     // (dot(T, v), dot(B, v), dot(N, v))
    vec3 cov = mfPixelSigma * mfPixelSigma
        * vec3(dx.x * dx.x + dy.x * dy.x, dx.y * dx.y + dy.y * dy.y, dx.x * dx.y + dy.x * dy.y);
    vec3 color = vec3(0.0);
    vec3 wi0 = vec3(0.0);
    float e0 = 0.0;
#if NUM_POINT_LIGHTS > 0
    PointLight pl;
    for (int i = 0; i < NUM_POINT_LIGHTS; i++) {
        pl = pointLights[i];
        vec3 L = pl.position - vMfViewPos;
        float d = length(L);
        vec3 wi = (L / d) * F;
        float att = getDistanceAttenuation(d, pl.distance, pl.decay);
        if (i == 0) { wi0 = wi; e0 = pl.color.r * att; }
        if (mfDebug != 0) continue;
        float f = mf_glint_eval_cos(mfGlintA, mfGlintB, vMfUv, cov, mfCutoff, wi, wo, mfExact, mfSeparable);
        vec3 Fr = mf_fresnel_schlick(mfF0, vec3(1.0), dot(wo, normalize(wi + wo)));
        color += pl.color * att * Fr * f;
    }
#endif
    gl_FragColor = vec4(color, 1.0);
    if (mfDebug != 0) {       // the per-pixel inputs (world-space frame and position)
        mat3 toWorld = transpose(mat3(viewMatrix));
        if (mfDebug == 1) gl_FragColor = vec4(vMfUv, dx);
        else if (mfDebug == 2) gl_FragColor = vec4(dy, e0, 1.0);
        else if (mfDebug == 3) gl_FragColor = vec4(wo, 1.0);
        else if (mfDebug == 4) gl_FragColor = vec4(wi0, 1.0);
        else if (mfDebug == 5) gl_FragColor = vec4(toWorld * F[0], 1.0);
        else if (mfDebug == 6) gl_FragColor = vec4(toWorld * F[1], 1.0);
        else if (mfDebug == 7) gl_FragColor = vec4(toWorld * F[2], 1.0);
        else gl_FragColor = vec4(toWorld * (vMfViewPos - viewMatrix[3].xyz), 1.0);
        return;
    }
#include <tonemapping_fragment>
#include <colorspace_fragment>
}
"""


def fragment_shader() -> str:
    """Fragment shader of the material (three.js ``ShaderMaterial``, ``lights: true``; three.js
    compiles it as GLSL ES 3.00): three.js's ``common`` and ``lights_pars_begin`` chunks, the
    library's ``glints.glsl`` (its ``#version`` line removed: three.js writes its own) and a
    ``main`` summing the point lights, then three.js's tone mapping and output colour space
    (neither applies to a float render target: linear radiance).
    ``MF_GLINT_MAX_WINDOW`` comes from the material's ``defines`` (``maxWindow``).

    Returns
    -------
    str
        The shader's GLSL (three.js's ``#include`` chunks unexpanded).

    Examples
    --------
    >>> frag = fragment_shader()
    >>> frag.startswith("#include <common>"), "#version" in frag, "mf_glint_eval_cos(" in frag
    (True, False, True)
    """
    lib = source("glints", "es300").split("\n", 1)[1]
    return "#include <common>\n#include <lights_pars_begin>\n" + lib + _MAIN


_MODULE = """// microfacet: the glint P-BRDF (Chermain et al. 2019) as a three.js ShaderMaterial.
// Generated by microfacet.export.glints_threejs; the GLSL is microfacet's glints.glsl.
export const VERTEX_SHADER = %(vertex)s;
export const FRAGMENT_SHADER = %(fragment)s;

// Lobe textures from 'lobes.json' + 'lobes.bin' (per level: RGBA32F then R32F, little endian).
export async function loadGlintLobes(THREE, jsonUrl) {
  const meta = await (await fetch(jsonUrl)).json();
  if (meta.format !== '%(format)s') throw new Error(`${jsonUrl}: not ${'%(format)s'}`);
  const bin = await (await fetch(new URL(meta.data, new URL(jsonUrl, location.href)))).arrayBuffer();
  const mipA = [], mipB = [];
  let offset = 0;
  for (const [w, h] of meta.levels) {
    mipA.push({ data: new Float32Array(bin, offset, 4 * w * h), width: w, height: h }); offset += 16 * w * h;
    mipB.push({ data: new Float32Array(bin, offset, w * h), width: w, height: h }); offset += 4 * w * h;
  }
  const texture = (mips, format) => {
    const t = new THREE.DataTexture(mips[0].data, mips[0].width, mips[0].height, format, THREE.FloatType);
    t.mipmaps = mips;
    t.minFilter = THREE.NearestMipmapNearestFilter;
    t.magFilter = THREE.NearestFilter;
    t.wrapS = t.wrapT = THREE.RepeatWrapping;
    t.generateMipmaps = false;
    t.flipY = false;
    t.colorSpace = THREE.NoColorSpace;
    t.needsUpdate = true;
    return t;
  };
  return { meta, a: texture(mipA, THREE.RGBAFormat), b: texture(mipB, THREE.RedFormat) };
}

// options: f0 (Schlick F0, [r, g, b], default 1 = ideal mirror facets), uvScale ([su, sv]),
// pixelSigma (pixel filter deviation in pixels, default 0.5), cutoff (default the file's),
// exact (default true: Eq. 10-17; false: the merged-lobe approximation of Sec. 4.2.2),
// separable (default false: height-correlated G2), maxWindow (lobes per axis summed at one
// level, default %(max_window)d; wider footprints use coarser lobe levels), bitangentSign (default 1:
// the bitangent cross(N, T) w points along +v, as computeTangents() and derivative tangents give;
// -1 for a glTF TANGENT attribute, whose bitangent points along -v), debug (default 0: radiance;
// 1-8 the per-pixel inputs: see DEBUG_OUTPUTS).
// The mesh needs uv and normals; tangents (a 'tangent' attribute, xyz + handedness w) are used
// where present, else derived per pixel from the screen derivatives of position and uv.
export const DEBUG_OUTPUTS = %(debug)s;
export function createGlintMaterial(THREE, lobes, options = {}) {
  const uniforms = THREE.UniformsUtils.merge([THREE.UniformsLib.lights]);
  const f0 = options.f0 ?? [1, 1, 1];
  const uv = options.uvScale ?? [1, 1];
  Object.assign(uniforms, {
    mfGlintA: { value: lobes.a }, mfGlintB: { value: lobes.b },
    mfCutoff: { value: options.cutoff ?? lobes.meta.cutoff },
    mfPixelSigma: { value: options.pixelSigma ?? 0.5 },
    mfF0: { value: new THREE.Vector3(f0[0], f0[1], f0[2]) },
    mfUvScale: { value: new THREE.Vector2(uv[0], uv[1]) },
    mfExact: { value: options.exact ?? true }, mfSeparable: { value: options.separable ?? false },
    mfBitangentSign: { value: options.bitangentSign ?? 1 }, mfDebug: { value: options.debug ?? 0 },
  });
  const maxWindow = options.maxWindow ?? %(max_window)d;
  if (!(Number.isInteger(maxWindow) && maxWindow >= 1)) throw new Error(`maxWindow must be an integer >= 1`);
  if (!(Math.abs(uniforms.mfBitangentSign.value) === 1)) throw new Error(`bitangentSign must be 1 or -1`);
  const material = new THREE.ShaderMaterial({ uniforms, lights: true,
                                              defines: { MF_GLINT_MAX_WINDOW: maxWindow },
                                              vertexShader: VERTEX_SHADER, fragmentShader: FRAGMENT_SHADER });
  // a mesh without tangents (or normals) reads these zero vectors: the shader derives its own
  material.defaultAttributeValues.tangent = [0, 0, 0, 1];
  material.defaultAttributeValues.normal = [0, 0, 0];
  return material;
}
"""


def material_module() -> str:
    """The ES module ``glints-material.js``: ``VERTEX_SHADER``, ``FRAGMENT_SHADER``,
    ``loadGlintLobes(THREE, jsonUrl)`` (the textures of :func:`write_lobes`) and
    ``createGlintMaterial(THREE, lobes, options)`` (a ``THREE.ShaderMaterial``; options in the
    module's comment, among them ``maxWindow``, default :data:`MAX_WINDOW`).

    Returns
    -------
    str
        The module's JavaScript.

    Examples
    --------
    >>> js = material_module()
    >>> MAX_WINDOW, "export function createGlintMaterial" in js, LOBES_FORMAT in js
    (48, True, True)
    """
    return _MODULE % {"vertex": json.dumps(vertex_shader()), "fragment": json.dumps(fragment_shader()),
                      "format": LOBES_FORMAT, "max_window": MAX_WINDOW, "debug": json.dumps(DEBUG_OUTPUTS)}


def write_lobes(ms, folder, name: str = "lobes") -> Path:
    """Write ``NAME.json`` (levels, cutoff, the microsurface's parameters) and ``NAME.bin``
    (:func:`lobe_textures`, float32 little endian, per level ``a`` then ``b``) into ``folder``;
    returns the ``.json`` path.

    Parameters
    ----------
    ms : Microsurface
        A lobe mixture.
    folder : str or os.PathLike
        The folder (created).
    name : str
        The files' stem.

    Returns
    -------
    Path
        ``folder/NAME.json``.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> slopes = 0.1 * np.random.default_rng(0).standard_normal((4, 4, 2))     # a 4 x 4 normal map's slopes
    >>> ms = mf.glints.Microsurface.from_slopes(slopes)
    >>> import json
    >>> meta = json.loads(write_lobes(ms, "web").read_text())
    >>> meta["format"] == LOBES_FORMAT, meta["levels"], meta["data"]
    (True, [[4, 4], [2, 2], [1, 1]], 'lobes.bin')
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    levels = lobe_textures(ms)
    with open(folder / f"{name}.bin", "wb") as f:
        for a, b in levels:
            f.write(a.astype("<f4").tobytes())
            f.write(b.astype("<f4").tobytes())
    meta = {"format": LOBES_FORMAT, "data": f"{name}.bin",
            "levels": [[int(a.shape[1]), int(a.shape[0])] for a, _ in levels],
            "cutoff": float(ms.cutoff), "h": float(ms.h), "sigma_eps": float(ms.sigma_eps),
            "map": [int(v) for v in ms.resolution]}
    path = folder / f"{name}.json"
    path.write_text(json.dumps(meta, indent=1))
    return path


@dataclass
class SphereScene:
    """A glinty sphere for three.js: ``THREE.SphereGeometry(1, *segments)`` at the origin (its
    ``uv``: ``u = phi / 2 pi`` around ``y``, ``v = 1 - theta / pi`` from the ``+y`` pole, times
    ``uv_scale``), tangents from ``computeTangents()`` (``tangents``; else the shader derives them
    from screen derivatives), a perspective camera at ``(0, 0, distance)`` looking at the origin
    (vertical field of view ``fov_deg``, square image of ``width`` pixels) and a point light
    (``intensity``, decay 2) at ``light``.

    Parameters
    ----------
    width : int
        Image width and height in pixels.
    fov_deg : float
        Vertical field of view, degrees.
    distance : float
        Camera distance from the sphere's centre (> 1).
    light : (3,) tuple
        Position of the point light (outside the sphere).
    intensity : float
        The light's intensity ``I`` (irradiance ``I / d^2``).
    segments : (int, int)
        ``widthSegments, heightSegments`` of the geometry.
    uv_scale : (float, float)
        The material's ``uvScale`` (tiling; ``(2, 1)`` gives square texels at the equator).
    tangents : bool
        Call ``computeTangents()`` (tangent attribute) or let the shader derive them.

    Examples
    --------
    >>> SphereScene(width=32).height, SphereScene().params()["mesh"] in MESHES
    (32, True)
    """

    width: int = 64
    fov_deg: float = 30.0
    distance: float = 4.0
    light: tuple = (2.0, 2.5, 3.0)
    intensity: float = 10.0
    segments: tuple = (64, 32)
    uv_scale: tuple = (2.0, 1.0)
    tangents: bool = True

    def __post_init__(self):
        if isinstance(self.width, bool) or int(self.width) != self.width or self.width < 1:
            raise ValueError(f"width must be a positive integer, got {self.width!r}")
        if not 0 < self.fov_deg < 180:
            raise ValueError(f"fov_deg must lie in (0, 180), got {self.fov_deg!r}")
        if not self.distance > 1:
            raise ValueError(f"distance must exceed the sphere's radius 1, got {self.distance!r}")
        lt = np.asarray(self.light, dtype=np.float64)
        if lt.shape != (3,) or not np.all(np.isfinite(lt)) or np.linalg.norm(lt) <= 1:
            raise ValueError(f"light must be a finite position outside the unit sphere, got {self.light!r}")
        sg = tuple(int(v) for v in self.segments)
        if len(sg) != 2 or sg[0] < 3 or sg[1] < 2 or sg != tuple(self.segments):
            raise ValueError(f"segments must be two integers (>= 3, >= 2), got {self.segments!r}")
        us = np.asarray(self.uv_scale, dtype=np.float64)
        if us.shape != (2,) or not np.all(us > 0):
            raise ValueError(f"uv_scale must be two positive numbers, got {self.uv_scale!r}")
        self.width, self.segments = int(self.width), sg

    @property
    def height(self) -> int:
        return self.width

    def params(self) -> dict:
        """The page's scene parameters (``renderGlints``).

        Returns
        -------
        dict
            ``mesh``, ``width``, ``height``, ``fovDeg``, ``distance``, ``light``, ``intensity``,
            ``segments``, ``tangents``.
        """
        return {"mesh": "sphere", "width": self.width, "height": self.height, "fovDeg": float(self.fov_deg),
                "distance": float(self.distance), "light": [float(v) for v in self.light],
                "intensity": float(self.intensity), "segments": list(self.segments),
                "tangents": bool(self.tangents)}


@dataclass
class ShaderInputs:
    """The P-BRDF's inputs at each pixel as the material's fragment shader computes them (its
    ``debug`` outputs, :data:`DEBUG_OUTPUTS`, read back from float render targets), row 0 the
    image's top: ``uv`` (scaled by ``uvScale``) and its screen derivatives ``duv_dx``, ``duv_dy``
    ``(H, W, 2)`` (``dFdx``/``dFdy``, one pixel; ``duv_dy`` toward the image's top), the first
    point light's ``irradiance`` ``I / d^2`` ``(H, W)``, local-frame ``wo``, ``wi`` and the
    world-space shading frame ``tangent``, ``bitangent``, ``normal`` and ``position``
    ``(H, W, 3)``; ``covered`` ``(H, W)``: the pixels the mesh covers.

    Parameters
    ----------
    uv, duv_dx, duv_dy : (H, W, 2) ndarray
        Footprint centre (scaled uv) and its derivatives along the image's x and y (up).
    irradiance : (H, W) ndarray
        ``I / d^2`` of the first point light.
    wo, wi : (H, W, 3) ndarray
        View and light directions in the shading frame.
    tangent, bitangent, normal, position : (H, W, 3) ndarray
        The shading frame and the surface point, world space.
    covered : (H, W) ndarray of bool
        Pixels the mesh covers.

    Examples
    --------
    The exact sphere's inputs have the same form (:func:`sphere_inputs`); the modes they are
    read back from:

    >>> inp = sphere_inputs(SphereScene(width=8))
    >>> inp.uv.shape, inp.covariance(0.5).shape, DEBUG_OUTPUTS[1]
    ((8, 8, 2), (8, 8, 2, 2), ('u', 'v', 'du/dx', 'dv/dx'))
    """

    uv: np.ndarray
    duv_dx: np.ndarray
    duv_dy: np.ndarray
    irradiance: np.ndarray
    wo: np.ndarray
    wi: np.ndarray
    tangent: np.ndarray
    bitangent: np.ndarray
    normal: np.ndarray
    position: np.ndarray
    covered: np.ndarray

    def covariance(self, pixel_sigma: float) -> np.ndarray:
        """The footprint covariance in uv^2 the shader uses, ``pixel_sigma^2 (J J^T)``,
        ``J = [duv_dx, duv_dy]``.

        Parameters
        ----------
        pixel_sigma : float
            Pixel filter's standard deviation in pixels.

        Returns
        -------
        (H, W, 2, 2) ndarray
            Per pixel.
        """
        J = np.stack([self.duv_dx, self.duv_dy], -1)
        return pixel_sigma * pixel_sigma * np.einsum("...ik,...jk->...ij", J, J)


def sphere_frame(points) -> dict:
    """The analytic shading frame of ``THREE.SphereGeometry`` (unit sphere, its parametrization
    ``x = -cos(phi) sin(theta), y = cos(theta), z = sin(phi) sin(theta)``, ``u = phi / 2 pi``,
    ``v = 1 - theta / pi``) at the radial projections of ``points`` ``(..., 3)``: ``uv``
    (before ``uvScale``), ``tangent = dP/du``, ``bitangent = dP/dv`` and ``normal`` (unit).

    Parameters
    ----------
    points : array_like, shape (..., 3)
        Points near the sphere (e.g. a tessellation's).

    Returns
    -------
    dict
        ``{"uv", "tangent", "bitangent", "normal"}``.

    Examples
    --------
    >>> f = sphere_frame([0.0, 0.0, 1.0])
    >>> f["uv"], f["tangent"].round(12) + 0.0, f["bitangent"].round(12) + 0.0
    (array([0.25, 0.5 ]), array([1., 0., 0.]), array([0., 1., 0.]))
    """
    p = np.asarray(points, dtype=np.float64)
    n = p / np.linalg.norm(p, axis=-1, keepdims=True)
    theta = np.arccos(np.clip(n[..., 1], -1.0, 1.0))
    phi = np.arctan2(n[..., 2], -n[..., 0]) % (2 * np.pi)
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    zero = np.zeros_like(phi)
    return {"uv": np.stack([phi / (2 * np.pi), 1.0 - theta / np.pi], -1),
            "tangent": np.stack([sp, zero, cp], -1) + 0.0,
            "bitangent": np.stack([cp * ct, st, -sp * ct], -1) + 0.0, "normal": n}


def sphere_hits(scene: SphereScene, offset=(0.0, 0.0)):
    """Where the ray of each pixel of ``scene`` (:class:`SphereScene`'s perspective camera,
    through the pixel's centre moved by ``offset`` pixels, right and up) meets the exact unit
    sphere: ``(points (H, W, 3), hit (H, W))``, row 0 the image's top (NaN where missed).

    Parameters
    ----------
    scene : SphereScene
        The camera.
    offset : (float, float)
        Sub-pixel offset (right, up) in pixels.

    Returns
    -------
    points : (H, W, 3) ndarray
        The nearest intersections.
    hit : (H, W) ndarray of bool
        Rays that meet the sphere.

    Examples
    --------
    >>> pts, hit = sphere_hits(SphereScene(width=4, distance=8.0))
    >>> hit.tolist()[1], bool(np.allclose(np.linalg.norm(pts[hit], axis=-1), 1))
    ([False, True, True, False], True)
    """
    w = h = scene.width
    t = np.tan(np.radians(scene.fov_deg) / 2)
    x = ((np.arange(w) + 0.5 + offset[0]) / w * 2 - 1) * t * (w / h)
    y = (1 - (np.arange(h) + 0.5 - offset[1]) / h * 2) * t
    X, Y = np.meshgrid(x, y)
    d = np.stack([X, Y, -np.ones_like(X)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, float(scene.distance)])
    b = d @ o                                             # |o + s d| = 1: s^2 + 2 b s + |o|^2 - 1 = 0
    disc = b * b - (o @ o - 1.0)
    hit = disc >= 0
    sd = -b - np.sqrt(np.where(hit, disc, np.nan))
    return o + sd[..., None] * d, hit


def sphere_inputs(scene: SphereScene) -> ShaderInputs:
    """The P-BRDF's inputs of :class:`ShaderInputs` on the exact unit sphere of ``scene``, in
    float64: each pixel's ray hit (:func:`sphere_hits`), its analytic frame and ``uv * uv_scale``
    (:func:`sphere_frame`), the uv Jacobian per pixel by central differences of the hits 1e-3
    pixel apart (the exact derivative to ~1e-6), ``I / d^2`` and local ``wi``, ``wo``: the
    reference that a tessellated sphere and the shader's one-pixel ``dFdx``/``dFdy`` approximate.

    Parameters
    ----------
    scene : SphereScene
        Sphere, camera and light.

    Returns
    -------
    ShaderInputs
        ``covered``: the pixels whose centre ray (and its differentials) meets the sphere.

    Examples
    --------
    >>> inp = sphere_inputs(SphereScene(width=8))
    >>> int(inp.covered.sum()), bool(np.all(inp.wo[inp.covered][:, 2] > 0))
    (52, True)
    """
    scale = np.asarray(scene.uv_scale, dtype=np.float64)
    p, hit = sphere_hits(scene)
    f = sphere_frame(np.where(hit[..., None], p, 1.0))
    eps = 1e-3

    def uv_at(off):
        q, ok = sphere_hits(scene, off)
        return sphere_frame(np.where(ok[..., None], q, 1.0))["uv"], ok

    def derivative(a, b):
        (ua, oka), (ub, okb) = a, b
        d = ub - ua
        d[..., 0] = (d[..., 0] + 0.5) % 1.0 - 0.5         # across the seam u = 0 | 1
        return d / (2 * eps) * scale, oka & okb
    jx, okx = derivative(uv_at((-eps, 0.0)), uv_at((eps, 0.0)))
    jy, oky = derivative(uv_at((0.0, -eps)), uv_at((0.0, eps)))
    covered = hit & okx & oky
    frame = np.stack([f["tangent"], f["bitangent"], f["normal"]], -2)         # rows T, B, N
    cam = np.array([0.0, 0.0, float(scene.distance)])
    v = cam - p
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    L = np.asarray(scene.light, dtype=np.float64) - p
    d2 = np.sum(L * L, -1)
    L /= np.sqrt(d2)[..., None]
    return ShaderInputs(uv=f["uv"] * scale, duv_dx=jx, duv_dy=jy, irradiance=float(scene.intensity) / d2,
                        wo=np.einsum("...ij,...j->...i", frame, v), wi=np.einsum("...ij,...j->...i", frame, L),
                        tangent=f["tangent"], bitangent=f["bitangent"], normal=f["normal"], position=p,
                        covered=covered)


def pbrdf_at_inputs(ms, inputs: ShaderInputs, *, pixel_sigma: float | None = None, f0=None, exact: bool = True,
                    g2: str = "correlated") -> np.ndarray:
    """The library's image at the shader's own per-pixel inputs: ``I / d^2 F eval_cos`` with
    :func:`~microfacet.glints.pbrdf.eval_cos_footprints` (Chermain et al. 2019, Eq. 7; float64)
    at ``inputs`` (:class:`ShaderInputs`: uv, footprint ``pixel_sigma^2 J J^T``, local ``wi``,
    ``wo``, irradiance), zero off the mesh: what the material's radiance should be, up to its
    float32 rounding, on any mesh.

    Parameters
    ----------
    ms : Microsurface
        The lobe mixture.
    inputs : ShaderInputs
        Read back by :meth:`GlintsRenderer.render_sphere`.
    pixel_sigma : float, optional
        Pixel footprint's standard deviation (default :data:`~microfacet.glints.figures.PIXEL_SIGMA`).
    f0 : float or (3,) array_like, optional
        Schlick ``F0`` (None: ideal mirror facets).
    exact : bool
        Exact lobe evaluation, as :class:`~microfacet.glints.PatchBRDF`.
    g2 : {"correlated", "separable"}
        Masking-shadowing form.

    Returns
    -------
    (H, W, 3) ndarray
        Linear radiance.

    Examples
    --------
    >>> with GlintsRenderer() as r:                                    # doctest: +SKIP
    ...     img, inputs = r.render_sphere(ms, SphereScene(width=32))
    >>> np.abs(img - pbrdf_at_inputs(ms, inputs)).sum() / img.sum() < 1e-3  # doctest: +SKIP
    True
    """
    from .. import fresnel as _fr
    from ..glints.figures import PIXEL_SIGMA
    from ..glints.pbrdf import eval_cos_footprints
    sigma = PIXEL_SIGMA if pixel_sigma is None else float(pixel_sigma)
    m = inputs.covered
    out = np.zeros(m.shape + (3,))
    if not m.any():
        return out
    fres = None if f0 is None else _fr.Schlick(f0)
    f = eval_cos_footprints(ms, inputs.uv[m], inputs.covariance(sigma)[m], inputs.wi[m], inputs.wo[m],
                            fresnel=fres, exact=exact, g2=g2)
    out[m] = inputs.irradiance[m][:, None] * f
    return out


#: Scenes shared by the demo page and :class:`GlintsRenderer`: ``p.mesh`` "plane" (default), the
#: library's :class:`~microfacet.glints.figures.PlaneScene` (plane ``[-1, 1]^2`` in ``xy``,
#: orthographic camera of elevation ``viewDeg`` from azimuth ``-y``, a point light), or "sphere",
#: :class:`SphereScene` (``THREE.SphereGeometry`` of radius 1 at the origin with
#: ``computeTangents()`` unless ``p.tangents`` is false, a perspective camera on ``+z``).
_SCENE_JS = """
async function renderGlints(THREE, renderer, M, p) {
  const lobes = await M.loadGlintLobes(THREE, p.lobes);
  const material = M.createGlintMaterial(THREE, lobes, p.options || {});
  const scene = new THREE.Scene();
  let geometry, camera;
  if (p.mesh === 'sphere') {
    geometry = new THREE.SphereGeometry(1, p.segments[0], p.segments[1]);
    if (p.tangents !== false) geometry.computeTangents();
    camera = new THREE.PerspectiveCamera(p.fovDeg, p.width / p.height, 0.1, 20);
    camera.position.set(0, 0, p.distance);
    camera.lookAt(0, 0, 0);
  } else {
    geometry = new THREE.PlaneGeometry(2, 2);
    if (p.tangents === true) geometry.computeTangents();
    const e = p.viewDeg * Math.PI / 180, se = Math.sin(e);
    camera = new THREE.OrthographicCamera(-1, 1, se, -se, 0.1, 20);
    camera.up.set(0, 0, 1);
    camera.position.set(0, -5 * Math.cos(e), 5 * se);
    camera.lookAt(0, 0, 0);
  }
  const mesh = new THREE.Mesh(geometry, material);
  scene.add(mesh);
  const light = new THREE.PointLight(0xffffff, p.intensity, 0, 2);
  light.position.set(p.light[0], p.light[1], p.light[2]);
  scene.add(light);
  renderer.setSize(p.width, p.height);
  const dispose = () => { material.dispose(); geometry.dispose(); lobes.a.dispose(); lobes.b.dispose(); };
  return { scene, camera, material, dispose };
}
"""

_TEST_PAGE = """<!doctype html><html><head><meta charset="utf-8">
<script type="importmap">{"imports": {"three": "/node_modules/three/build/three.module.js"}}</script></head><body>
<script type="module">
import * as THREE from 'three';
%(scene)s
const renderer = new THREE.WebGLRenderer({ antialias: false });
renderer.setPixelRatio(1);
window.renderGlints = async (p) => {
  const M = await import('/glints-material.js');
  const s = await renderGlints(THREE, renderer, M, p);
  const target = new THREE.WebGLRenderTarget(p.width, p.height, { type: THREE.FloatType, format: THREE.RGBAFormat });
  renderer.setRenderTarget(target);
  renderer.setClearColor(0x000000, 0);
  const images = [];
  for (const mode of (p.modes || [0])) {      // 0: radiance; 1-8: the material's debug outputs
    s.material.uniforms.mfDebug.value = mode;
    s.material.uniformsNeedUpdate = true;
    renderer.clear();
    renderer.render(s.scene, s.camera);
    const buf = new Float32Array(p.width * p.height * 4);
    renderer.readRenderTargetPixels(target, 0, 0, p.width, p.height, buf);
    images.push(Array.from(buf));
  }
  renderer.setRenderTarget(null);
  target.dispose();
  s.dispose();
  return { revision: THREE.REVISION, pixels: images[0], images };
};
window.pageReady = true;
</script></body></html>
""" % {"scene": _SCENE_JS}

_DEMO_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>microfacet glints</title>
<script type="importmap">{"imports": {"three": "%(three)s"}}</script>
<style>body { margin: 0; background: #000; }</style></head><body>
<script type="module">
import * as THREE from 'three';
import * as M from './glints-material.js';
%(scene)s
const renderer = new THREE.WebGLRenderer({ antialias: false });
renderer.setPixelRatio(1);
renderer.toneMapping = THREE.ACESFilmicToneMapping;
document.body.appendChild(renderer.domElement);
const p = %(params)s;
const s = await renderGlints(THREE, renderer, M, p);
let t0 = performance.now();
renderer.setAnimationLoop(() => {            // the light circles: the glints move
  const t = (performance.now() - t0) / 4000;
  const light = s.scene.children.find(o => o.isPointLight);
  const r = p.mesh === 'sphere' ? 0.5 * Math.hypot(p.light[0], p.light[1]) : Math.hypot(p.light[0], p.light[1]);
  light.position.set(r * Math.sin(2 * Math.PI * t) + p.light[0], p.light[1], p.light[2]);
  renderer.render(s.scene, s.camera);
});
</script></body></html>
"""


def _max_window(n) -> int:
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"max_window must be a positive integer, got {n!r}")
    return int(n)


def export_glints_threejs(ms, out, *, width: int = 512, view_deg: float = 50.0, light=(0.0, 0.35, 0.9),
                          intensity: float = 1.0, three_url: str = THREE_URL,
                          max_window: int = MAX_WINDOW, mesh: str = "plane") -> Path:
    """Write the folder ``out``: ``glints-material.js`` (:func:`material_module`),
    ``lobes.json``/``lobes.bin`` (:func:`write_lobes`) and ``index.html``, a page that renders
    (``mesh="plane"``) the plane of :class:`~microfacet.glints.figures.PlaneScene` (``width``
    pixels, elevation ``view_deg``) under a point light at ``light`` circling over it, or
    (``mesh="sphere"``) the sphere of :class:`SphereScene` (``width`` pixels square, its own
    camera and light, which circles), with three.js from ``three_url``. Serve the folder over
    HTTP (``python -m http.server``); returns ``out``.

    Parameters
    ----------
    ms : Microsurface
        A lobe mixture (e.g. ``Microsurface.load("scratches.npz")``).
    out : str or os.PathLike
        The folder (created).
    width : int
        The page's image width in pixels.
    view_deg : float
        Camera elevation from the plane, degrees.
    light : (3,) sequence
        Position of the point light.
    intensity : float
        The light's intensity.
    three_url : str
        The ``three.module.js`` of the page's import map.
    max_window : int
        Lobes per axis summed at one level.
    mesh : {"plane", "sphere"}
        The demo's mesh (``view_deg``, ``light`` and ``intensity`` are the plane's).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ValueError
        ``max_window`` is not a positive integer, or ``mesh`` is neither ``"plane"`` nor ``"sphere"``.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> slopes = 0.1 * np.random.default_rng(0).standard_normal((4, 4, 2))     # a 4 x 4 normal map's slopes
    >>> ms = mf.glints.Microsurface.from_slopes(slopes)
    >>> web = export_glints_threejs(ms, "web", width=64)
    >>> "renderGlints" in (web / "index.html").read_text()
    True
    """
    from ..glints.figures import PlaneScene
    max_window = _max_window(max_window)
    if mesh not in MESHES:
        raise ValueError(f"mesh must be one of {', '.join(MESHES)}, got {mesh!r}")
    scene = PlaneScene(width=int(width), view_deg=float(view_deg), light=tuple(map(float, light)),
                       intensity=float(intensity))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "glints-material.js").write_text(material_module())
    write_lobes(ms, out)
    params = {"lobes": "./lobes.json", "width": scene.width, "height": scene.height, "viewDeg": scene.view_deg,
              "light": list(scene.light), "intensity": scene.intensity,
              "options": {"maxWindow": max_window}}
    if mesh == "sphere":
        sphere = SphereScene(width=int(width))
        params = dict(sphere.params(), lobes="./lobes.json",
                      options={"maxWindow": max_window, "uvScale": list(sphere.uv_scale)})
    (out / "index.html").write_text(_DEMO_PAGE % {"three": three_url, "scene": _SCENE_JS,
                                                  "params": json.dumps(params)})
    return out


def _material_options(f0, exact: bool, g2: str, pixel_sigma, max_window: int, uv_scale=(1.0, 1.0),
                      bitangent_sign: int = 1) -> dict:
    """``createGlintMaterial``'s options for :class:`GlintsRenderer`, checked."""
    from ..glints.figures import PIXEL_SIGMA
    if g2 not in ("correlated", "separable"):
        raise ValueError(f"g2 must be 'correlated' or 'separable', got {g2!r}")
    if bitangent_sign not in (1, -1):
        raise ValueError(f"bitangent_sign must be 1 or -1, got {bitangent_sign!r}")
    f0 = [1.0, 1.0, 1.0] if f0 is None else list(np.broadcast_to(np.asarray(f0, float), (3,)))
    return {"f0": f0, "exact": bool(exact), "separable": g2 == "separable",
            "pixelSigma": float(PIXEL_SIGMA if pixel_sigma is None else pixel_sigma),
            "maxWindow": _max_window(max_window), "uvScale": [float(v) for v in uv_scale],
            "bitangentSign": int(bitangent_sign)}


class GlintsRenderer(ThreeRenderer):
    """Renders a :class:`~microfacet.glints.Microsurface` on the plane of a
    :class:`~microfacet.glints.figures.PlaneScene` with the three.js material, in the system
    Chromium (WebGL2 on SwiftShader), and reads the float image back: the three.js twin of
    :func:`microfacet.glints.figures.render_pbrdf`.

    Parameters
    ----------
    timeout_ms : int
        Milliseconds the page may take to start and to render.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> slopes = 0.1 * np.random.default_rng(0).standard_normal((4, 4, 2))     # a 4 x 4 normal map's slopes
    >>> ms = mf.glints.Microsurface.from_slopes(slopes)
    >>> from microfacet.glints.figures import PlaneScene
    >>> with GlintsRenderer() as r:                                    # doctest: +SKIP
    ...     img = r.render_scene(ms, PlaneScene(width=16))
    >>> img.shape                                                      # doctest: +SKIP
    (12, 16, 3)
    """

    HTML = _TEST_PAGE

    def __init__(self, timeout_ms: int = 60000):
        super().__init__(timeout_ms)
        self._count = 0

    def render_scene(self, ms, scene, *, f0=None, exact: bool = True, g2: str = "correlated",
                     pixel_sigma: float | None = None, max_window: int = MAX_WINDOW,
                     tangents: bool = False) -> np.ndarray:
        """``(scene.height, scene.width, 3)`` linear radiance (row 0 the far edge, as
        :func:`~microfacet.glints.figures.render_pbrdf`): ``I / r^2 F eval_cos`` per pixel.
        ``f0``: Schlick F0 (None: ideal mirror facets, the library's default); ``exact``, ``g2``
        as :class:`~microfacet.glints.PatchBRDF`; ``pixel_sigma`` default
        :data:`~microfacet.glints.figures.PIXEL_SIGMA`; ``max_window``: lobes per axis summed at
        one level (wider footprints: coarser lobe levels); ``tangents``: give the plane a tangent
        attribute (``computeTangents()``) instead of the shader's derivative tangents.

        Parameters
        ----------
        ms : microfacet.glints.Microsurface
            The glint microsurface (its lobe pyramid is written for the page).
        scene : microfacet.glints.figures.PlaneScene
            The plane, camera and point light (:func:`~microfacet.glints.figures.render_pbrdf`'s).
        f0 : float or (3,) array_like, optional
            Schlick ``F0`` (None: ideal mirror facets).
        exact : bool
            Exact lobe evaluation, as :class:`~microfacet.glints.PatchBRDF`.
        g2 : {"correlated", "separable"}
            Masking-shadowing form, as :class:`~microfacet.glints.PatchBRDF`.
        pixel_sigma : float, optional
            Pixel footprint's standard deviation (default :data:`~microfacet.glints.figures.PIXEL_SIGMA`).
        max_window : int
            Lobes per axis summed at one level (wider footprints use coarser levels).
        tangents : bool
            ``computeTangents()`` on the plane (else the shader derives the tangent).

        Returns
        -------
        (height, width, 3) ndarray
            Linear radiance read back from the render target.
        """
        p = {"width": int(scene.width), "height": int(scene.height), "viewDeg": float(scene.view_deg),
             "light": [float(v) for v in scene.light], "intensity": float(scene.intensity),
             "tangents": bool(tangents)}
        options = _material_options(f0, exact, g2, pixel_sigma, max_window)
        return self._render(ms, p, options, [0])[0][..., :3].copy()

    def render_sphere(self, ms, scene: SphereScene, *, f0=None, exact: bool = True, g2: str = "correlated",
                      pixel_sigma: float | None = None, max_window: int = MAX_WINDOW, bitangent_sign: int = 1):
        """Render :class:`SphereScene` with the material and read back, from the same material in
        its ``debug`` modes (:data:`DEBUG_OUTPUTS`), the inputs it evaluated at each pixel.
        Arguments as :meth:`render_scene`; ``bitangent_sign``: the material's ``bitangentSign``.

        Parameters
        ----------
        ms : microfacet.glints.Microsurface
            The glint microsurface.
        scene : SphereScene
            Sphere, camera and point light.
        f0, exact, g2, pixel_sigma, max_window
            As :meth:`render_scene`.
        bitangent_sign : int
            1 or -1 (the material's ``bitangentSign``).

        Returns
        -------
        image : (width, width, 3) ndarray
            Linear radiance, row 0 the image's top.
        inputs : ShaderInputs
            The per-pixel inputs (:func:`pbrdf_at_inputs` evaluates the library there).
        """
        if not isinstance(scene, SphereScene):
            raise ValueError(f"scene must be a SphereScene, got {type(scene).__name__}")
        p = scene.params()
        options = _material_options(f0, exact, g2, pixel_sigma, max_window, scene.uv_scale, bitangent_sign)
        imgs = self._render(ms, p, options, list(range(9)))
        covered = imgs[2][..., 3] > 0.5      # debug mode 2 writes alpha 1, the clear colour is 0
        m1, m2 = imgs[1], imgs[2]
        inputs = ShaderInputs(uv=m1[..., :2], duv_dx=m1[..., 2:], duv_dy=m2[..., :2], irradiance=m2[..., 2],
                              wo=imgs[3][..., :3], wi=imgs[4][..., :3], tangent=imgs[5][..., :3],
                              bitangent=imgs[6][..., :3], normal=imgs[7][..., :3], position=imgs[8][..., :3],
                              covered=covered)
        return imgs[0][..., :3].copy(), inputs

    def _render(self, ms, p, options: dict, modes):
        """The page's float images ``(h, w, 4)`` per debug mode, row 0 the top (``options``:
        :func:`_material_options`)."""
        root = self.root
        if not (root / "glints-material.js").exists():
            (root / "glints-material.js").write_text(material_module())
        self._count += 1
        lobes = write_lobes(ms, root, f"lobes{self._count}")
        p = dict(p, lobes="/" + lobes.name, modes=[int(m) for m in modes], options=options)
        out = self.page.evaluate("(p) => window.renderGlints(p)", p)
        self.revision = out["revision"]
        w, h = p["width"], p["height"]
        return [np.ascontiguousarray(np.asarray(im, np.float64).reshape(h, w, 4)[::-1]) for im in out["images"]]
