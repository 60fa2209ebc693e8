"""LEADR textures in three.js: a plane receding to the horizon, naive MIPs vs LEADR MIPs vs a
supersampled reference (the validation of :mod:`microfacet.export.leadr_textures`).

:class:`PlaneRenderer` serves a page on 127.0.0.1 that loads the exported plane ``.glb`` with
three.js's ``GLTFLoader`` and ``KTX2Loader`` (KHR_texture_basisu images load with their own MIP
chains), so that the glTF material becomes the ``MeshPhysicalMaterial`` any three.js application
gets (normal map, roughness from ``metallicRoughness`` G, ``KHR_materials_anisotropy``),
optionally replaces its three textures by ``DataTexture`` s carrying a given MIP chain
(``texture.mipmaps = [...]``, ``generateMipmaps = false``: three.js keeps its own MIP selection) or
level 0 alone without MIPs, scales the plane, looks at it from a grazing camera under one
``DirectionalLight`` and reads a float render target back, box-averaged over ``supersample^2``
pixels, in the system Chromium through Playwright (as :class:`microfacet.export.threejs.ThreeRenderer`,
whose finders it uses). three.js's multiple-scattering compensation and ``geometryRoughness``
(its own specular anti-aliasing, which would blur the naive MIPs too) are removed from its
shader chunks, so that the comparison is of the textures alone. A third patch (``mapped_frame=True``,
the default) fixes a limitation of three.js that the comparison would otherwise measure: its
anisotropic lobe (used whenever ``material.anisotropy > 0``, so for every texel of an anisotropy
map, even one of strength 0) takes its tangent and bitangent from the geometric frame, not
re-orthogonalised against the normal-mapped normal, so the normal map hardly moves the
anisotropic GGX lobe ``D(T.h, B.h, N.h)``; the patch turns the anisotropy tangent into the plane
of the mapped normal (Gram-Schmidt) and takes ``B = N x T``. ``mapped_frame=False`` renders
stock three.js.

:func:`compare_plane` renders (a) naive MIPs (:func:`~microfacet.export.leadr_textures.naive_textures`:
the box-filtered level-0 textures, a constant roughness), (b) the LEADR MIPs and (c) the
reference: level 0 without MIPs rendered at ``supersample`` times the resolution and
box-downsampled, and returns the relative L1 error of (a) and (b) against (c).

Examples
--------
>>> import microfacet as mf
>>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((64, 64), 0.4, seed=1), roughness=0.05)
>>> with PlaneRenderer() as r:                                          # doctest: +SKIP
...     result = compare_plane(pyramid, r, "out_dir")
...     result["errors"]                                                 # {'naive': ..., 'leadr': ...}
"""
from __future__ import annotations

import base64
import functools
import http.server
import shutil
import tempfile
import threading
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .leadr_textures import TEXTURES, leadr_textures, naive_textures, write_plane_glb
from .threejs import PAGE_PROLOGUE, chromium, npm_modules

__all__ = ["PlaneView", "PlaneRenderer", "compare_plane", "relative_l1", "PLANE_PAGE"]


@dataclass(frozen=True)
class PlaneView:
    """The horizon scene: the unit plane of the ``.glb`` scaled to ``extent`` (x, z) world units
    holding ``tiles`` repeats of the map along each axis, a perspective camera (vertical ``fov``
    degrees) at ``eye`` looking at ``target``, a directional light of irradiance 1 from
    ``light``, the textures' ``anisotropy`` (three.js ``texture.anisotropy``: 1 is trilinear), an
    image of ``width x height`` pixels; ``extra``: material overrides (``{"normalScale": k,
    "anisotropy": 0}``: the latter turns KHR_materials_anisotropy off, three.js's isotropic lobe).
    The default looks down 15 degrees at the point 15 units away, the horizon in view.

    Attributes
    ----------
    extent : (float, float)
        The plane's size along world x and z.
    tiles : float
        Repeats of the map along each axis.
    eye, target : (float, float, float)
        Camera position and the point it looks at.
    fov : float
        Vertical field of view, degrees.
    light : (float, float, float)
        Direction toward the directional light.
    anisotropy : int
        three.js ``texture.anisotropy`` of the textures.
    width, height : int
        Image size in pixels.
    extra : dict
        Material overrides.

    Examples
    --------
    >>> view = PlaneView(width=32, height=24, anisotropy=4)
    >>> view.tiles, view.eye, (view.width, view.height)
    (80.0, (0.0, 4.0, 20.0), (32, 24))
    """
    extent: tuple = (40.0, 40.0)
    tiles: float = 80.0
    eye: tuple = (0.0, 4.0, 20.0)
    target: tuple = (0.0, 0.0, 5.0)
    fov: float = 40.0
    light: tuple = (0.0, 0.27, -1.0)
    anisotropy: int = 1
    width: int = 128
    height: int = 96
    extra: dict = field(default_factory=dict)


