"""The demo's Mitsuba 3 section: the plugins of :mod:`microfacet.mitsuba` in real scenes.

Three scenes, each render timed (wall clock of ``mi.render``, kernel compilation included
for the first render of each plugin in ``llvm_ad_rgb``):

1. the best fits of the demo's fitting section (:func:`microfacet.demo.fit_materials`:
   corpus materials with the shared data, else built-in ones), each fit file's ``best`` fit
   rendered by ``mf_fitted`` (``use="best"``) under the demo's directional light
   (orthographic camera) beside the library's own render of the same fit and of the data,
   with their relative RMS difference, and under the environment;
2. a LEADR-mapped plane receding to the horizon (``mf.leadr.bake`` of
   :func:`microfacet.leadr.figures.default_heightfield`): naive MIP mapping (each level a
   single facet of the averaged normal, :func:`microfacet.leadr.naive_pyramid`) vs
   ``mf_leadr``, both filtered over each pixel's footprint (camera ray differentials) vs a
   supersampled reference (the LEADR pyramid's finest level at many samples per pixel);
3. a glint plane (``mf.glints.Microsurface.from_normal_map`` of
   :func:`microfacet.glints.figures.scratched_normal_map`) under a small point light,
   rendered by ``mf_glints``.

The variant is ``llvm_ad_rgb`` where Dr.Jit finds a working libLLVM (probed in a
subprocess: a too-old libLLVM aborts the process), else ``scalar_rgb``.
"""
from __future__ import annotations

import functools
import math
import os
import shutil
import subprocess
import sys
import time
from html import escape
from pathlib import Path

import numpy as np

from .._colour import LUMINANCE
from ..io import html_grid, write_exr, write_png

__all__ = ["demo_section", "choose_variant", "relative_rms", "shared_rgl_files", "highlight_mask", "MATERIALS", "LIBRARY_SUPERSAMPLE"]

_LLVM_PROBE = ("import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); import drjit as dr; "
               "x = dr.arange(mi.Float, 4); dr.eval(x * x); print(dr.sum(x))")
#: Materials rendered, at most (the first ones of the fitting section's).
MATERIALS = 4
#: Points per pixel side of the library's renders beside Mitsuba's (box-filtered).
LIBRARY_SUPERSAMPLE = 4


def choose_variant() -> str:
    """The Mitsuba variant of the demo: ``"llvm_ad_rgb"`` if it runs here, else ``"scalar_rgb"``.

    The LLVM variant is probed in a subprocess (a too-old libLLVM aborts the process).

    Returns
    -------
    str

    Raises
    ------
    ImportError
        Without Mitsuba.

    Examples
    --------
    >>> from microfacet.mitsuba.demo import choose_variant
    >>> choose_variant() in ("llvm_ad_rgb", "scalar_rgb")
    True
    """
    import mitsuba as mi
    if "llvm_ad_rgb" in mi.variants():
        probe = subprocess.run([sys.executable, "-c", _LLVM_PROBE], capture_output=True, text=True, timeout=120)
        if probe.returncode == 0:
            return "llvm_ad_rgb"
    return "scalar_rgb"


def shared_rgl_files() -> list[Path]:
    """The RGL ``.bsdf`` files of the shared data, sorted; empty where there are none.

    The data folder is ``$MICROFACET_DATA``, else ``../shared/data`` beside the repository.

    Returns
    -------
    list of pathlib.Path

    Examples
    --------
    >>> import os
    >>> from microfacet.mitsuba.demo import shared_rgl_files
    >>> os.makedirs("data/rgl", exist_ok=True)
    >>> open("data/rgl/gold.bsdf", "wb").close()
    >>> previous = os.environ.get("MICROFACET_DATA")
    >>> os.environ["MICROFACET_DATA"] = "data"
    >>> [p.name for p in shared_rgl_files()]
    ['gold.bsdf']
    >>> if previous is None:
    ...     del os.environ["MICROFACET_DATA"]
    ... else:
    ...     os.environ["MICROFACET_DATA"] = previous
    """
    root = os.environ.get("MICROFACET_DATA") or Path(__file__).resolve().parents[3].parent / "shared" / "data"
    return sorted((Path(root) / "rgl").glob("*.bsdf"))


