"""Exported MaterialX materials rendered by MaterialX's own ``GlslRenderer``, against the library.

:func:`render_mtlx` draws a material of a ``.mtlx`` document (by default the exact pbrlib
graph ``M_microfacet_exact`` of :func:`microfacet.export.mtlx.mtlx_document`) with
``MaterialX.PyMaterialXRenderGlsl.GlslRenderer`` (OpenGL through GLX: it needs an X display;
:func:`xvfb_display` starts a private ``Xvfb`` when none is set) in a process of its own,
spawned on first use and kept (a GLX context cannot share a process with another OpenGL
context, such as moderngl's EGL one), on the comparison sphere of
:mod:`microfacet.export.consumers`: an orthographic unit sphere filling the image, lit by one
directional light of irradiance 1 from :data:`~microfacet.export.comparison.LIGHT`, the tangent
the world x axis projected on the surface, no environment. The image is linear Rec. 709 RGB,
``E f cos theta_i`` per pixel, directly comparable with
:func:`~microfacet.export.comparison.library_render` (same pixel centres, same frame).

Set-up, what makes the comparison exact:

* Geometry: the visible hemisphere as a height field with one vertex at every pixel centre
  (written as an OBJ and read by MaterialX's ``TinyObjLoader``), so the rasterizer's
  interpolated position and normal at each pixel centre are the sphere's own. Texture
  coordinates ``(u, v) = (x, atan2(y, z))``: MaterialX derives tangents from them (Lengyel's
  method), and along ``v = const`` the surface runs in the plane through the x axis, i.e.
  along the world x axis projected on the surface (the library's :func:`tangent_frame`).
* Camera: orthographic over ``[-1, 1]^2`` seen from ``(0, 0, 1e6)`` (the shader takes the
  view direction from the eye position: at that distance it is ``+z`` to 1e-6 rad).
* Light: one ``directional_light`` (``direction = -LIGHT``, colour 1, intensity 1); indirect
  lighting off (the environment maps bound are MaterialX's zero image), with
  ``hwSpecularEnvironmentMethod = SPECULAR_ENVIRONMENT_FIS`` (``NONE`` generates GLSL that
  does not compile in MaterialX 1.39.5: ``u_refractionTwoSided`` undeclared).
* Shader compilation: the render process sets ``GALLIVM_PERF=nopt`` (unless set) so that
  Mesa's llvmpipe skips LLVM's optimization passes: with them, the shader of a fit's mixture
  of a dozen lobes takes minutes to compile on the CPU (LLVM's scalar evolution), without
  them seconds, for the same image.
* pbrlib's multiple-scattering energy compensation (Turquin 2019, ``mx_ggx_energy_compensation``)
  returns 1 in a copy of MaterialX's ``libraries`` folder written to a temporary folder
  (:func:`patched_libraries`; the installed package is untouched): the library's BRDFs are
  single-scattering.

What remains different is MaterialX's own model (documented in :mod:`.mtlx`): its
anisotropic Smith term uses ``sqrt(alpha_x alpha_y)`` (1.6-1.8 % relL1 on the anisotropic
sphere), and its ``layer`` attenuates the base by ``1 - E_c(theta_o)`` only (the library's
:class:`~microfacet.layered.LayeredBRDF` by ``(1 - E_c(theta_i)) (1 - E_c(theta_o))``), with
``E_c`` from its Schlick albedo fit. :func:`compare_mtlx` returns the relL1
(``sum |a - b| / sum |b|`` over ``r < 0.95``) of the MaterialX render against the library's.

Measured figures per case are in ``experiments/results/export_mtlx.md``
(``experiments/export_mtlx.py``).

Examples
--------
>>> import microfacet as mf
>>> int(sphere_mask(4).sum())                    # pixel centres inside the unit disk
12
>>> EYE_DISTANCE                                 # the eye of the orthographic view, on +z
1000000.0
>>> r = compare_mtlx(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), size=32)     # doctest: +SKIP
>>> r["relL1"] < 0.005                                                  # doctest: +SKIP
True
"""
from __future__ import annotations

import atexit
import contextlib
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from .comparison import LIGHT, library_render, rel_l1

__all__ = ["render_mtlx", "compare_mtlx", "xvfb_display", "xvfb_available", "patched_libraries",
           "stop_xvfb", "sphere_obj", "plane_obj", "sphere_mask", "render_xml", "MaterialXLayer", "mtlx_as_held",
           "EYE_DISTANCE"]