PLANE_PAGE = PAGE_PROLOGUE + """if (new URLSearchParams(location.search).get('frame') !== 'stock') {
  patch('lights_physical_fragment', 'material.anisotropyB = tbn[ 1 ] * anisotropyV.x - tbn[ 0 ] * anisotropyV.y;',
        'material.anisotropyB = tbn[ 1 ] * anisotropyV.x - tbn[ 0 ] * anisotropyV.y;\\n' +
        'material.anisotropyT = normalize( material.anisotropyT - dot( material.anisotropyT, normal ) * normal );\\n' +
        'material.anisotropyB = normalize( cross( normal, material.anisotropyT ) );');
}
const renderer = new THREE.WebGLRenderer({ antialias: false });
renderer.setPixelRatio(1);
const { KTX2Loader } = await import('three/addons/loaders/KTX2Loader.js');
const ktx2Loader = new KTX2Loader().setTranscoderPath('/node_modules/three/examples/jsm/libs/basis/')
  .detectSupport(renderer);
const gltfLoader = new GLTFLoader().setKTX2Loader(ktx2Loader);
function describe(t) {
  return { compressed: !!t.isCompressedTexture, format: t.format, levels: t.mipmaps ? t.mipmaps.length : 0,
           width: t.image.width, height: t.image.height, minFilter: t.minFilter, colorSpace: t.colorSpace };
}
function bytes(s) { const b = atob(s); const a = new Uint8Array(b.length);
  for (let i = 0; i < b.length; i++) a[i] = b.charCodeAt(i); return a; }
function dataTexture(levels, mips, anisotropy) {
  const l0 = levels[0];
  const tex = new THREE.DataTexture(bytes(l0.data), l0.w, l0.h, THREE.RGBAFormat, THREE.UnsignedByteType);
  tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
  tex.magFilter = THREE.LinearFilter; tex.flipY = false; tex.colorSpace = THREE.NoColorSpace;
  tex.anisotropy = anisotropy; tex.generateMipmaps = false;
  if (mips) {
    tex.mipmaps = levels.map(l => ({ data: bytes(l.data), width: l.w, height: l.h }));
    tex.minFilter = THREE.LinearMipmapLinearFilter;
  } else tex.minFilter = THREE.LinearFilter;
  tex.needsUpdate = true;
  return tex;
}
window.renderPlane = async (url, maps, mips, o) => {
  const gltf = await gltfLoader.loadAsync(url);
  let mesh = null;
  gltf.scene.traverse(x => { if (x.isMesh) mesh = x; });
  mesh.scale.set(o.extent[0], 1, o.extent[1]);
  const m = mesh.material;
  if (!m.normalMap || !m.roughnessMap || !m.anisotropyMap) throw new Error('the glb material lacks a texture');
  const own = { normal: describe(m.normalMap), metallic_roughness: describe(m.roughnessMap),
                anisotropy: describe(m.anisotropyMap) };
  if (maps) {
    m.normalMap = dataTexture(maps.normal, mips, o.anisotropy);
    m.roughnessMap = m.metalnessMap = dataTexture(maps.metallic_roughness, mips, o.anisotropy);
    m.anisotropyMap = dataTexture(maps.anisotropy, mips, o.anisotropy);
  } else {
    for (const t of [m.normalMap, m.roughnessMap, m.anisotropyMap]) {
      if (!mips) { t.minFilter = THREE.LinearFilter; t.generateMipmaps = false; }
      t.anisotropy = o.anisotropy; t.needsUpdate = true;
    }
  }
  if (o.extra.normalScale !== undefined) m.normalScale.set(o.extra.normalScale, o.extra.normalScale);
  if (o.extra.anisotropy !== undefined) m.anisotropy = o.extra.anisotropy;
  m.needsUpdate = true;
  const scene = new THREE.Scene();
  scene.add(gltf.scene);
  const sun = new THREE.DirectionalLight(0xffffff, 1.0);
  sun.position.set(o.light[0], o.light[1], o.light[2]);
  scene.add(sun); scene.add(sun.target);
  const W = o.width * o.ss, H = o.height * o.ss;
  const camera = new THREE.PerspectiveCamera(o.fov, o.width / o.height, 0.01, 1000);
  camera.position.set(o.eye[0], o.eye[1], o.eye[2]); camera.lookAt(o.target[0], o.target[1], o.target[2]);
  renderer.setSize(W, H);
  const target = new THREE.WebGLRenderTarget(W, H, { type: THREE.FloatType, format: THREE.RGBAFormat });
  renderer.setRenderTarget(target); renderer.setClearColor(0x000000, 0); renderer.clear();
  renderer.render(scene, camera);
  const buf = new Float32Array(W * H * 4);
  renderer.readRenderTargetPixels(target, 0, 0, W, H, buf);
  renderer.setRenderTarget(null); target.dispose();
  const out = new Float32Array(o.width * o.height * 3), k = 1 / (o.ss * o.ss);
  for (let y = 0; y < H; y++) for (let x = 0; x < W; x++) {
    const i = 4 * (y * W + x), j = 3 * (Math.floor(y / o.ss) * o.width + Math.floor(x / o.ss));
    out[j] += k * buf[i]; out[j + 1] += k * buf[i + 1]; out[j + 2] += k * buf[i + 2];
  }
  return { revision: THREE.REVISION, maxAnisotropy: renderer.capabilities.getMaxAnisotropy(), textures: own,
           pixels: Array.from(out) };
};
window.pageReady = true;
</script></body></html>
"""


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()


