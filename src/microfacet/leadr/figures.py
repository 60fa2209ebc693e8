"""Naive MIP mapping vs. LEADR downsampling at decreasing resolutions (thesis Fig. 5.3).

A displaced square patch (a LEADR pyramid merged with a base material, Ch. 5) is
rendered at the resolution of each MIP level ``k`` (one pixel per level-``k`` texel, a
pixel covering ``2^k x 2^k`` level-0 texels) under a point light at a finite distance
and under a lat-long environment, seen by a camera at a finite distance (so that view
and light directions vary over the patch). Three images per level:

* **reference** — supersampled: every level-0 texel (a base lobe sheared by the texel's
  slope) shaded with its own directions, averaged over the pixel's texels weighted by
  their projected area toward the viewer ``A_t(o) = c_o (1 + Lambda(o))`` (the area of
  the displaced surface the pixel sees, supplemental Eq. 6-7);
* **naive MIP** — the texels' unit normals averaged and renormalized, shaded once with
  the base lobe (:func:`~microfacet.leadr.downsample.naive_pyramid`);
* **LEADR** — the level's moments (displacement + base, moment addition) shaded once
  (:mod:`~microfacet.leadr.shading`).

Shading accounts for masking, not self-shadowing (the supplemental's choice when shadows
of the displacement are not rendered): point light by the analytic formula (Sec. 3.3),
environment by the 5 x 5 filtered sample grid (Sec. 3.5). Errors are relative RMS over
the image against the reference of the same resolution.

Examples
--------
>>> METHODS
('reference', 'naive', 'leadr')
"""
from __future__ import annotations

from dataclasses import dataclass
from html import escape
from pathlib import Path

import numpy as np

from .. import fresnel as fr
from ..geometry import normalize
from ..render.lights import procedural_sky
from . import shading
from .downsample import base_lobe, box_average, downsample_operator, naive_pyramid

__all__ = ["PatchScene", "default_heightfield", "render_level", "relative_rms",
           "compare_levels", "leadr_section", "METHODS"]

METHODS = ("reference", "naive", "leadr")
#: Frame of the patch in the world of :mod:`microfacet.render.lights` (y up): the patch
#: lies on the ground, local x = world x, local y = world -z, local z = world y.
PATCH_FRAME = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]))