#: Distance of the (orthographic) eye: the view direction the shader derives is ``+z`` to
#: ``1/EYE_DISTANCE`` rad.
EYE_DISTANCE = 1.0e6

_COMPENSATION = "vec3 mx_ggx_energy_compensation(float NdotV, float alpha, vec3 Fss)\n{"


def _mx():
    try:
        import MaterialX as mx
    except ImportError as e:                      # pragma: no cover - the extra is absent
        raise ImportError("MaterialX rendering needs the 'materialx' package: pip install 'microfacet[export]'") from e
    return mx


def sphere_mask(size: int) -> np.ndarray:
    """The pixels of a ``size x size`` comparison image whose centre lies inside the unit disk
    (the pixels :func:`~microfacet.export.comparison.library_render` shades).

    Parameters
    ----------
    size : int
        Image side in pixels.

    Returns
    -------
    (size, size) bool ndarray

    Examples
    --------
    >>> sphere_mask(2).all(), int(sphere_mask(64).sum())
    (np.True_, 3228)
    """
    k = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    return k[None, :] ** 2 + k[:, None] ** 2 < 1.0


def xvfb_available() -> bool:
    """Whether :func:`render_mtlx` can have an X display: ``DISPLAY`` is set or ``Xvfb`` is on
    the ``PATH``.

    Returns
    -------
    bool

    Examples
    --------
    >>> isinstance(xvfb_available(), bool)
    True
    """
    return bool(os.environ.get("DISPLAY")) or shutil.which("Xvfb") is not None


# MaterialX connects to the X server once per process (SimpleWindowLinux keeps a static Xt
# application shell): the display of the first render must outlive every later render.
_XVFB: dict = {"proc": None, "display": None, "stopped": False}


def _end_with_parent() -> None:
    """In the child before ``exec``: SIGTERM when the process that started it ends, even by
    ``kill -9`` (Linux ``prctl(PR_SET_PDEATHSIG)``; elsewhere nothing), so that no Xvfb is
    left behind."""
    import ctypes
    import signal
    try:
        ctypes.CDLL(None).prctl(1, signal.SIGTERM)      # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):                   # pragma: no cover - not Linux
        pass


def _start_xvfb(timeout: float) -> str:
    """Start ``Xvfb`` on a display number it picks itself (``-displayfd``: no race between
    processes) and return ``":N"``."""
    exe = shutil.which("Xvfb")
    if exe is None:
        raise RuntimeError("xvfb_display: no DISPLAY and no Xvfb: apt-get install xvfb")
    read, write = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(write), "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                            pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            preexec_fn=_end_with_parent)
    os.close(write)
    number = b""
    t0 = time.monotonic()
    try:
        while not number.endswith(b"\n"):
            ready, _, _ = select.select([read], [], [], 0.1)
            chunk = os.read(read, 16) if ready else b""
            if ready and not chunk or time.monotonic() - t0 > timeout:
                proc.kill()
                proc.wait()
                raise RuntimeError(f"xvfb_display: Xvfb did not start within {timeout:g} s (exit {proc.returncode})")
            number += chunk
    finally:
        os.close(read)
    display = ":" + number.decode().strip()
    _XVFB.update(proc=proc, display=display)
    atexit.register(stop_xvfb)
    return display


def stop_xvfb() -> None:
    """Stop :func:`render_mtlx`'s render process and the Xvfb that :func:`xvfb_display`
    started in this process, if any (also run at exit). A later :func:`render_mtlx` spawns a
    new render process; in a process whose Xvfb was stopped, :func:`xvfb_display` raises
    ``RuntimeError`` (MaterialX cannot reconnect to another display in the same process).

    Examples
    --------
    >>> stop_xvfb()          # no-op when this process started none   # doctest: +SKIP
    """
    executor = _RENDERER["executor"]
    if executor is not None:                 # render_mtlx's process, which stops its own Xvfb
        _RENDERER["executor"] = None
        executor.shutdown()
    proc = _XVFB["proc"]
    if proc is None:
        return
    _XVFB.update(proc=None, stopped=True)
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:     # pragma: no cover - Xvfb ignores SIGTERM
        proc.kill()
        proc.wait()