def relative_rms(image, reference) -> float:
    """``sqrt(sum((I - R)^2) / sum(R^2))`` over pixels and channels (float64).

    Parameters
    ----------
    image, reference : array_like
        Images of the same shape.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.mitsuba.demo import relative_rms
    >>> reference = np.ones((4, 4, 3))
    >>> relative_rms(1.1 * reference, reference), relative_rms(reference, reference)
    (0.10000000000000009, 0.0)
    """
    a, b = np.asarray(image, dtype=np.float64), np.asarray(reference, dtype=np.float64)
    return float(np.sqrt(np.sum((a - b) ** 2) / max(np.sum(b * b), 1e-300)))


def _render(mi, scene: dict, spp: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """Load and render ``scene``; the image (float64) and the seconds of ``mi.render``."""
    loaded = mi.load_dict(scene)
    t = time.perf_counter()
    image = np.array(mi.render(loaded, spp=spp, seed=seed), dtype=np.float64)
    return image, time.perf_counter() - t


def _save(folder: Path, stem: str, image: np.ndarray, exposure: float = 0.0) -> str:
    write_exr(folder / f"{stem}.exr", image)
    write_png(folder / f"{stem}.png", image, exposure)
    return f"mitsuba/{stem}.png"


def _camera(mi, origin, target, width: int, height: int, fov: float) -> dict:
    return {"type": "perspective", "fov": fov, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=target, up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent"}}


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(c) for c in np.ravel(v)]}


def _metal(name: str) -> dict:
    """``eta``, ``k`` of a conductor of :attr:`microfacet.fresnel.Conductor.METALS`."""
    from ..fresnel import Conductor
    eta, k = Conductor.METALS[name]
    return {"eta": _rgb(eta), "k": _rgb(k)}


@functools.lru_cache(maxsize=1)
def _sphere(size: int):
    """:class:`microfacet.render.Sphere` of ``size`` pixels, made once for every library render."""
    from ..render import Sphere
    return Sphere(size)


def _library_render(brdf, size: int, light) -> np.ndarray:
    """The library's own render of ``brdf``: an orthographic unit sphere under the
    directional ``light`` (:func:`microfacet.render.shade_directional`), shaded at
    :data:`LIBRARY_SUPERSAMPLE`² points per pixel and box-filtered, as Mitsuba's box
    filter integrates each pixel; black background."""
    from ..render import shade_directional
    k = LIBRARY_SUPERSAMPLE
    sphere = _sphere(size * k)
    image = sphere.image(shade_directional(brdf, sphere.wo, sphere.to_local(light.w), light.rgb))
    return image.reshape(size, k, size, k, 3).mean(axis=(1, 3))


def highlight_mask(image, fraction: float = 0.01) -> np.ndarray:
    """The pixels of ``image`` among its brightest ``fraction`` (luminance) of lit pixels.

    Parameters
    ----------
    image : array_like
        ``(H, W, 3)`` linear RGB.
    fraction : float, optional
        The share of the lit pixels kept.

    Returns
    -------
    ndarray of bool
        ``(H, W)``.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.mitsuba.demo import highlight_mask
    >>> image = np.zeros((4, 4, 3))
    >>> image[:2] = 1.0
    >>> image[0, 0] = 5.0                       # 8 lit pixels, one highlight
    >>> mask = highlight_mask(image, fraction=0.1)
    >>> int(mask.sum()), bool(mask[0, 0])
    (1, True)
    """
    lum = np.asarray(image, dtype=np.float64) @ LUMINANCE
    lit = lum[lum > 0]
    return lum > np.quantile(lit, 1.0 - fraction) if lit.size else np.zeros(lum.shape, dtype=bool)


