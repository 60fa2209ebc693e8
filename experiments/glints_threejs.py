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

Sphere (``SphereScene``: ``THREE.SphereGeometry`` of radius 1, perspective camera at distance
4, field of view 30 degrees, ``uvScale`` (2, 1), a point light at (2, 2.5, 3)): the shader's
image against the library's ``eval_cos_footprints`` at the per-pixel inputs the same material
reads back in its debug modes (``pbrdf_at_inputs``); the shader's frame against the analytic
frame of the sphere at the same points (``sphere_frame``); and the inputs and image against
those of the exact sphere (``sphere_inputs``: ray-traced hits, analytic frame and footprints),
which measures the tessellation and the one-pixel ``dFdx``/``dFdy`` footprints, not the shader.

Usage::

    python experiments/glints_threejs.py [--out experiments/results/glints_threejs.md]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from microfacet import fresnel as fr
from microfacet.export.glints_threejs import (MAX_WINDOW, GlintsRenderer, SphereScene, pbrdf_at_inputs,
                                             sphere_frame, sphere_inputs)
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
        sphere_rows, sphere_pngs = sphere_runs(r, maps, out.parent)
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

""" + "\n\n".join(pngs) + "\n" + sphere_text(sphere_rows, sphere_pngs)
    write_text(out, text)
    print(f"wrote {out}")


def _angles(a, b) -> np.ndarray:
    c = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _stats(x) -> str:
    return f"{np.median(x):.2g} / {np.percentile(x, 99):.2g} / {np.max(x):.2g}"


def sphere_levels(ms, inputs) -> np.ndarray:
    """Per covered pixel, the lobe MIP level the shader sums (glints.glsl's ``mf_glint_level``:
    the first level whose footprint window has at most ``MAX_WINDOW`` lobes per axis)."""
    uv = inputs.uv[inputs.covered]
    cov = inputs.covariance(PIXEL_SIGMA)[inputs.covered]
    var = np.stack([cov[:, 0, 0], cov[:, 1, 1]], -1)
    level = np.full(len(uv), -1)
    for k, mip in enumerate(ms.mip):
        n = np.array(mip.shape[:2][::-1], float)
        r = ms.cutoff * np.sqrt(var + (1.0 / (n * 2.3548200450309493)) ** 2)
        ln = np.floor((uv + r) * n - 0.5) - np.ceil((uv - r) * n - 0.5) + 1
        fits = (level < 0) & (np.all(ln <= MAX_WINDOW, -1) | (k == len(ms.mip) - 1))
        level[fits] = k
    return level


def sphere_runs(r, maps, folder):
    """Rows of the sphere table (module docstring) and its PNGs."""
    runs = [  # (map index, width, segments, tangents, png stem)
        (0, 256, (64, 32), True, "glints_threejs_sphere"),
        (0, 256, (64, 32), False, None),
        (0, 256, (256, 128), True, None),
        (1, 256, (64, 32), True, "glints_threejs_sphere_glitterman"),
    ]
    rows, pngs = [], []
    for mi, width, seg, tangents, stem in runs:
        if mi >= len(maps):
            continue
        name, ms = maps[mi]
        scene = SphereScene(width=width, segments=seg, tangents=tangents)
        t0 = time.perf_counter()
        img, inp = r.render_sphere(ms, scene)
        t_three = time.perf_counter() - t0
        assert not r.errors, r.errors
        ref = pbrdf_at_inputs(ms, inp)
        m = inp.covered
        e = float(np.abs(img - ref).sum() / np.abs(ref).sum())
        mx = float(np.abs(img - ref).max() / np.abs(ref).max())
        c = float(np.corrcoef(img.ravel(), ref.ravel())[0, 1])
        a = sphere_frame(inp.position[m])
        t_err = _angles(inp.tangent[m], a["tangent"])
        ex = sphere_inputs(scene)
        both = m & ex.covered
        n_err = _angles(inp.normal[both], ex.normal[both])
        texels = np.array(ms.grid[::-1], float)                     # lobes per unit of (scaled) uv
        du = inp.uv[both] - ex.uv[both]
        du[:, 0] = (du[:, 0] + 0.5 * scene.uv_scale[0]) % scene.uv_scale[0] - 0.5 * scene.uv_scale[0]
        uv_err = np.linalg.norm(du * texels, axis=-1)
        J, Je = (np.stack([x.duv_dx[both], x.duv_dy[both]], -1) for x in (inp, ex))
        j_err = np.linalg.norm(J - Je, axis=(-2, -1)) / np.linalg.norm(Je, axis=(-2, -1))
        exact = pbrdf_at_inputs(ms, ex)
        e_ex = float(np.abs(img - exact).sum() / np.abs(exact).sum())
        dm_ex = float(img.sum() / exact.sum() - 1)
        level = sphere_levels(ms, inp)
        fine = np.zeros_like(m)
        fine[m] = level == 0
        e0 = float(np.abs(img - ref)[fine].sum() / np.abs(ref[fine]).sum())
        rows.append(f"| {name} | {width}² ({int(m.sum())} px) | {seg[0]}×{seg[1]} | "
                    f"{'attribute' if tangents else 'derivatives'} | {100 * (level > 0).mean():.1f} % | {e:.2e} | "
                    f"{e0:.2e} | {mx:.1e} | {1 - c:.1e} | "
                    f"{_stats(t_err)} | {_stats(n_err)} | {_stats(uv_err)} | {_stats(j_err)} | "
                    f"{e_ex:.3f} ({dm_ex:+.3f}) | {t_three:.2f} s |")
        print(rows[-1], flush=True)
        if stem:
            side_by_side(folder / f"{stem}.png", ref, img, 1e4)
            ev = 2.0 ** np.log2(1.0 / max(float(np.percentile(ref[..., 0][m], 99.5)), 1e-12))
            sep = np.ones((img.shape[0], 2, 3))
            write_png(folder / f"{stem}_exact.png", np.concatenate([exact * ev, sep, img * ev], 1))
            pngs.append(f"![{name}, sphere {width} px: library at the shader's inputs | three.js | "
                        f"|difference| × 10000]({stem}.png)")
            pngs.append(f"![{name}, sphere {width} px: library on the exact sphere | three.js on the "
                        f"{seg[0]}×{seg[1]} mesh]({stem}_exact.png)")
    return rows, pngs


def sphere_text(rows, pngs) -> str:
    return """
