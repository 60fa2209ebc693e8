"""The glTF export in its real consumers: Khronos ``gltf-validator`` and three.js in Chromium.

Both come from npm (``make setup-npm``: ``three`` and ``gltf-validator`` in the git-ignored
``.npm-export``; :func:`npm_modules` finds them, ``$MICROFACET_NPM_DIR`` overrides).
:func:`validate_gltf` runs the validator under node and returns its report.
:class:`ThreeRenderer` serves a page on 127.0.0.1 that loads a ``.glb`` with three.js's
``GLTFLoader`` (so ``KHR_materials_specular``/``_ior``/``_anisotropy``/``_clearcoat`` become a
``MeshPhysicalMaterial`` as in any three.js application), lights it with one
``DirectionalLight`` of irradiance 1, looks at it with an orthographic camera (the view of
:class:`microfacet.render.Sphere`: x right, y up, ``[-1, 1]^2``) and reads a float render
target back, in the system Chromium through Playwright (WebGL2 on SwiftShader). Two stock
effects of three.js are removed from its shader chunks for the comparison, since the glTF
material defines neither: the multiple-scattering compensation of direct light
(``material.multiScatteringCompensation``, Fdez-Agüera 2019) and ``material.roughness +=
geometryRoughness`` (its specular anti-aliasing). With ``exact_schlick`` (default) a third:
three.js evaluates Schlick's ``(1 - c)^5`` as Epic's ``exp2((-5.55473 c - 6.98316) c)``
(Karis 2013), 0.7 % off on a dielectric sphere, replaced by the power the glTF specification
writes. The page fails if three.js's chunks no longer contain these lines.

Examples
--------
>>> with ThreeRenderer() as r:                                   # doctest: +SKIP
...     image = r.render("sphere.glb", size=64)
"""
from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError

__all__ = ["npm_modules", "validate_gltf", "ThreeRenderer", "chromium", "NPM_DIR_ENV", "PAGE", "PAGE_PROLOGUE"]

#: Environment variable naming the folder whose ``node_modules`` holds three and gltf-validator.
NPM_DIR_ENV = "MICROFACET_NPM_DIR"
_HERE = Path(__file__).resolve().parent
DEFAULT_NPM_DIR = _HERE.parents[2] / ".npm-export"
CHROMIUM = ("/usr/lib/chromium/chromium", "/usr/bin/chromium", "/usr/bin/chromium-browser")


def npm_modules(required: bool = True) -> Path | None:
    """The ``node_modules`` folder with ``three`` and ``gltf-validator``: under
    ``$MICROFACET_NPM_DIR``, else the repository's ``.npm-export``; when absent, ``None`` or
    (``required``) a :class:`MicrofacetError` saying in one line what to do.

    Parameters
    ----------
    required : bool
        Raise instead of returning None.

    Returns
    -------
    Path or None
        The ``node_modules`` folder.

    Examples
    --------
    :data:`NPM_DIR_ENV` names the folder first; the answer depends on the machine:

    >>> NPM_DIR_ENV
    'MICROFACET_NPM_DIR'
    >>> mods = npm_modules(required=False)
    >>> mods is None or (mods.name == "node_modules" and (mods / "three").is_dir())
    True
    """
    env = os.environ.get(NPM_DIR_ENV)
    for base in ([Path(env)] if env else []) + [DEFAULT_NPM_DIR]:
        mods = base / "node_modules"
        if (mods / "three" / "build" / "three.module.js").is_file() and (mods / "gltf-validator").is_dir():
            return mods
    if required:
        raise MicrofacetError(f"three.js / gltf-validator not found: run 'make setup-npm' (npm install three "
                              f"gltf-validator into .npm-export) or set {NPM_DIR_ENV}")
    return None


def chromium(required: bool = True) -> str | None:
    """Path of the system Chromium (never a Playwright download), or None / an error.

    Parameters
    ----------
    required : bool
        Raise a :class:`MicrofacetError` saying what to install instead of returning None.

    Returns
    -------
    str or None
        The executable.

    Examples
    --------
    >>> exe = chromium(required=False)
    >>> exe is None or Path(exe).exists()
    True
    """
    exe = next((c for c in CHROMIUM if Path(c).exists()), shutil.which("chromium"))
    if exe is None and required:
        raise MicrofacetError("no system Chromium: apt-get install chromium")
    return exe