def _orthographic(mi, size: int) -> dict:
    """An orthographic camera on +z looking at the origin, its image the square [-1, 1]²
    (the library's :class:`microfacet.render.Sphere` view)."""
    return {"type": "orthographic",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent"}}


def _fits(folder: Path, fits) -> list[tuple[object, Path]]:
    """``[(FitExample, fit file in folder)]``: ``fits`` copied into ``folder`` (the files
    the section renders travel with it), or, with ``fits=None``, the first
    :data:`MATERIALS` materials of :func:`microfacet.demo.fit_materials` fitted into it."""
    from ..demo_materials import fit_demo_material, fit_materials
    if fits is None:
        examples, _ = fit_materials()
        return [(ex, fit_demo_material(ex, folder)[1]) for ex in examples[:MATERIALS]]
    out = []
    for ex, path in list(fits)[:MATERIALS]:
        target = folder / f"{ex.key}.npz"
        shutil.copyfile(path, target)
        out.append((ex, target))
    return out


def _materials(mi, folder: Path, size: int, spp: int, tick, fits) -> str:
    """Scene 1: the best fit of each demo material rendered by ``mf_fitted`` (``use="best"``)
    under the environment, and under a directional light beside the library's own render
    of the same fit (and of the data); the relative RMS difference of the two renders."""
    from ..demo_materials import LIGHT, preview_exposure
    from ..fit import fit_names, load
    from ..render import procedural_sky
    env = write_exr(folder / "environment.exr", procedural_sky())
    w = LIGHT.w
    light = {"type": "directional", "direction": [float(-c) for c in w], "irradiance": _rgb(LIGHT.rgb)}
    rows, notes = [], []
    materials = _fits(folder, fits)
    for ex, path in materials:
        best = fit_names(path)[1]
        fit = load(path, model="best")
        bsdf = {"type": "mf_fitted", "filename": str(path), "use": "best"}
        library = _library_render(fit, size, LIGHT)
        data = _library_render(ex.material(), size, LIGHT)
        tick(1)
        direct, t_direct = _render(mi, {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                                        "sensor": _orthographic(mi, size), "light": light,
                                        "sphere": {"type": "sphere", "bsdf": bsdf}}, spp)
        tick(1)
        lit, t_lit = _render(mi, {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                                  "sensor": _camera(mi, [0, 0, 4.2], [0, 0, 0], size, size, 30),
                                  "light": {"type": "envmap", "filename": str(env)},
                                  "sphere": {"type": "sphere", "bsdf": bsdf}}, spp)
        tick(1)
        exposure = preview_exposure(data)
        diff = relative_rms(direct, library)
        keep = ~highlight_mask(library)
        rest = relative_rms(direct[keep], library[keep])
        cells = [(_save(folder, f"{ex.key}_data", data, exposure), "the data, library render (directional)"),
                 (_save(folder, f"{ex.key}_library", library, exposure),
                  f"best fit {best}, library render (directional)"),
                 (_save(folder, f"{ex.key}_direct", direct, exposure),
                  f"mf_fitted use=best, {spp} spp: {t_direct:.2f} s, rel. difference {diff:.3f} "
                  f"({rest:.3f} outside the highlight)"),
                 (_save(folder, f"{ex.key}_environment", lit),
                  f"mf_fitted use=best, environment, {spp} spp: {t_lit:.2f} s")]
        rows.append((f"{ex.label} ({best})", cells))
        notes.append((ex.label, best, diff, rest))
    tick(3 * (MATERIALS - len(materials)))
    text = (f"The best fit of each material of the fitting section (the fit microfacet fit chose by image error, "
            f"in the file it wrote) rendered by mf_fitted (use=\"best\", its default) on a sphere: under "
            f"the demo's directional light through an orthographic camera ({size}×{size} px, {spp} spp, box filter), "
            f"beside the library's own render of the same fit (microfacet.fit.load(OUT.npz, model=\"best\"), "
            f"{LIBRARY_SUPERSAMPLE}×{LIBRARY_SUPERSAMPLE} points per pixel) and of the data, the three at one "
            f"exposure; and under the demo's environment (perspective camera, path tracer). Rel. difference: "
            f"relative RMS of the Mitsuba render against the library's, over the image and outside the highlight "
            f"(the brightest 1 % of the lit pixels): what remains is how each integrates a pixel (Mitsuba by "
            f"Monte Carlo at {spp} spp, the library on a {LIBRARY_SUPERSAMPLE}×{LIBRARY_SUPERSAMPLE} grid), "
            f"which matters where the highlight and its glow vary within a pixel; both fall with more samples "
            f"and grid points.")
    listed = "".join(f"<li>{escape(label)}: best fit {escape(best)}, Mitsuba vs library rel. difference "
                     f"{diff:.3f}, {rest:.3f} outside the highlight</li>" for label, best, diff, rest in notes)
    return f"<h3>Best fits on spheres</h3><p>{escape(text)}</p>{html_grid(rows)}<ul>{listed}</ul>"


_INTEGRATORS: dict[str, type] = {}


def _footprint_integrator(mi) -> str:
    """Register (once per variant) and name ``mf_demo_direct``: direct lighting (emitter
    sampling, delta lights) plus the background, that sets ``si.duv_dx``, ``si.duv_dy`` from
    the camera ray's differentials (``compute_uv_partials``; Mitsuba 3's path tracer leaves
    them zero, so ``mf_leadr`` would fall back to its fixed ``footprint``). Mitsuba hands
    the integrator differentials scaled by ``1/sqrt(spp)``; they are scaled back, so that
    the footprint is the pixel's at any sample count. With ``footprint = false`` the
    partials stay zero: lookups of the finest level."""
    import drjit as dr
    name = "mf_demo_direct"
    if mi.variant() in _INTEGRATORS:
        return name

    class Direct(mi.SamplingIntegrator):
        def __init__(self, props):
            mi.SamplingIntegrator.__init__(self, props)
            self.footprint = props.get("footprint", True)

        def sample(self, scene, sampler, ray, medium=None, active=True):
            si = scene.ray_intersect(mi.Ray3f(ray), ray_flags=mi.RayFlags.All, coherent=True)
            if self.footprint:
                ray.scale_differential(math.sqrt(sampler.sample_count()))   # in place: ours
                si.compute_uv_partials(ray)
            hit = si.is_valid()
            scalar = isinstance(hit, bool)                   # scalar variants: one ray per call
            bsdf = si.bsdf(ray) if not scalar or hit else None
            env = scene.environment()
            ds, weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, hit)
            value = (bsdf.eval(mi.BSDFContext(), si, si.to_local(ds.d), hit) * weight
                     if bsdf is not None else mi.Color3f(0.0))
            miss = (not hit) if scalar else ~hit
            background = env.eval(si, miss) if env is not None else mi.Color3f(0.0)
            return dr.select(hit, value, background), dr.full(mi.Bool, True), []

        def aov_names(self):
            return []

        def to_string(self):
            return f"{name}[footprint={self.footprint}]"

    mi.register_integrator(name, lambda props: Direct(props))
    _INTEGRATORS[mi.variant()] = Direct
    return name