@contextlib.contextmanager
def xvfb_display(timeout: float = 10.0):
    """Context manager: an X display for MaterialX's GL renderer, yielded as a string.

    Uses ``DISPLAY`` when it is set; otherwise starts ``Xvfb`` on a display number of its
    choosing (``-displayfd``, ``-nolisten tcp``) on first use, sets ``DISPLAY`` while inside,
    and keeps that Xvfb for the rest of the process (MaterialX connects to the X server once
    per process); it is stopped at exit or by :func:`stop_xvfb`.

    Parameters
    ----------
    timeout : float
        Seconds to wait for Xvfb to come up.

    Yields
    ------
    str
        The display (``":N"``).

    Raises
    ------
    RuntimeError
        Xvfb absent, not up within ``timeout``, or already stopped in this process.

    Examples
    --------
    >>> with xvfb_display() as display:                 # doctest: +SKIP
    ...     image = render_mtlx("sphere.mtlx", size=32)
    """
    if os.environ.get("DISPLAY") and _XVFB["proc"] is None:
        yield os.environ["DISPLAY"]
        return
    if _XVFB["stopped"]:
        raise RuntimeError("xvfb_display: this process's Xvfb was stopped and MaterialX cannot reconnect; "
                           "render in a new process")
    display = _XVFB["display"] if _XVFB["proc"] is not None else _start_xvfb(timeout)
    before = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = display
    try:
        yield display
    finally:
        if before is None:
            os.environ.pop("DISPLAY", None)
        else:
            os.environ["DISPLAY"] = before


def patched_libraries(dest) -> Path:
    """Copy MaterialX's ``libraries`` folder under ``dest`` with pbrlib's GGX energy
    compensation (``mx_ggx_energy_compensation``: Turquin 2019, Eq. 14 and 16) returning 1,
    so that every pbrlib GGX lobe is single-scattering as the library's. The installed
    package is not modified.

    Parameters
    ----------
    dest : path-like
        Folder to write ``libraries/`` into (about 10 MB).

    Returns
    -------
    Path
        ``dest``: the root to search for libraries and GLSL sources.

    Raises
    ------
    RuntimeError
        The function is not where MaterialX 1.39 has it (another MaterialX version).

    Examples
    --------
    >>> root = patched_libraries("mx_copy")                             # doctest: +SKIP
    >>> "return vec3(1.0);" in (root / "libraries/pbrlib/genglsl/lib/mx_microfacet_specular.glsl").read_text()  # doctest: +SKIP
    True
    """
    mx = _mx()
    root = Path(mx.getDefaultDataSearchPath().asString().split(os.pathsep)[0])
    dest = Path(dest)
    shutil.copytree(root / "libraries", dest / "libraries", dirs_exist_ok=True)
    spec = dest / "libraries" / "pbrlib" / "genglsl" / "lib" / "mx_microfacet_specular.glsl"
    text = spec.read_text()
    if _COMPENSATION not in text:
        raise RuntimeError(f"patched_libraries: mx_ggx_energy_compensation not found in {spec}")
    spec.write_text(text.replace(_COMPENSATION, _COMPENSATION + "\n    return vec3(1.0);", 1))
    return dest


