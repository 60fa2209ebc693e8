#!/usr/bin/env python3
"""The glint P-BRDF in three.js (``microfacet.export.glints_threejs``, ``glsl/glints.glsl``)
against the library's own glint render (``microfacet.glints.figures.render_pbrdf``).

Scenes: the plane of ``PlaneScene`` (orthographic view at 50 degrees elevation, a point light
at distance 1.2 in direction (0, 0.35, 0.9): the ``microfacet glints render`` defaults),
Gaussian pixel footprints of 0.5 px; three.js r187 in the system Chromium (WebGL2 on
SwiftShader, float render target). Maps: the procedural scratched map (256 texels,
``scratched_normal_map``) and ``glitterman_scratches.png`` of ``../shared/data/maps``
(1024 texels) when present. Per image: relative L1 error, relative error of the mean,
correlation of the pixel values, the largest per-pixel error relative to the image's
maximum, and the lobe level the shader summed (0 = the library's lobes; above: the coarse
fallback of footprints wider than ``maxWindow`` = 48 lobes per axis). Writes
``experiments/results/glints_threejs.md`` and side-by-side PNGs (library | three.js |
|difference| magnified).

Usage::

    python experiments/glints_threejs.py [--out experiments/results/glints_threejs.md]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from microfacet import fresnel as fr
from microfacet.export.glints_threejs import MAX_WINDOW, GlintsRenderer
from microfacet.glints import Microsurface
from microfacet.glints.figures import PIXEL_SIGMA, PlaneScene, render_pbrdf, scratched_normal_map
from microfacet.io import write_png, write_text

MAPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "maps"
LIGHT = tuple(1.2 * np.array([0.0, 0.35, 0.9]) / np.linalg.norm([0.0, 0.35, 0.9]))


def window(ms, scene) -> int:
    """Lobes per axis of the widest footprint window at level 0 (glints.glsl's rule)."""
    n = np.array(ms.grid[::-1], float)
    ks2 = (1.0 / (n * 2.3548200450309493)) ** 2
    sd = PIXEL_SIGMA / np.array([scene.width, scene.height])
    return int(np.max(np.floor(2 * ms.cutoff * np.sqrt(sd**2 + ks2) * n) + 1))


def side_by_side(path, ref, img, gain) -> None:
    ev = np.log2(1.0 / max(float(np.percentile(ref[..., 0], 99.5)), 1e-12))
    s = 2.0 ** ev
    sep = np.ones((ref.shape[0], 2, 3))
    write_png(path, np.concatenate([ref * s, sep, img * s, sep, np.abs(img - ref) * s * gain], 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "glints_threejs.md"))
    args = ap.parse_args()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    maps = [("procedural scratches 256²", Microsurface.from_normal_map(scratched_normal_map(256)))]
    if (MAPS / "glitterman_scratches.png").exists():
        maps.append(("glitterman_scratches 1024²", Microsurface.from_normal_map(MAPS / "glitterman_scratches.png")))
    runs = [  # (map index, width, view, exact, g2, fresnel F0, png stem, diff gain)
        (0, 256, 50.0, True, "correlated", None, "glints_threejs_procedural", 1e4),
        (0, 128, 35.0, False, "separable", [0.95, 0.64, 0.54], None, 0),
        (0, 32, 50.0, True, "correlated", None, None, 0),
        (1, 256, 50.0, True, "correlated", None, "glints_threejs_glitterman", 1e4),
        (1, 64, 50.0, True, "correlated", None, "glints_threejs_glitterman_coarse", 1.0),
    ]
    rows, pngs = [], []
    with GlintsRenderer() as r:
        for mi, width, view, exact, g2, f0, stem, gain in runs:
            if mi >= len(maps):
                continue
            name, ms = maps[mi]
            scene = PlaneScene(width=width, view_deg=view, light=LIGHT)
            fres = None if f0 is None else fr.Schlick(f0)
            render_pbrdf(ms, PlaneScene(width=8, view_deg=view, light=LIGHT), exact, fres, g2)   # compile
            t0 = time.perf_counter()
            ref = render_pbrdf(ms, scene, exact=exact, fresnel=fres, g2=g2)
            t_lib = time.perf_counter() - t0
            r.render_scene(ms, PlaneScene(width=8, view_deg=view, light=LIGHT), f0=f0, exact=exact, g2=g2)
            t0 = time.perf_counter()
            img = r.render_scene(ms, scene, f0=f0, exact=exact, g2=g2)
            t_three = time.perf_counter() - t0
            assert not r.errors, r.errors
            e = float(np.abs(img - ref).sum() / np.abs(ref).sum())
            dm = float(img.mean() / ref.mean() - 1)
            c = float(np.corrcoef(img.ravel(), ref.ravel())[0, 1])
            mx = float(np.abs(img - ref).max() / np.abs(ref).max())
            w = window(ms, scene)
            level = 0
            while w > MAX_WINDOW:                      # the shader's level choice, per axis
                level += 1
                w = window(_Coarse(ms, level), scene)
            mode = ("exact" if exact else "approx. (Sec. 4.2.2)") + f", {g2}" + ("" if f0 is None else ", Schlick")
            rows.append(f"| {name} | {scene.width}×{scene.height} | {mode} | {level} | {e:.2e} | {dm:+.2e} | "
                        f"{1 - c:.1e} | {mx:.1e} | {t_three:.2f} s | {t_lib:.2f} s |")
            print(rows[-1], flush=True)
            if stem:
                side_by_side(out.parent / f"{stem}.png", ref, img, gain)
                pngs.append(f"![{name}, {scene.width} px: library | three.js | |difference| × {gain:g}]({stem}.png)")
        revision = r.revision
    text = f"""# Glints in three.js against the library

Generated by `experiments/glints_threejs.py` (three.js r{revision}, system Chromium, WebGL2 on
SwiftShader; the library's `render_pbrdf` in float64). Plane of `PlaneScene`, point light at
distance 1.2 toward (0, 0.35, 0.9), Gaussian pixel footprints of {PIXEL_SIGMA} px, ideal mirror
facets unless "Schlick" (F0 = 0.95, 0.64, 0.54). "Level": the lobe MIP level the shader sums
(0: the library's lobes; above: footprints wider than {MAX_WINDOW} lobes per axis, summed over
prefiltered lobes, an approximation). Max err: the largest per-pixel |difference| over the
image's maximum. Times: one image each, the three.js one including the page's upload of the lobes.

| map | image | mode | level | rel. L1 | rel. mean | 1 − correlation | max err | three.js | library |
|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(rows) + """

At level 0 the shader's sums are the library's (same lobes, window and weights, texelFetch: no
texture filtering), so the difference is float32 rounding. At a coarser level the prefiltered
lobes keep the image's mean and coarse pattern but not each glint.

""" + "\n\n".join(pngs) + "\n"
    write_text(out, text)
    print(f"wrote {out}")


class _Coarse:
    """The lobe grid of MIP level ``level`` of ``ms`` (for :func:`window`)."""

    def __init__(self, ms, level):
        self.grid, self.cutoff = ms.mip[level].shape[:2], ms.cutoff


if __name__ == "__main__":
    main()