def _leadr(mi, folder: Path, size: int, spp: int, reference_spp: int, tick) -> str:
    """Scene 2: a LEADR plane receding to the horizon (``size`` pixels wide): naive MIP vs
    mf_leadr vs reference."""
    from ..leadr import bake, naive_pyramid, write_pyramid
    from ..leadr.figures import default_heightfield
    side = 256 if size >= 64 else 64
    pyramid = bake(default_heightfield(side, 3), 1.0)
    files = {"leadr": write_pyramid(folder / "leadr_pyramid.exr", pyramid),
             "naive": write_pyramid(folder / "naive_pyramid.exr", naive_pyramid(pyramid[0]))}
    T = mi.ScalarTransform4f
    width, height = size, max(8, size // 2)
    images, seconds = {}, {}
    integrator = _footprint_integrator(mi)
    for name, file, n in (("reference", files["leadr"], reference_spp), ("naive", files["naive"], spp),
                          ("leadr", files["leadr"], spp)):
        scene = {"type": "scene", "integrator": {"type": integrator, "footprint": name != "reference"},
                 "sensor": _camera(mi, [0, 0.6, 0], [0, 0.35, -4], width, height, 60),
                 "light": {"type": "directional", "direction": [0, -0.45, 1], "irradiance": 3.0},
                 "sky": {"type": "constant", "radiance": 0.05},
                 "plane": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(40),
                           "bsdf": {"type": "mf_leadr", "filename": str(file), "alpha": 0.1,
                                    **_metal("Au"),
                                    "uv_scale": 40.0}}}
        images[name], seconds[name] = _render(mi, scene, n)
        tick(1)
    exposure = -math.log2(max(float(np.quantile(images["reference"], 0.99)), 1e-6))
    cells = [(_save(folder, f"leadr_{name}", images[name], exposure),
              f"{label}, {n} spp: {seconds[name]:.2f} s"
              + ("" if name == "reference" else f", rel. error {relative_rms(images[name], images['reference']):.3f}"))
             for name, label, n in (("naive", "naive MIP (averaged normal)", spp), ("leadr", "mf_leadr", spp),
                                    ("reference", "supersampled reference", reference_spp))]
    text = (f"A {side}² height map (leadr.figures.default_heightfield: bumps plus fine anisotropic "
            "grooves) baked by mf.leadr.bake, tiled 40 times across a gold plane that recedes to the "
            f"horizon under a low sun ({width}×{height} px). Naive MIP mapping keeps one facet of the "
            "averaged normal per level (mf.leadr.naive_pyramid) and loses the grooves' roughness: "
            "the distant plane turns into a mirror; mf_leadr filters the five moments (LEADR) and "
            f"keeps the far highlight's width. Reference: the LEADR pyramid at {reference_spp} spp "
            "(Mitsuba scales ray differentials by 1/√spp, so lookups stay near the finest level and "
            "the pixel is integrated by sampling). Errors: relative RMS against the reference.")
    return f"<h3>LEADR plane to the horizon</h3><p>{escape(text)}</p>{html_grid([('gold, α = 0.1 base', cells)])}"