def sphere_obj(path, size: int) -> Path:
    """Write the comparison sphere's visible hemisphere as an OBJ for a ``size x size`` image.

    One vertex at each pixel centre (and a ring of one pixel beyond the image, so that every
    pixel centre is inside a triangle), ``z = sqrt(1 - x^2 - y^2)`` and the normal
    ``(x, y, z)`` inside the unit disk, ``z = 0`` and the radial normal outside, texture
    coordinates ``(x, atan2(y, z))`` (module docstring: MaterialX's tangents follow ``u``).
    At the pixel centres the rasterized normal is exact (to float32).

    Parameters
    ----------
    path : path-like
        The ``.obj`` to write.
    size : int
        Image side in pixels.

    Returns
    -------
    Path

    Examples
    --------
    >>> text = sphere_obj("sphere.obj", 4).read_text()
    >>> text.count("\\nv "), text.count("\\nf ")          # (4 + 2)^2 vertices, 2 (4 + 1)^2 triangles
    (36, 50)
    """
    n = int(size)
    k = (np.arange(-1, n + 1) + 0.5) / n * 2.0 - 1.0
    x, y = np.meshgrid(k, -k)                   # row 0 at the top (y = +1), as the library's Sphere
    r2 = x * x + y * y
    z = np.sqrt(np.maximum(0.0, 1.0 - r2))
    outside = r2 >= 1.0
    r = np.sqrt(r2)
    nx = np.where(outside, x / np.maximum(r, 1e-12), x)
    ny = np.where(outside, y / np.maximum(r, 1e-12), y)
    u, v = x, np.arctan2(y, z)
    m = n + 2
    lines = ["# microfacet comparison sphere (height field, one vertex per pixel centre)"]
    lines += [f"v {a:.9g} {b:.9g} {c:.9g}" for a, b, c in zip(x.ravel(), y.ravel(), z.ravel())]
    lines += [f"vn {a:.9g} {b:.9g} {c:.9g}" for a, b, c in zip(nx.ravel(), ny.ravel(), z.ravel())]
    lines += [f"vt {a:.9g} {b:.9g}" for a, b in zip(u.ravel(), v.ravel())]
    for i in range(m - 1):
        for j in range(m - 1):
            a, b, c, d = (i * m + j + 1, i * m + j + 2, (i + 1) * m + j + 1, (i + 1) * m + j + 2)
            # counter-clockwise seen from +z (rows go down in y)
            lines.append(f"f {a}/{a}/{a} {c}/{c}/{c} {b}/{b}/{b}")
            lines.append(f"f {b}/{b}/{b} {c}/{c}/{c} {d}/{d}/{d}")
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


def plane_obj(path) -> Path:
    """Write the plane ``[-1, 1]^2`` (normal ``+z``, uv ``((x + 1) / 2, (y + 1) / 2)``) as an OBJ of two triangles.

    Parameters
    ----------
    path : path-like
        The ``.obj`` to write.

    Returns
    -------
    Path

    Examples
    --------
    >>> plane_obj("plane.obj").read_text().count("\\nf ")
    2
    """
    path = Path(path)
    path.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
                    "f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    return path


def _document(mx, path_or_document):
    if isinstance(path_or_document, (str, os.PathLike)):
        path = Path(path_or_document)
        if not path.is_file():
            raise ValueError(f"render_mtlx: no MaterialX file {path}")
        doc = mx.createDocument()
        mx.readFromXmlFile(doc, str(path))
        return doc
    return path_or_document


def render_mtlx(path_or_document, size: int = 64, material: str = "M_microfacet_exact", light=LIGHT,
                compensation: bool = False) -> np.ndarray:
    """Render a material of a MaterialX document with MaterialX's ``GlslRenderer`` on the
    comparison sphere (module docstring): ``E f cos theta_i`` per pixel, ``E = 1``.

    Against :func:`~microfacet.export.comparison.library_render` of the BRDF the graph holds,
    relL1 ~1e-6 for isotropic lobes (float32); see the module docstring for what differs.

    Parameters
    ----------
    path_or_document : path-like or MaterialX.Document
        A ``.mtlx`` file or a document (:func:`~microfacet.export.mtlx.mtlx_document`).
    size : int
        Image side in pixels (>= 2); 32-64 render in about 0.5 s.
    material : str
        The material node to render (``"M_microfacet_openpbr"`` for the OpenPBR surface).
    light : (3,) array_like
        Direction toward the directional light (normalized here).
    compensation : bool
        Keep pbrlib's multiple-scattering energy compensation (default off: the libraries
        are read from a patched copy, :func:`patched_libraries`).

    Returns
    -------
    (size, size, 3) float32 ndarray
        Linear Rec. 709 RGB, row 0 at the top, zero outside the unit disk.

    Raises
    ------
    ValueError
        Bad ``size``, no such file or no such material.
    RuntimeError
        No X display can be had (:func:`xvfb_display`).

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.export.mtlx import mtlx_document
    >>> doc, lost = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)))   # doctest: +SKIP
    >>> render_mtlx(doc, size=32).shape                                   # doctest: +SKIP
    (32, 32, 3)
    """
    if int(size) != size or size < 2:
        raise ValueError(f"size must be an integer >= 2, got {size!r}")
    size = int(size)
    mx = _mx()
    doc = _document(mx, path_or_document)
    if doc.getChild(material) is None:
        raise ValueError(f"render_mtlx: the document has no material {material!r}")
    from concurrent.futures.process import BrokenProcessPool
    try:
        img = _render_process().submit(render_xml, mx.writeToXmlString(doc), material, size,
                                       tuple(float(v) for v in np.ravel(light)), bool(compensation)).result()
    except BrokenProcessPool:
        _RENDERER["executor"] = None
        raise RuntimeError("render_mtlx: MaterialX's render process ended abruptly (X display or OpenGL failed)") \
            from None
    out = np.zeros((size, size, 3), np.float32)
    mask = sphere_mask(size)
    out[mask] = img[mask]
    return out


