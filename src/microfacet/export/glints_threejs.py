"""The glint P-BRDF (Chermain, Claux and Mérillou 2019) as a three.js material.

A :class:`~microfacet.glints.Microsurface` (a normal map's mixture of Beckmann lobes) leaves
the library as lobe textures and a ``THREE.ShaderMaterial`` whose fragment shader is the
library's ``glints.glsl`` (:func:`microfacet.glsl.source`): per pixel, the footprint of a
Gaussian pixel filter (``pixelSigma`` pixels, from the screen derivatives of ``uv``), its lobe
window and weights (Eq. 9), the P-NDF and the patch areas (Eq. 13-17) and
``eval_cos = F D_P G2 / (4 A_P(o))`` (Eq. 7) for each three.js ``PointLight`` (its
``color * intensity / d^2``: ``decay`` 2, ``distance`` 0), as
:func:`microfacet.glints.pbrdf.eval_cos_footprints` computes it. The mesh's object-space
``x, y, z`` is the shading frame (a plane in its ``xy``, e.g. ``THREE.PlaneGeometry``) and its
``uv`` the map's (``u`` along columns, ``v = 0`` the map's first row, wrapped).

- :func:`lobe_textures`: per MIP level of the lobe grid, the central moments
  ``(E[x~], E[y~], Var x~, Var y~)`` (RGBA32F) and ``Cov(x~, y~)`` (R32F), float32.
- :func:`fragment_shader`, :func:`vertex_shader`: the GLSL ES 3.00 of the material.
- :func:`material_module`: the ES module ``glints-material.js`` (``loadGlintLobes(THREE, url)``,
  ``createGlintMaterial(THREE, lobes, options)``).
- :func:`export_glints_threejs`: a folder with the module, ``lobes.bin``/``lobes.json`` and a
  demo page (a plane under a point light).
- :class:`GlintsRenderer`: the same material rendered in the system Chromium (the headless
  harness of :mod:`microfacet.export.threejs`), for tests against the library.

Accuracy: float32 throughout (the library sums in float64); at the footprints where the
window fits (:data:`MAX_WINDOW` lobes per axis) the sums are the library's. Larger footprints
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
from pathlib import Path

import numpy as np

from ..glsl import source
from .threejs import ThreeRenderer

__all__ = ["lobe_textures", "vertex_shader", "fragment_shader", "material_module", "export_glints_threejs",
           "GlintsRenderer", "write_lobes", "MAX_WINDOW", "LOBES_FORMAT"]

#: Most lobes per axis summed at one level (``MF_GLINT_MAX_WINDOW``).
MAX_WINDOW = 48
#: three.js of the demo page's import map (the revision the tests render with).
THREE_URL = "https://unpkg.com/three@0.187.0/build/three.module.js"
#: Tag of ``lobes.json``.
LOBES_FORMAT = "microfacet.glints.threejs/1"


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
out vec2 vMfUv;
out vec3 vMfViewPos;
out vec3 vMfT;
out vec3 vMfB;
out vec3 vMfN;
void main() {
    vMfUv = uv * mfUvScale;
    vec4 mv = modelViewMatrix * vec4(position, 1.0);
    vMfViewPos = mv.xyz;
    mat3 m = mat3(modelViewMatrix);
    vMfT = m[0]; vMfB = m[1]; vMfN = m[2];
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
in vec2 vMfUv;
in vec3 vMfViewPos;
in vec3 vMfT;
in vec3 vMfB;
in vec3 vMfN;
void main() {
    vec3 T = normalize(vMfT), B = normalize(vMfB), N = normalize(vMfN);
    vec3 v = isOrthographic ? vec3(0.0, 0.0, 1.0) : normalize(-vMfViewPos);
    vec3 wo = vec3(dot(T, v), dot(B, v), dot(N, v));
    // Gaussian pixel filter of mfPixelSigma pixels mapped to uv: Sigma_P = s^2 J J^T
    vec2 dx = dFdx(vMfUv), dy = dFdy(vMfUv);
    vec3 cov = mfPixelSigma * mfPixelSigma
        * vec3(dx.x * dx.x + dy.x * dy.x, dx.y * dx.y + dy.y * dy.y, dx.x * dx.y + dy.x * dy.y);
    vec3 color = vec3(0.0);
#if NUM_POINT_LIGHTS > 0
    PointLight pl;
    for (int i = 0; i < NUM_POINT_LIGHTS; i++) {
        pl = pointLights[i];
        vec3 L = pl.position - vMfViewPos;
        float d = length(L);
        vec3 l = L / d;
        vec3 wi = vec3(dot(T, l), dot(B, l), dot(N, l));
        float f = mf_glint_eval_cos(mfGlintA, mfGlintB, vMfUv, cov, mfCutoff, wi, wo, mfExact, mfSeparable);
        vec3 F = mf_fresnel_schlick(mfF0, vec3(1.0), dot(wo, normalize(wi + wo)));
        color += pl.color * getDistanceAttenuation(d, pl.distance, pl.decay) * F * f;
    }
#endif
    gl_FragColor = vec4(color, 1.0);
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
// level, default %(max_window)d; wider footprints use coarser lobe levels).
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
  });
  const maxWindow = options.maxWindow ?? %(max_window)d;
  if (!(Number.isInteger(maxWindow) && maxWindow >= 1)) throw new Error(`maxWindow must be an integer >= 1`);
  return new THREE.ShaderMaterial({ uniforms, lights: true,
                                    defines: { MF_GLINT_MAX_WINDOW: maxWindow },
                                    vertexShader: VERTEX_SHADER, fragmentShader: FRAGMENT_SHADER });
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
                      "format": LOBES_FORMAT, "max_window": MAX_WINDOW}


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


#: Scene shared by the demo page and :class:`GlintsRenderer`: the library's
#: :class:`~microfacet.glints.figures.PlaneScene` (plane ``[-1, 1]^2`` in ``xy``, orthographic
#: camera of elevation ``viewDeg`` from azimuth ``-y``, a point light), read back as float.
_SCENE_JS = """
async function renderGlints(THREE, renderer, M, p) {
  const lobes = await M.loadGlintLobes(THREE, p.lobes);
  const material = M.createGlintMaterial(THREE, lobes, p.options || {});
  const scene = new THREE.Scene();
  const plane = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), material);
  scene.add(plane);
  const light = new THREE.PointLight(0xffffff, p.intensity, 0, 2);
  light.position.set(p.light[0], p.light[1], p.light[2]);
  scene.add(light);
  const e = p.viewDeg * Math.PI / 180, se = Math.sin(e);
  const camera = new THREE.OrthographicCamera(-1, 1, se, -se, 0.1, 20);
  camera.up.set(0, 0, 1);
  camera.position.set(0, -5 * Math.cos(e), 5 * se);
  camera.lookAt(0, 0, 0);
  renderer.setSize(p.width, p.height);
  const dispose = () => { material.dispose(); plane.geometry.dispose(); lobes.a.dispose(); lobes.b.dispose(); };
  return { scene, camera, dispose };
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
  renderer.clear();
  renderer.render(s.scene, s.camera);
  const buf = new Float32Array(p.width * p.height * 4);
  renderer.readRenderTargetPixels(target, 0, 0, p.width, p.height, buf);
  renderer.setRenderTarget(null);
  target.dispose();
  s.dispose();
  return { revision: THREE.REVISION, pixels: Array.from(buf) };
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
  const r = Math.hypot(p.light[0], p.light[1]);
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
                          max_window: int = MAX_WINDOW) -> Path:
    """Write the folder ``out``: ``glints-material.js`` (:func:`material_module`),
    ``lobes.json``/``lobes.bin`` (:func:`write_lobes`) and ``index.html``, a page that renders the
    plane of :class:`~microfacet.glints.figures.PlaneScene` (``width`` pixels, elevation
    ``view_deg``) under a point light at ``light`` circling over it, with three.js from
    ``three_url``. Serve the folder over HTTP (``python -m http.server``); returns ``out``.

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

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ValueError
        ``max_window`` is not a positive integer.

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
    scene = PlaneScene(width=int(width), view_deg=float(view_deg), light=tuple(map(float, light)),
                       intensity=float(intensity))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "glints-material.js").write_text(material_module())
    write_lobes(ms, out)
    params = {"lobes": "./lobes.json", "width": scene.width, "height": scene.height, "viewDeg": scene.view_deg,
              "light": list(scene.light), "intensity": scene.intensity,
              "options": {"maxWindow": max_window}}
    (out / "index.html").write_text(_DEMO_PAGE % {"three": three_url, "scene": _SCENE_JS,
                                                  "params": json.dumps(params)})
    return out


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
                     pixel_sigma: float | None = None, max_window: int = MAX_WINDOW) -> np.ndarray:
        """``(scene.height, scene.width, 3)`` linear radiance (row 0 the far edge, as
        :func:`~microfacet.glints.figures.render_pbrdf`): ``I / r^2 F eval_cos`` per pixel.
        ``f0``: Schlick F0 (None: ideal mirror facets, the library's default); ``exact``, ``g2``
        as :class:`~microfacet.glints.PatchBRDF`; ``pixel_sigma`` default
        :data:`~microfacet.glints.figures.PIXEL_SIGMA`; ``max_window``: lobes per axis summed at
        one level (wider footprints: coarser lobe levels).

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

        Returns
        -------
        (height, width, 3) ndarray
            Linear radiance read back from the render target.
        """
        from ..glints.figures import PIXEL_SIGMA
        if g2 not in ("correlated", "separable"):
            raise ValueError(f"g2 must be 'correlated' or 'separable', got {g2!r}")
        root = self.root
        if not (root / "glints-material.js").exists():
            (root / "glints-material.js").write_text(material_module())
        self._count += 1
        lobes = write_lobes(ms, root, f"lobes{self._count}")
        f0 = [1.0, 1.0, 1.0] if f0 is None else list(np.broadcast_to(np.asarray(f0, float), (3,)))
        p = {"lobes": "/" + lobes.name, "width": int(scene.width), "height": int(scene.height),
             "viewDeg": float(scene.view_deg), "light": [float(v) for v in scene.light],
             "intensity": float(scene.intensity),
             "options": {"f0": f0, "exact": bool(exact), "separable": g2 == "separable",
                         "pixelSigma": float(PIXEL_SIGMA if pixel_sigma is None else pixel_sigma),
                         "maxWindow": _max_window(max_window)}}
        out = self.page.evaluate("(p) => window.renderGlints(p)", p)
        self.revision = out["revision"]
        w, h = p["width"], p["height"]
        img = np.asarray(out["pixels"], np.float64).reshape(h, w, 4)[::-1, :, :3]
        return np.ascontiguousarray(img)