## On a sphere

`THREE.SphereGeometry(1, segments)` (tangents from `computeTangents()`, "attribute", or derived
per pixel from the screen derivatives of position and uv, "derivatives"), perspective camera at
distance 4 (field of view 30°), `uvScale` (2, 1), point light of intensity 10 at (2, 2.5, 3),
ideal mirror facets, exact, height-correlated. "Coarse": the pixels whose footprint window
exceeds 48 lobes per axis (grazing footprints near the silhouette), where the shader sums a
coarser lobe level (module notes) and the library the finest. **rel. L1, max err, 1 − correlation**:
the shader's image against the library's `eval_cos_footprints` (float64) at the per-pixel inputs
the same material reads back from its debug outputs (uv, uv derivatives, local wi/wo, I/d²):
the shader's own error ("level 0": over the pixels summed at the finest level only). The other columns (median / 99th percentile / max) compare with the
exact sphere and measure the mesh, not the shader: **T err**: the shader's tangent against the
analytic dP/du at the same (interpolated) point, degrees; **N err**: the normal against the
exact sphere's at the pixel's ray hit, degrees; **uv err**: the interpolated uv against the
exact hit's, in lobe spacings; **J err**: the footprint's uv Jacobian (one-pixel `dFdx`/`dFdy` on the
mesh) against the exact sphere's derivative, relative (Frobenius); **vs exact sphere**: relL1
(and mean) of the shader's image against the library's on the exact sphere (`sphere_inputs`).

| map | image | segments | tangents | coarse | rel. L1 | rel. L1, level 0 | max err | 1 − correlation | T err (°) | N err (°) | uv err (lobes) | J err | vs exact sphere | three.js |
|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(rows) + """

The shader evaluates the library's P-BRDF at its inputs to float32 rounding on the sphere as on
the plane. What a curved mesh adds is in its inputs: the interpolated uv and normal of the
tessellation and the one-pixel finite-difference footprints, largest at the silhouette (grazing
footprints); a finer mesh brings the image toward the exact sphere's.

""" + "\n\n".join(pngs) + "\n"


class _Coarse:
    """The lobe grid of MIP level ``level`` of ``ms`` (for :func:`window`)."""

    def __init__(self, ms, level):
        self.grid, self.cutoff = ms.mip[level].shape[:2], ms.cutoff


if __name__ == "__main__":
    main()