# The process that renders (spawned on first use, kept): MaterialX's GLX context cannot share
# a process with another OpenGL context (an EGL one of moderngl ends the process), and it
# connects to its X display once per process.
_RENDERER: dict = {"executor": None}


def _render_process():
    executor = _RENDERER["executor"]
    if executor is None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        from ..batch.workers import exit_with
        executor = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=exit_with,
                                       initargs=(os.getpid(),))       # ends with this process, even after kill -9
        _RENDERER["executor"] = executor
        atexit.register(executor.shutdown)
    return executor


def render_xml(xml: str, material: str, size: int, light, compensation: bool = False, mesh: str = "sphere",
               folder=None) -> np.ndarray:
    """In a render process (GLX, an X display: a private Xvfb when none is set): MaterialX's
    ``GlslRenderer`` draws ``material`` of the document ``xml`` on ``mesh`` seen along ``-z``
    (orthographic over ``[-1, 1]^2``), lit by one directional light of irradiance 1 from
    ``light``, no indirect light: ``"sphere"`` the comparison sphere (:func:`sphere_obj`),
    ``"plane"`` the plane ``z = 0`` (:func:`plane_obj`); texture file names resolve in
    ``folder``, ``v = 0`` at an image's bottom row (MaterialX's convention). pbrlib's energy
    compensation is removed unless ``compensation`` (:func:`patched_libraries`).
    :func:`render_mtlx` calls it in its render process, which it keeps.

    Parameters
    ----------
    xml : str
        The document.
    material : str
        The material node to render.
    size : int
        Image side in pixels.
    light : (3,) sequence
        Direction toward the light (normalized here).
    compensation : bool
        Keep pbrlib's multiple-scattering energy compensation.
    mesh : {"sphere", "plane"}
        What is drawn.
    folder : str or PathLike, optional
        Where texture file names resolve.

    Returns
    -------
    (size, size, 3) float32 ndarray
        Linear Rec. 709 RGB, row 0 at the top (outside the sphere: what the rasterizer drew).

    Examples
    --------
    >>> import MaterialX as mx, microfacet as mf
    >>> from microfacet.export.mtlx import mtlx_document
    >>> doc, lost = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)))            # doctest: +SKIP
    >>> render_xml(mx.writeToXmlString(doc), "M_microfacet_exact", 32, (0, 0, 1)).shape   # doctest: +SKIP
    (32, 32, 3)
    """
    # Mesa llvmpipe: no LLVM optimization passes (a graph of 13 lobes compiles in ~13 s, not
    # minutes; the image is the same to float32); before the first GL context of this process
    os.environ.setdefault("GALLIVM_PERF", "nopt")
    if mesh not in ("sphere", "plane"):
        raise ValueError(f"mesh must be 'sphere' or 'plane', got {mesh!r}")
    mx = _mx()
    doc = mx.createDocument()
    mx.readFromXmlString(doc, xml)
    with tempfile.TemporaryDirectory() as tmp, xvfb_display():
        tmp = Path(tmp)
        obj = sphere_obj(tmp / "sphere.obj", size) if mesh == "sphere" else plane_obj(tmp / "plane.obj")
        # the renderer (its X window and GL context) is freed on return, before the display goes
        return _render(doc, doc.getChild(material), tmp, size, light, compensation, obj, folder)