def _glints(mi, folder: Path, size: int, spp: int, tick) -> str:
    """Scene 3: a scratched glint plane under a small point light (mf_glints)."""
    from ..glints import Microsurface
    from ..glints.figures import scratched_normal_map
    side = 256 if size >= 64 else 32
    t = time.perf_counter()
    normals = scratched_normal_map(side, scratches=max(4, int(160 * (side / 512) ** 2)), seed=0)
    path = Microsurface.from_normal_map(normals).save(folder / "glints.npz")
    t_build = time.perf_counter() - t
    T = mi.ScalarTransform4f
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
             "sensor": _camera(mi, [0, 1.3, 1.55], [0, 0, 0], size, size, 50),
             "light": {"type": "point", "position": [0, 1.0, -1.0], "intensity": 2.0},
             "plane": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90),
                       "bsdf": {"type": "mf_glints", "filename": str(path),
                                **_metal("Ag")}}}
    image, seconds = _render(mi, scene, spp)
    tick(1)
    cell = (_save(folder, "glints", image), f"mf_glints, {spp} spp: {seconds:.2f} s")
    text = (f"A procedural scratched normal map ({side}² texels, glints.figures.scratched_normal_map) "
            f"turned into a Beckmann lobe mixture (Microsurface.from_normal_map, {t_build:.2f} s) on a "
            f"2 × 2 silver plane under a point light ({size}×{size} px); mf_glints evaluates the "
            "patch BRDF over each ray's footprint (ray differentials), so the scratches sparkle "
            "without a sample per texel.")
    return f"<h3>Glints under a small light</h3><p>{escape(text)}</p>{html_grid([('silver', [cell])])}"


#: Progress steps of :func:`demo_section` (renders).
STEPS = 3 * MATERIALS + 3 + 1   # microfacet.demo.MITSUBA_STEPS (tested equal)


#: Defaults of :func:`demo_section`: vectorized (llvm) and scalar variants (Python runs
#: per ray there: a few 10^4 rays per second).
DEFAULTS = {"llvm": {"size": 96, "leadr_width": 256, "spp": 64, "reference_spp": 1024},
            "scalar": {"size": 32, "leadr_width": 32, "spp": 4, "reference_spp": 32}}