def _rgba_b64(levels: list[np.ndarray]) -> list[dict]:
    """Levels ``(H, W, 3)`` uint8 as ``{w, h, data}`` with RGBA bytes in base64, row 0 first
    (three.js ``flipY = false``: row 0 at ``v = 0``, the top of the image as glTF has it)."""
    out = []
    for a in levels:
        rgba = np.concatenate([a, np.full(a.shape[:2] + (1,), 255, np.uint8)], axis=-1)
        out.append({"w": int(a.shape[1]), "h": int(a.shape[0]),
                    "data": base64.b64encode(np.ascontiguousarray(rgba).tobytes()).decode()})
    return out


class PlaneRenderer:
    """Renders the LEADR plane ``.glb`` in three.js in headless Chromium (module docstring): a
    context manager holding one server (127.0.0.1) and one page. ``revision``: three.js's;
    ``max_anisotropy``: the GPU's (SwiftShader's) largest ``texture.anisotropy``; ``textures``: per
    texture of the last ``.glb`` loaded, what three.js made of its own image (``compressed``, the
    GPU ``format``, MIP ``levels``, ``width``, ``height``, ``minFilter``, ``colorSpace``);
    ``mapped_frame``: the anisotropy frame patch (module docstring). The page's ``GLTFLoader``
    has a ``KTX2Loader`` (three.js's Basis transcoder, WebAssembly, in a worker), so a ``.glb``
    of KHR_texture_basisu textures loads with its KTX2 MIP chains.

    Parameters
    ----------
    timeout_ms : int
        Milliseconds the page may take to start and to render.
    mapped_frame : bool
        Patch three.js's anisotropy frame into the plane of the mapped normal.

    Examples
    --------
    Its page (:data:`PLANE_PAGE`) starts from the shared prologue of
    :mod:`microfacet.export.threejs`:

    >>> from microfacet.export.threejs import PAGE_PROLOGUE
    >>> PLANE_PAGE.startswith(PAGE_PROLOGUE), "window.pageReady = true" in PLANE_PAGE
    (True, True)

    Rendering needs three.js and Chromium (:func:`~microfacet.export.threejs.npm_modules`,
    :func:`~microfacet.export.threejs.chromium`):

    >>> import microfacet as mf
    >>> from microfacet.export.leadr_textures import leadr_textures, write_plane_glb
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1), roughness=0.05)
    >>> glb = write_plane_glb(leadr_textures(pyramid)[0], "plane.glb", tiles=80)
    >>> with PlaneRenderer() as r:                                           # doctest: +SKIP
    ...     image = r.render(glb, PlaneView(width=32, height=24))
    >>> image.shape                                                          # doctest: +SKIP
    (24, 32, 3)
    """

    def __init__(self, timeout_ms: int = 120000, mapped_frame: bool = True):
        self.timeout_ms = timeout_ms
        self.mapped_frame = mapped_frame
        self.revision = None
        self.max_anisotropy = None
        self.textures = None

    def __enter__(self):
        from playwright.sync_api import sync_playwright
        mods, exe = npm_modules(), chromium()
        self._dir = tempfile.TemporaryDirectory()
        root = Path(self._dir.name)
        (root / "node_modules").symlink_to(mods, target_is_directory=True)
        (root / "index.html").write_text(PLANE_PAGE)
        handler = functools.partial(_Quiet, directory=str(root))
        self._server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}/"
        self._pw = sync_playwright().start()
        try:
            self._browser = self._pw.chromium.launch(executable_path=exe, headless=True)
            self.page = self._browser.new_page()
            self.page.set_default_timeout(self.timeout_ms)
            self.errors: list[str] = []
            self.page.on("pageerror", lambda e: self.errors.append(str(e)))
            self.page.goto(self.url + "index.html" + ("" if self.mapped_frame else "?frame=stock"))
            try:
                self.page.wait_for_function("window.pageReady === true", timeout=self.timeout_ms)
            except Exception as e:                  # noqa: BLE001 - the page's own error says more
                raise MicrofacetError(f"three.js page did not start: {self.errors or e}") from None
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc):
        for close in (lambda: self._browser.close(), lambda: self._pw.stop(), lambda: self._server.shutdown(),
                      lambda: self._server.server_close(), lambda: self._dir.cleanup()):
            try:
                close()
            except Exception:                       # noqa: BLE001 - best-effort teardown
                pass

    def render(self, glb, view: PlaneView, levels: list[dict] | None = None, mips: bool = True,
               supersample: int = 1) -> np.ndarray:
        """``(view.height, view.width, 3)`` linear radiance (row 0 at the top) of the plane ``glb``
        seen as ``view``: with ``levels`` (a list of per-level texture dicts, level 0 first) its
        textures replaced by them (``mips``: the whole list as the MIP chain; else level 0 without
        MIPs), without ``levels`` the glb's own (``mips``: three.js's MIPs of level 0); rendered at
        ``supersample`` times the resolution and box-averaged.

        Parameters
        ----------
        glb : str or path-like
            The plane's ``.glb`` file.
        view : PlaneView
            The scene: camera, light, plane extent and tiling, image size.
        levels : list of dict, optional
            Per-level texture dicts (level 0 first) replacing the glb's textures; ``None``
            (default): the glb's own textures.
        mips : bool, optional
            Use ``levels`` as the whole MIP chain (default ``True``; without ``levels``: let
            three.js make the MIPs of level 0); ``False``: level 0 without MIPs.
        supersample : int, optional
            Render at this many times the resolution along each axis and box-average
            (default 1).

        Returns
        -------
        numpy.ndarray, shape (view.height, view.width, 3)
            Linear radiance, row 0 at the top.
        """
        name = f"p{abs(hash(str(glb))) % 10**8}.glb"
        shutil.copyfile(glb, Path(self._dir.name) / name)
        maps = None if levels is None else {t: _rgba_b64([lv[t] for lv in (levels if mips else levels[:1])])
                                            for t in TEXTURES}
        opts = asdict(view)
        opts["ss"] = int(supersample)
        out = self.page.evaluate("([u, m, p, o]) => window.renderPlane(u, m, p, o)", [name, maps, bool(mips), opts])
        if self.errors:
            raise MicrofacetError(f"three.js page error: {self.errors[-1]}")
        self.revision, self.max_anisotropy = out["revision"], out["maxAnisotropy"]
        self.textures = out["textures"]
        img = np.asarray(out["pixels"], np.float64).reshape(view.height, view.width, 3)[::-1]
        return np.ascontiguousarray(img)