def _render(doc, mat, tmp: Path, size: int, light, compensation: bool, obj: Path, folder) -> np.ndarray:
    """The GlslRenderer part of :func:`render_xml` (an X display is set)."""
    mx = _mx()
    import MaterialX.PyMaterialXGenGlsl as gen_glsl
    import MaterialX.PyMaterialXGenShader as gen
    import MaterialX.PyMaterialXRender as mx_render
    import MaterialX.PyMaterialXRenderGlsl as mx_glsl

    root = Path(mx.getDefaultDataSearchPath().asString().split(os.pathsep)[0]) if compensation \
        else patched_libraries(tmp / "mx")
    search = mx.FileSearchPath(str(root))
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    doc.setDataLibrary(lib)

    generator = gen_glsl.GlslShaderGenerator.create()
    ctx = gen.GenContext(generator)
    ctx.registerSourceCodeSearchPath(search)
    opts = ctx.getOptions()
    # FIS, not NONE: MaterialX 1.39.5's GLSL under NONE references an undeclared u_refractionTwoSided.
    # Indirect lighting is off below, so the environment maps bound are MaterialX's zero image.
    opts.hwSpecularEnvironmentMethod = gen.SPECULAR_ENVIRONMENT_FIS
    opts.hwMaxActiveLightSources = 1
    opts.hwShadowMap = False
    opts.hwAmbientOcclusion = False
    opts.hwSrgbEncodeOutput = False
    opts.targetColorSpaceOverride = "lin_rec709"
    opts.fileTextureVerticalFlip = True          # v = 0 at the image's bottom row (MaterialX's convention)

    w = np.asarray(light, float) / np.linalg.norm(light)
    light_doc = mx.createDocument()
    light_doc.setDataLibrary(lib)
    sun = light_doc.addNode("directional_light", "sun", "lightshader")
    sun.setInputValue("direction", mx.Vector3(*(float(-c) for c in w)))
    sun.setInputValue("color", mx.Color3(1.0, 1.0, 1.0))
    sun.setInputValue("intensity", 1.0)
    lights = mx_render.LightHandler.create()
    lights.registerLights(lib, [sun], ctx)
    lights.setLightSources([sun])
    lights.setIndirectLighting(False)

    shader = generator.generate("microfacet_render", mx.getShaderNodes(mat)[0], ctx)

    renderer = mx_glsl.GlslRenderer.create(size, size, mx_render.BaseType.FLOAT)
    renderer.initialize()
    images = mx_glsl.GLTextureHandler.create(mx_render.StbImageLoader.create())
    if folder is not None:
        images.setSearchPath(mx.FileSearchPath(str(folder)))
    renderer.setImageHandler(images)
    renderer.setLightHandler(lights)
    geometry = renderer.getGeometryHandler()
    geometry.clearGeometry()
    if not geometry.loadGeometry(mx.FilePath(str(obj)), False):
        raise RuntimeError(f"render_xml: MaterialX could not load {obj.name}")
    camera = renderer.getCamera()
    camera.setViewMatrix(mx_render.Camera.createViewMatrix(mx.Vector3(0, 0, EYE_DISTANCE), mx.Vector3(0, 0, 0),
                                                           mx.Vector3(0, 1, 0)))
    camera.setProjectionMatrix(mx_render.Camera.createOrthographicMatrix(-1, 1, -1, 1, EYE_DISTANCE - 4,
                                                                         EYE_DISTANCE + 4))
    camera.setWorldMatrix(mx.Matrix44.IDENTITY)
    renderer.createProgram(shader)
    renderer.validateInputs()
    renderer.render()
    captured = renderer.captureImage(None)
    return _to_array(captured)[::-1].copy()   # OpenGL rows: bottom first


def _to_array(image) -> np.ndarray:
    """An ``mx.Image`` as ``(h, w, 3)`` float32, rows as stored (OpenGL: the bottom row first)."""
    h, w = image.getHeight(), image.getWidth()
    out = np.empty((h, w, 3), np.float32)
    for i in range(h):
        for j in range(w):
            c = image.getTexelColor(j, i)
            out[i, j] = (c[0], c[1], c[2])
    return out