def demo_section(out, size: int | None = None, spp: int | None = None, reference_spp: int | None = None,
                 variant: str | None = None, progress=None, leadr_width: int | None = None,
                 fits=None) -> str:
    """Render the Mitsuba scenes under ``out/mitsuba/`` and return the HTML section.

    Parameters
    ----------
    out : str or os.PathLike
        The demo's output folder.
    size : int, optional
        Side in pixels of the sphere and glint images (>= 8).
    spp : int, optional
        Samples per pixel.
    reference_spp : int, optional
        Samples per pixel of the references.
    variant : str, optional
        A Mitsuba RGB variant, default :func:`choose_variant`.
    progress : callable, optional
        ``progress(n)``, called as renders complete.
    leadr_width : int, optional
        Width of the LEADR plane (``x width/2``; default ``size`` where ``size`` is given).
    fits : list or callable, optional
        ``[(FitExample, fit file)]`` of :mod:`microfacet.demo`'s fitting section, whose best
        fits scene 1 renders (the first :data:`MATERIALS`, each beside the library's own render
        supersampled :data:`LIBRARY_SUPERSAMPLE` times per pixel side), or a function
        returning them, called after scenes 2 and 3 are rendered (the demo's fits are still
        running then; its wait is not in the section's time); default: the demo's materials
        fitted here (:func:`microfacet.demo.fit_demo_material`).

    Returns
    -------
    str
        The HTML section.

    Raises
    ------
    ImportError
        Without Mitsuba.
    ValueError
        For a size or sample count that is not an integer of the range.

    Notes
    -----
    ``None`` takes :data:`DEFAULTS` of the variant.

    Examples
    --------
    The LEADR and glint scenes at 8 pixels, one sample per pixel, no fit:

    >>> from microfacet.mitsuba.demo import LIBRARY_SUPERSAMPLE, MATERIALS, demo_section
    >>> MATERIALS, LIBRARY_SUPERSAMPLE
    (4, 4)
    >>> html = demo_section("out", size=8, spp=1, reference_spp=1, variant="scalar_rgb", fits=[])
    >>> html.startswith('<section id="mitsuba">')
    True
    >>> import os
    >>> "glints.png" in os.listdir("out/mitsuba")
    True
    """
    variant = choose_variant() if variant is None else variant
    defaults = dict(DEFAULTS["scalar" if variant.startswith("scalar") else "llvm"])
    if size is not None:
        defaults["leadr_width"] = size
    given = {"size": size, "leadr_width": leadr_width, "spp": spp, "reference_spp": reference_spp}
    n = {name: defaults[name] if v is None else v for name, v in given.items()}
    for name, v in n.items():
        lo = 8 if name in ("size", "leadr_width") else 1
        if isinstance(v, bool) or int(v) != v or v < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    size, leadr_width, spp, reference_spp = (int(n[k]) for k in ("size", "leadr_width", "spp", "reference_spp"))
    import mitsuba as mi

    from . import register
    mi.set_variant(variant)
    register()
    tick = progress if progress is not None else (lambda n=1: None)
    folder = Path(out) / "mitsuba"
    folder.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    leadr = _leadr(mi, folder, leadr_width, spp, reference_spp, tick)
    glints = _glints(mi, folder, size, spp, tick)
    total = time.perf_counter() - t
    if callable(fits):
        fits = fits()
    t = time.perf_counter()
    parts = [_materials(mi, folder, size, spp, tick, fits), leadr, glints]
    total += time.perf_counter() - t
    intro = (f"The plugins of microfacet.mitsuba (import microfacet.mitsuba as mfm; mfm.register()) in "
             f"Mitsuba {mi.__version__}, variant {variant}. Times: wall clock of mi.render (the first "
             f"render of each plugin includes kernel compilation); the whole section took {total:.1f} s.")
    return ('<section id="mitsuba"><h2>Rendering in Mitsuba 3</h2>'
            f"<p>{escape(intro)}</p>" + "".join(parts) + "</section>")