@dataclass(frozen=True)
class PatchScene:
    """Camera and lights of the patch ``[0, 1]^2 x {0}`` (local frame, z up; texture
    ``u`` along x, ``v`` down the rows, so ``y = 1 - v``).

    Parameters
    ----------
    camera : (float, float, float), optional
        Camera position in the patch's local frame.
    light : (float, float, float), optional
        Point light position in the patch's local frame.
    intensity : float, optional
        The point light's intensity ``I`` (irradiance ``I / r^2``).
    fresnel : Fresnel, optional
        The surface's Fresnel term (default: silver).
    env_size : (int, int), optional
        ``(height, width)`` of the procedural sky environment map.
    grid : int, optional
        Samples per axis of the environment-lighting grid (Sec. 3.4).
    lod_offset : float, optional
        Bias added to the environment's MIP level; ``None`` (default): the supplemental's
        banding-free bias.

    Examples
    --------
    >>> import numpy as np
    >>> scene = PatchScene()
    >>> wi, wo, irradiance = scene.directions(np.array([[0.5, 0.5]]))
    >>> wi.round(3), wo.round(3)
    (array([[ 0.   , -0.774,  0.633]]), array([[-0.041,  0.664,  0.747]]))
    """

    camera: tuple[float, float, float] = (0.5, -0.6, 0.9)
    light: tuple[float, float, float] = (0.45, 1.3, 0.9)
    intensity: float = 2.5
    fresnel: fr.Fresnel = fr.Conductor.metal("Ag")
    env_size: tuple[int, int] = (64, 128)
    grid: int = 5           # samples per axis of the environment grid (Sec. 3.4)
    lod_offset: float | None = None     # None: the supplemental's banding-free bias

    def directions(self, uv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(wo, wi, E)`` at texture coordinates ``uv (..., 2)``: unit directions toward
        the camera and the light, and the light's irradiance ``I / r^2`` at the point.

        Parameters
        ----------
        uv : array-like, shape (..., 2)
            Texture coordinates on the patch.

        Returns
        -------
        wo : numpy.ndarray, shape (..., 3)
            Unit direction toward the camera.
        wi : numpy.ndarray, shape (..., 3)
            Unit direction toward the light.
        E : numpy.ndarray, shape (...)
            The point light's irradiance ``intensity / r^2``.
        """
        uv = np.asarray(uv, dtype=np.float64)
        p = np.stack([uv[..., 0], 1.0 - uv[..., 1], np.zeros(uv.shape[:-1])], axis=-1)
        to_light = np.asarray(self.light) - p
        r2 = np.sum(to_light * to_light, axis=-1)
        return normalize(np.asarray(self.camera) - p), normalize(to_light), self.intensity / r2

    def environment(self) -> shading.MipEnvironment:
        """The scene's environment light: :func:`microfacet.render.lights.procedural_sky` of ``env_size``, MIP-mapped.

        Returns
        -------
        shading.MipEnvironment
            The environment, for :func:`render_level` with ``kind="env"``.
        """
        return shading.MipEnvironment(procedural_sky(*self.env_size))


def default_heightfield(size: int = 256, seed: int = 3) -> np.ndarray:
    """A tileable displacement: smooth bumps (correlation 48 texels, ``alpha = 0.25``) plus
    fine anisotropic, correlated grooves (correlation 3 texels, ``alpha = (0.45, 0.15)``,
    ``rho = 0.5``), Gaussian random fields (:func:`microfacet.leadr.gaussian_heightfield`).

    Parameters
    ----------
    size : int, optional
        Side of the square map in texels (default 256).
    seed : int, optional
        Seed of the random fields (default 3).

    Returns
    -------
    numpy.ndarray, shape (size, size)
        Heights (float64).

    Examples
    --------
    >>> default_heightfield(size=16).shape
    (16, 16)
    """
    from .heightfield import gaussian_heightfield
    coarse = gaussian_heightfield((size, size), 0.25, correlation=48.0, seed=seed)
    fine = gaussian_heightfield((size, size), 0.45, 0.15, 0.5, correlation=3.0, seed=seed + 1)
    return coarse + fine


def _pixel_uv(n: int) -> np.ndarray:
    c = (np.arange(n) + 0.5) / n
    return np.stack(np.meshgrid(c, c, indexing="xy"), axis=-1)      # (n, n, 2): [row, col]


def _shade(kind: str, E, uv, scene: PatchScene, env) -> np.ndarray:
    wo, wi, irr = scene.directions(uv)
    if kind == "point":
        return shading.point_light(E, wi, wo, irr[..., None], scene.fresnel, shadowing=False)
    s, t, n = (np.broadcast_to(v, wo.shape) for v in PATCH_FRAME)
    return shading.env_specular(E, wo, env, (s, t, n), n=scene.grid, fresnel=scene.fresnel,
                                lod_offset=scene.lod_offset)


def render_level(method: str, level: int, pyramid0, naive, leadr, scene: PatchScene,
                 kind: str = "point", env=None) -> np.ndarray:
    """Image ``(n_k, n_k, 3)`` of the patch at MIP ``level`` by ``method`` (module
    docstring). ``pyramid0`` is the merged level 0, ``naive`` and ``leadr`` the naive and
    merged pyramids; ``kind`` is ``"point"`` or ``"env"``.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`: ``"reference"``, ``"naive"`` or ``"leadr"``.
    level : int
        MIP level rendered (``n_k = n_0 / 2^level`` pixels per side).
    pyramid0 : ndarray, shape (n_0, n_0, 5)
        The merged level-0 moments (used by ``"reference"``).
    naive, leadr : list of ndarray
        The naive and merged (LEADR) moment pyramids.
    scene : PatchScene
        Camera and lights.
    kind : str, optional
        ``"point"`` (point light, default) or ``"env"`` (environment).
    env : shading.MipEnvironment, optional
        The environment for ``kind="env"`` (:meth:`PatchScene.environment`).

    Returns
    -------
    numpy.ndarray, shape (n_k, n_k, 3)
        Linear RGB image.

    Examples
    --------
    >>> from microfacet.leadr import bake, naive_pyramid, downsample_operator
    >>> height = default_heightfield(size=16)
    >>> leadr = downsample_operator(bake(height), 0.1)
    >>> naive = naive_pyramid(leadr[0], base=0.1)
    >>> render_level("leadr", 2, leadr[0], naive, leadr, PatchScene()).shape      # 16 / 2^2 pixels
    (4, 4, 3)
    """
    if method == "reference":
        E0 = np.asarray(pyramid0, dtype=np.float64)
        uv = _pixel_uv(E0.shape[0])
        wo = scene.directions(uv)[0]
        area = shading.projected_area(E0, wo)
        return box_average(_shade(kind, E0, uv, scene, env), 1 << level, area)
    E = np.asarray((naive if method == "naive" else leadr)[level], dtype=np.float64)
    return _shade(kind, E, _pixel_uv(E.shape[0]), scene, env)


def relative_rms(image, reference) -> float:
    """``sqrt(mean((I - R)^2) / mean(R^2))`` over all pixels and channels.

    Parameters
    ----------
    image : array-like
        The image to compare.
    reference : array-like
        The reference, of the same shape.

    Returns
    -------
    float
        The relative RMS error (0: identical).

    Examples
    --------
    >>> import numpy as np
    >>> round(relative_rms(np.full((2, 2, 3), 1.1), np.ones((2, 2, 3))), 6)
    0.1
    """
    a, b = np.asarray(image, dtype=np.float64), np.asarray(reference, dtype=np.float64)
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b * b)))


def compare_levels(height, base=0.1, scale: float = 1.0, levels=(1, 2, 3, 4, 5),
                   scene: PatchScene | None = None, kinds=("point", "env")):
    """Render every method at every level; returns ``{(kind, level): {method: image}}``
    and ``{(kind, level): {method: relative RMS error}}`` (naive and LEADR against the
    reference). ``height`` is a square power-of-two height map, ``base`` the base
    material (:func:`~microfacet.leadr.downsample.base_lobe`).

    Parameters
    ----------
    height : ndarray, (N, N)
        Heights, ``N`` a power of two.
    base : see :func:`~microfacet.leadr.downsample.base_lobe`
        The base material's lobe.
    scale : float
        Height scale (:func:`microfacet.leadr.bake`).
    levels : sequence of int
        MIP levels rendered.
    scene : PatchScene, optional
        Camera and lights (default ``PatchScene()``).
    kinds : sequence of {"point", "env"}
        Lightings rendered.

    Returns
    -------
    (dict, dict)
        Images ``{(kind, level): {method: (n, n, 3)}}`` and relative RMS errors
        ``{(kind, level): {"naive": e, "leadr": e}}`` against the reference.

    Examples
    --------
    >>> images, errors = compare_levels(default_heightfield(size=16), levels=(2,), kinds=("point",))
    >>> sorted(images[("point", 2)]), images[("point", 2)]["leadr"].shape
    (['leadr', 'naive', 'reference'], (4, 4, 3))
    >>> errors[("point", 2)]["leadr"] < errors[("point", 2)]["naive"]
    True
    """
    from .maps import bake
    scene = PatchScene() if scene is None else scene
    b = base_lobe(base)
    leadr = downsample_operator(bake(height, scale), b)
    naive = naive_pyramid(bake(height, scale)[0], b)
    env = scene.environment() if "env" in kinds else None
    images, errors = {}, {}
    for kind in kinds:
        for level in levels:
            imgs = {m: render_level(m, level, leadr[0], naive, leadr, scene, kind, env) for m in METHODS}
            images[kind, level] = imgs
            errors[kind, level] = {m: relative_rms(imgs[m], imgs["reference"]) for m in ("naive", "leadr")}
    return images, errors


def _upscale(image: np.ndarray, size: int) -> np.ndarray:
    f = max(1, round(size / image.shape[0]))
    return np.repeat(np.repeat(image, f, axis=0), f, axis=1)


def _verdict(errors, levels, size) -> str:
    """What the error table shows: where LEADR is closer to the reference than naive MIP mapping."""
    cases = [(kind, lv) for kind in ("point", "env") for lv in levels]
    worse = [f"{kind} light at {size >> lv}²: LEADR {100 * errors[kind, lv]['leadr']:.1f}% vs naive "
             f"{100 * errors[kind, lv]['naive']:.1f}%" for kind, lv in cases
             if errors[kind, lv]["leadr"] >= errors[kind, lv]["naive"]]
    text = f"LEADR has the lower error in {len(cases) - len(worse)} of {len(cases)} cases"
    return text + (f"; not in {'; '.join(worse)}." if worse else ".")


def leadr_section(out, size: int = 256, levels=(1, 2, 3, 4, 5), base=0.1, seed: int = 3,
                  display: int = 256, progress=None) -> str:
    """Render the Fig. 5.3 comparison under ``out/leadr/`` (EXR data and PNG previews,
    every image shown upscaled to ``display`` pixels, nearest neighbour) and return the
    HTML section. ``size`` is the side of the height map (a power of two), ``levels``
    the MIP levels shown, ``base`` the base material (``alpha``, a Beckmann lobe, a
    BRDF or a fit: :func:`~microfacet.leadr.downsample.base_lobe`).

    Parameters
    ----------
    out : str or PathLike
        Folder; the files go under ``out/leadr/``.
    size : int
        Side of the height map (:func:`default_heightfield`), a power of two.
    levels : sequence of int
        MIP levels shown.
    base : see :func:`~microfacet.leadr.downsample.base_lobe`
        The base material.
    seed : int
        Seed of the height map.
    display : int
        Side of the shown images, pixels.
    progress : callable, optional
        Called as ``progress(1)`` after each image is written (a progress bar's update).

    Returns
    -------
    str
        The HTML section.

    Examples
    --------
    >>> html = leadr_section("out", size=16, levels=(1, 2), display=32)   # EXR and PNG files, ~2 s  # doctest: +SKIP
    """
    from ..io import html_grid, write_exr, write_png
    out = Path(out)
    folder = out / "leadr"
    folder.mkdir(parents=True, exist_ok=True)
    height = default_heightfield(size, seed)
    images, errors = compare_levels(height, base, levels=levels)
    exposure = {}
    for kind in ("point", "env"):
        ref = images[kind, levels[0]]["reference"]
        top = float(np.percentile(ref, 99.0))
        exposure[kind] = float(np.log2(1.0 / top)) if top > 0 else 0.0
    blocks = []
    labels = {"reference": "supersampled reference", "naive": "naive MIP (averaged normals)",
              "leadr": "LEADR (moments + base)"}
    titles = {"point": "point light (analytic, Sec. 3.3)", "env": "environment (5 x 5 grid, Sec. 3.5)"}
    for kind in ("point", "env"):
        rows = []
        for method in METHODS:
            cells = []
            for level in levels:
                stem = f"{kind}_{method}_level{level}"
                img = images[kind, level][method]
                write_exr(folder / f"{stem}.exr", img.astype(np.float32))
                write_png(folder / f"{stem}.png", _upscale(img, display), exposure[kind])
                n = img.shape[0]
                cap = f"{n}x{n}" + ("" if method == "reference"
                                    else f", error {100 * errors[kind, level][method]:.1f}%")
                cells.append((f"leadr/{stem}.png", cap))
                if progress:
                    progress(1)
            rows.append((labels[method], cells))
        blocks.append(f"<h3>{escape(titles[kind])}</h3>" + html_grid(rows))
    head = "".join(f"<th>{(size >> lv)}²</th>" for lv in levels)
    table = ["<table class=\"grid\"><tr><th>lighting</th><th>method</th>" + head + "</tr>"]
    for kind in ("point", "env"):
        for method in ("naive", "leadr"):
            table.append(f"<tr><td>{escape(kind)}</td><td>{escape(labels[method])}</td>"
                         + "".join(f"<td>{100 * errors[kind, lv][method]:.1f}%</td>" for lv in levels)
                         + "</tr>")
    table.append("</table>")
    intro = (f"Thesis Fig. 5.3: a {size}x{size} displacement map (Gaussian bumps plus fine anisotropic "
             "grooves) on a silver base material (Beckmann α = "
             f"{np.sqrt(2 * base_lobe(base)[2]):.3g}) rendered at the resolution of MIP levels "
             f"{', '.join(str(lv) for lv in levels)}. Naive MIP mapping averages the normals and loses "
             "the roughness they should become (highlights too sharp and too bright); LEADR adds the "
             "base material's moments to every MIP level (Ch. 5). Errors: relative RMS against the "
             "supersampled reference of the same resolution. Masking only (no self-shadowing) in all "
             f"three. {_verdict(errors, levels, size)}")
    return ('<section id="leadr"><h2>LEADR downsampling (thesis Ch. 5, Fig. 5.3)</h2>'
            f"<p>{escape(intro)}</p>" + "".join(table) + "".join(blocks) + "</section>")