class MaterialXLayer:
    """A coat over a base as MaterialX's ``layer`` node evaluates it: the base attenuated by
    the coat's view-side transmission only, ``f = f_c + (1 - E_c(theta_o)) f_b``, where the
    library's :class:`~microfacet.layered.LayeredBRDF` has ``(1 - E_c(theta_i))
    (1 - E_c(theta_o)) f_b`` (``E_c``: the library's coat albedo table; MaterialX uses its own
    fit of the Schlick albedo, the rest of the difference). Only ``eval_cos`` and ``eval``:
    a reference for renders, not a sampler.

    Parameters
    ----------
    layered : microfacet.layered.LayeredBRDF
        The coat over its base, as the library models it.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> from microfacet.layered import LayeredBRDF
    >>> paint = LayeredBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Dielectric(1.5)), mf.Lambertian(0.5))
    >>> w = np.array([0.0, 0.0, 1.0])
    >>> bool(MaterialXLayer(paint).eval(w, w)[0] > paint.eval(w, w)[0])   # one transmission factor, not two
    True
    """

    def __init__(self, layered):
        from ..layered import LayeredBRDF
        if not isinstance(layered, LayeredBRDF):
            raise ValueError(f"layered must be a LayeredBRDF, got {type(layered).__name__}")
        self.layered = layered

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_c cos theta_i + (1 - E_c(theta_o)) f_b cos theta_i``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : None
            Not used (the protocol's signature); a new array is returned.

        Returns
        -------
        (..., 3) ndarray
            :meth:`eval` times ``cos theta_i``.
        """
        L = self.layered
        wo = np.asarray(wo, dtype=np.float64)
        return L.coat.eval_cos(wi, wo) + L.transmission(wo[..., 2]) * L.base.eval_cos(wi, wo)

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f_c + (1 - E_c(theta_o)) f_b``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : None
            Not used (the protocol's signature); a new array is returned.

        Returns
        -------
        (..., 3) ndarray
            ``f_c + (1 - E_c(theta_o)) f_b``.
        """
        L = self.layered
        wo = np.asarray(wo, dtype=np.float64)
        return L.coat.eval(wi, wo) + L.transmission(wo[..., 2]) * L.base.eval(wi, wo)


def mtlx_as_held(brdf):
    """The library BRDF that the exported pbrlib graph evaluates, as far as the library can
    write it: :func:`~microfacet.export.mtlx.pbrlib_brdf` (Beckmann as GGX, tables as
    Schlick, mean slopes dropped) with a top-level coat as :class:`MaterialXLayer`. Not
    modelled: MaterialX's isotropic Smith term on anisotropic lobes and its Schlick-fit coat
    albedo.

    Parameters
    ----------
    brdf : BRDF
        An analytic tree that :func:`~microfacet.export.mtlx.mtlx_document` exports.

    Returns
    -------
    BRDF or MaterialXLayer

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.layered import LayeredBRDF
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Dielectric(1.5))
    >>> type(mtlx_as_held(LayeredBRDF(coat, mf.Lambertian(0.5)))).__name__
    'MaterialXLayer'
    """
    from ..layered import LayeredBRDF
    from .mtlx import pbrlib_brdf
    held = pbrlib_brdf(brdf)
    return MaterialXLayer(held) if isinstance(held, LayeredBRDF) else held


def compare_mtlx(brdf, size: int = 64, light=LIGHT, material: str = "M_microfacet_exact") -> dict:
    """Export ``brdf`` (:func:`~microfacet.export.mtlx.mtlx_document`), render it with
    :func:`render_mtlx` and with the library (:func:`~microfacet.export.comparison.library_render`)
    and measure the difference.

    Parameters
    ----------
    brdf : BRDF
        An analytic tree (MicrofacetBRDF, SumBRDF with a Lambertian, LayeredBRDF).
    size : int
        Image side in pixels.
    light : (3,) array_like
        Direction toward the light.
    material : str
        The material of the exported document to render.

    Returns
    -------
    dict
        ``relL1``: ``sum |a - b| / sum |b|`` over ``r < 0.95`` of the MaterialX render
        against the library's render of ``brdf``; ``relL1_as_held``: the same against the
        library's render of :func:`mtlx_as_held` (what the graph holds: isolates the
        renderer's agreement from the export's losses); the images ``mtlx``, ``library``,
        ``as_held``; ``lost``: what the export could not carry.

    Examples
    --------
    >>> import microfacet as mf
    >>> r = compare_mtlx(mf.MicrofacetBRDF(mf.GGX.from_ellipse(0.35, 0.08, 0.6)), size=32)  # doctest: +SKIP
    >>> r["relL1"] < 0.025                                                                   # doctest: +SKIP
    True
    """
    from .mtlx import mtlx_document
    doc, lost = mtlx_document(brdf)
    image = render_mtlx(doc, size, material=material, light=light)
    ref = library_render(brdf, size, light)
    held = library_render(mtlx_as_held(brdf), size, light)
    return {"relL1": rel_l1(image, ref), "relL1_as_held": rel_l1(image, held), "mtlx": image, "library": ref,
            "as_held": held, "lost": lost}