def relative_l1(image, reference) -> float:
    """``sum |image - reference| / sum |reference|`` over all pixels and channels.

    Parameters
    ----------
    image, reference : array_like
        Images of the same shape.

    Returns
    -------
    float
        The relative L1 difference.

    Examples
    --------
    >>> relative_l1([[1.0, 3.0]], [[2.0, 2.0]])
    0.5
    """
    ref = np.asarray(reference, np.float64)
    return float(np.abs(np.asarray(image, np.float64) - ref).sum() / np.abs(ref).sum())


def compare_plane(pyramid, renderer: PlaneRenderer, folder, view: PlaneView | None = None,
                  base_roughness=None, supersample: int = 8, ktx2: bool = False) -> dict:
    """Render the horizon plane (module docstring) of a moment pyramid (list of levels or EXR)
    three ways and return ``{"errors": {"naive": e_a, "leadr": e_b}, "images": {"naive",
    "leadr", "reference"}, "glb", "revision"}``; ``e`` is :func:`relative_l1` against the
    reference (level 0 without MIPs at ``supersample`` x the resolution, box-downsampled).
    ``folder`` receives the plane ``.glb``. With ``ktx2`` a fourth: the ``.glb`` of
    :func:`~microfacet.export.leadr_textures.export_leadr` ``"gltf"`` (the LEADR chains as
    KHR_texture_basisu KTX2 images, UASTC) loaded by three.js's ``GLTFLoader`` + ``KTX2Loader``
    and rendered with its own textures (``errors["ktx2"]``, ``images["ktx2"]``, ``ktx2_glb`` and
    ``ktx2_textures``: what three.js made of them, :attr:`PlaneRenderer.textures`).

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    renderer : PlaneRenderer
        An open renderer.
    folder : str or os.PathLike
        Where the plane ``.glb`` is written.
    view : PlaneView, optional
        The scene (default ``PlaneView()``).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    supersample : int
        The reference's supersampling per axis.
    ktx2 : bool
        Also render the KTX2 ``.glb`` (needs the KTX2 writer,
        :func:`~microfacet.export.leadr_textures.ktx2_writer`).

    Returns
    -------
    dict
        ``errors``, ``images``, ``glb``, ``revision``, ``max_anisotropy`` (and with ``ktx2``:
        ``ktx2_glb``, ``ktx2_textures``).

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1), roughness=0.05)
    >>> with PlaneRenderer() as r:                                                         # doctest: +SKIP
    ...     result = compare_plane(pyramid, r, ".", PlaneView(width=32, height=24), supersample=2, ktx2=True)
    >>> sorted(result["errors"]), result["images"]["leadr"].shape                          # doctest: +SKIP
    (['ktx2', 'leadr', 'naive'], (24, 32, 3))
    """
    view = view or PlaneView()
    levels = leadr_textures(pyramid, base_roughness)
    naive = naive_textures(levels[0])
    glb = write_plane_glb(levels[0], Path(folder) / "leadr_plane.glb", tiles=view.tiles)
    images = {"reference": renderer.render(glb, view, levels, mips=False, supersample=supersample),
              "naive": renderer.render(glb, view, naive, mips=True),
              "leadr": renderer.render(glb, view, levels, mips=True)}
    extra = {}
    if ktx2:
        from .leadr_textures import export_leadr
        rep = export_leadr(pyramid, "gltf", Path(folder) / "leadr_plane_ktx2.glb", base_roughness=base_roughness,
                           tiles=view.tiles)
        images["ktx2"] = renderer.render(rep["file"], view)
        extra = {"ktx2_glb": rep["file"], "ktx2_textures": renderer.textures}
    errors = {k: relative_l1(images[k], images["reference"]) for k in images if k != "reference"}
    return {"errors": errors, "images": images, "glb": str(glb), "revision": renderer.revision,
            "max_anisotropy": renderer.max_anisotropy, **extra}