_VALIDATE = """
const v = require(process.argv[1]);
const fs = require('fs');
const data = new Uint8Array(fs.readFileSync(process.argv[2]));
v.validateBytes(data, {uri: process.argv[2], maxIssues: 100}).then(r => {
  process.stdout.write(JSON.stringify(r));
}).catch(e => { process.stderr.write(String(e)); process.exit(1); });
"""


def validate_gltf(path, timeout: float = 60.0) -> dict:
    """The Khronos glTF-Validator report of ``path`` (``.glb``/``.gltf``): a dict whose
    ``issues`` has ``numErrors``, ``numWarnings``, ``numInfos`` and ``messages``.

    Parameters
    ----------
    path : str or os.PathLike
        The file to validate.
    timeout : float
        Seconds node may take.

    Returns
    -------
    dict
        The validator's JSON report.

    Raises
    ------
    MicrofacetError
        node, the validator (:func:`npm_modules`) or the validation failed.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.export.gltf import gltf_material, write_glb
    >>> glb = write_glb(gltf_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)))[0], "sphere.glb")
    >>> validate_gltf(glb)["issues"]["numErrors"]                # doctest: +SKIP
    0
    """
    mods = npm_modules()
    node = shutil.which("node")
    if node is None:
        raise MicrofacetError("node not found (install nodejs 20)")
    r = subprocess.run([node, "-e", _VALIDATE, str(mods / "gltf-validator"), str(Path(path).resolve())],
                       capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        raise MicrofacetError(f"gltf-validator failed on {path}: {r.stderr.strip()[-300:]}")
    return json.loads(r.stdout)


#: The page: three.js with the two patches, and ``window.renderGlb(url, size, light)``.
#: The start of the pages: the import map of the npm three.js, a `patch` of its shader chunks
#: and the two stock effects off (multiple-scattering compensation, `geometryRoughness`).
PAGE_PROLOGUE = """<!doctype html><html><head><meta charset="utf-8">
<script type="importmap">{"imports": {"three": "/node_modules/three/build/three.module.js",
  "three/addons/": "/node_modules/three/examples/jsm/"}}</script></head><body>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
function patch(chunk, from, to) {
  const text = THREE.ShaderChunk[chunk];
  if (!text.includes(from)) throw new Error(`three.js ${THREE.REVISION}: ${chunk} has no '${from}'`);
  THREE.ShaderChunk[chunk] = text.split(from).join(to);
}
patch('lights_physical_pars_fragment', 'irradiance * specularBRDF * material.multiScatteringCompensation',
      'irradiance * specularBRDF');
patch('lights_physical_fragment', 'material.roughness += geometryRoughness;', '');
"""
PAGE = PAGE_PROLOGUE + """patch('lights_physical_fragment', 'material.clearcoatRoughness += geometryRoughness;', '');
if (new URLSearchParams(location.search).get('schlick') !== 'stock')
  patch('common', 'float fresnel = exp2( ( - 5.55473 * dotVH - 6.98316 ) * dotVH );',
        'float fresnel = pow( 1.0 - dotVH, 5.0 );');
const renderer = new THREE.WebGLRenderer({ antialias: false });
renderer.setPixelRatio(1);
window.renderGlb = async (url, size, light) => {
  renderer.setSize(size, size);
  const gltf = await new GLTFLoader().loadAsync(url);
  const scene = new THREE.Scene();
  scene.add(gltf.scene);
  const sun = new THREE.DirectionalLight(0xffffff, 1.0);
  sun.position.set(light[0], light[1], light[2]);
  scene.add(sun); scene.add(sun.target);
  const camera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0.1, 10);
  camera.position.set(0, 0, 5); camera.lookAt(0, 0, 0);
  const target = new THREE.WebGLRenderTarget(size, size, { type: THREE.FloatType, format: THREE.RGBAFormat });
  renderer.setRenderTarget(target);
  renderer.setClearColor(0x000000, 0);
  renderer.clear();
  renderer.render(scene, camera);
  const buf = new Float32Array(size * size * 4);
  renderer.readRenderTargetPixels(target, 0, 0, size, size, buf);
  renderer.setRenderTarget(null);
  target.dispose();
  return { revision: THREE.REVISION, pixels: Array.from(buf) };
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


class ThreeRenderer:
    """Renders ``.glb`` files with three.js in headless Chromium (module docstring); a context
    manager holding one server (127.0.0.1) and one browser page. ``exact_schlick=False`` keeps
    three.js's approximate Schlick term. ``revision``: three.js's. Subclasses serve another page
    through ``HTML`` (it must set ``window.pageReady``) and add files to the served folder ``root``.

    Parameters
    ----------
    timeout_ms : int
        Milliseconds the page may take to start and to render.
    exact_schlick : bool
        Replace three.js's approximate Schlick term by ``(1 - c)^5``.

    Examples
    --------
    The page (:data:`PAGE`) starts from :data:`PAGE_PROLOGUE`, shared by the other pages:

    >>> PAGE.startswith(PAGE_PROLOGUE), "window.pageReady = true" in PAGE
    (True, True)

    Rendering needs three.js (:func:`npm_modules`) and Chromium (:func:`chromium`):

    >>> import microfacet as mf
    >>> from microfacet.export.gltf import gltf_material, write_glb
    >>> glb = write_glb(gltf_material(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)))[0], "sphere.glb")
    >>> with ThreeRenderer() as r:                               # doctest: +SKIP
    ...     image = r.render(glb, size=32)
    >>> image.shape                                              # doctest: +SKIP
    (32, 32, 3)
    """

    #: The page served as ``index.html``.
    HTML = PAGE

    def __init__(self, timeout_ms: int = 60000, exact_schlick: bool = True):
        self.timeout_ms = timeout_ms
        self.exact_schlick = exact_schlick
        self.revision = None

    def __enter__(self):
        from playwright.sync_api import sync_playwright
        mods = npm_modules()
        exe = chromium()
        self._dir = tempfile.TemporaryDirectory()
        root = Path(self._dir.name)
        (root / "node_modules").symlink_to(mods, target_is_directory=True)
        (root / "index.html").write_text(self.HTML)
        handler = functools.partial(_Quiet, directory=str(root))
        self._server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}/"
        self._pw = sync_playwright().start()
        try:
            self._browser = self._pw.chromium.launch(executable_path=exe, headless=True)
            self.page = self._browser.new_page()
            self.errors: list[str] = []
            self.page.on("pageerror", lambda e: self.errors.append(str(e)))
            self._load(self.exact_schlick)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    @property
    def root(self) -> Path:
        """The folder served at :attr:`url` (while the renderer is entered)."""
        return Path(self._dir.name)

    def _load(self, exact_schlick: bool) -> None:
        self.page.goto(self.url + "index.html" + ("" if exact_schlick else "?schlick=stock"))
        try:
            self.page.wait_for_function("window.pageReady === true", timeout=self.timeout_ms)
        except Exception as e:                      # noqa: BLE001 - the page's own error says more
            raise MicrofacetError(f"three.js page did not start: {self.errors or e}") from None
        self.exact_schlick = exact_schlick

    def __exit__(self, *exc):
        for close in (lambda: self._browser.close(), lambda: self._pw.stop(), lambda: self._server.shutdown(),
                      lambda: self._server.server_close(), lambda: self._dir.cleanup()):
            try:
                close()
            except Exception:                       # noqa: BLE001 - best-effort teardown
                pass

    def render(self, glb, size: int = 64, light=(-0.5, 0.5, 1.0), exact_schlick: bool | None = None) -> np.ndarray:
        """``(size, size, 3)`` linear radiance of ``glb`` (row 0 at the top) under a directional
        light of irradiance 1 from ``light``; ``exact_schlick`` (None: as constructed) reloads the
        page with or without that patch.

        Parameters
        ----------
        glb : str or path-like
            The ``.glb`` file to render.
        size : int, optional
            Image width and height in pixels (default 64).
        light : (float, float, float), optional
            Direction toward the light, in world coordinates.
        exact_schlick : bool, optional
            Render with (``True``) or without the exact-Schlick patch; ``None`` (default): as
            the renderer was constructed.

        Returns
        -------
        numpy.ndarray, shape (size, size, 3)
            Linear radiance, row 0 at the top.
        """
        if exact_schlick is not None and exact_schlick != self.exact_schlick:
            self._load(exact_schlick)
        name = f"m{abs(hash(str(glb))) % 10**8}.glb"
        shutil.copyfile(glb, Path(self._dir.name) / name)
        out = self.page.evaluate("([u, s, l]) => window.renderGlb(u, s, l)", [name, int(size), list(map(float, light))])
        self.revision = out["revision"]
        img = np.asarray(out["pixels"], np.float64).reshape(size, size, 4)[::-1, :, :3]
        return np.ascontiguousarray(img)
