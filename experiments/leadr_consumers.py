#!/usr/bin/env python3
"""LEADR in Blender (Cycles) and MaterialX (OpenPBR, GlslRenderer): a coarse level's textures
against the full-resolution map supersampled, and the naive coarse level.

For each map and coarse level L, the plane of :func:`microfacet.export.leadr_consumers.plane_for_level`
(seen from straight above, orthographic, one level-L texel per pixel, sun from LIGHT) is rendered
in each consumer's own renderer with (a) the LEADR textures of level L, (b) the naive level L
(the level-0 textures box-filtered: normals averaged, the base roughness only) and (c) level 0
supersampled (Cycles: REF_SPP uniform samples per pixel, box filter; MaterialX: REF_K x REF_K
pixels per pixel, box-downsampled). relL1 = sum |x - c| / sum c over the image (the metric of
experiments/results/leadr_engines.md). Noise: (c) against a second reference (Cycles: another
seed; MaterialX: REF_K/2), the floor under (a) and (b).

Usage::

    python experiments/leadr_consumers.py [--quick] [--out experiments/results/leadr_consumers.md]
"""
from __future__ import annotations

import argparse
import datetime
import platform
import sys
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.export.leadr_consumers import MtlxPlaneRenderer, compare_leadr, level_ellipses, plane_for_level
from microfacet.io.png import write_png

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "maps"
LIGHT = (0.5, 0.3, 0.8124)
SIZE, REF_SPP, REF_K = 96, 1024, 16


def maps(quick: bool) -> dict:
    """name: (pyramid, coarse levels)."""
    out = {"Gaussian bumps 64^2 (alpha 0.4 x 0.15, rho 0.6)":
           (mf.leadr.bake(mf.leadr.gaussian_heightfield((64, 64), 0.4, 0.15, 0.6, seed=1), roughness=0.05),
            (3,) if quick else (2, 3))}
    waves = DATA / "sms_normalmap_waves.exr"
    if waves.is_file() and not quick:
        out["sms_normalmap_waves 512^2"] = (mf.leadr.mip_pyramid(mf.leadr.normal_map_to_moments(waves, roughness=0.05)),
                                            (3, 4))
    elif not quick:
        print(f"{waves} absent: the waves map is left out", file=sys.stderr)
    return out


def run(quick: bool, out: Path) -> None:
    t0 = time.time()
    size, spp, k = (48, 256, 8) if quick else (SIZE, REF_SPP, REF_K)
    rows, strips, fails = [], [], []
    with MtlxPlaneRenderer() as renderer:
        for mname, (pyramid, levels) in maps(quick).items():
            for level in levels:
                plane = plane_for_level(pyramid, level, size=size, light=LIGHT, spp=16)
                for consumer, ref in (("blender", spp), ("mtlx", k)):
                    t = time.time()
                    r = compare_leadr(pyramid, level, consumer, plane, reference=ref, renderer=renderer, noise=True)
                    h, w = pyramid[level].shape[:2]
                    ok = "yes" if r["leadr"] < r["naive"] else "**no**"
                    fails += [] if r["leadr"] < r["naive"] else [f"{mname}, level {level}, {consumer}"]
                    e = level_ellipses(pyramid, level)
                    rows.append(f"| {mname} | {level} ({w}x{h}) | {np.sqrt(e['alpha1'] * e['alpha2']).mean():.3f} "
                                f"| {consumer} | {r['leadr']:.3f} | {r['naive']:.3f} "
                                f"| {r['noise']:.3f} | {ok} | {time.time() - t:.0f} s |")
                    print(rows[-1], flush=True)
                    s = np.percentile(r["reference_image"], 99.5)
                    strips.append(np.concatenate([r["naive_image"], r["leadr_image"], r["reference_image"]], axis=1)
                                  / s)
    figures = out.parent / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    width = max(s.shape[1] for s in strips)
    png = figures / "leadr_consumers.png"
    write_png(png, np.concatenate([np.pad(s, ((0, 2), (0, width - s.shape[1]), (0, 0))) for s in strips], axis=0))
    text = [
        "# LEADR in Blender and MaterialX: coarse level vs naive coarse level vs supersampled full resolution", "",
        f"`python experiments/leadr_consumers.py{' --quick' if quick else ''}`, "
        f"{datetime.date.today().isoformat()}, {platform.node()} ({platform.machine()}, "
        f"{__import__('os').cpu_count()} CPUs), {time.time() - t0:.0f} s. "
        "Blender 4.5 Cycles on the CPU (Principled BSDF, GGX, textures bilinear, box pixel filter of width 1); "
        "MaterialX 1.39 GlslRenderer under Xvfb (Mesa llvmpipe; open_pbr_surface, energy compensation removed; "
        "one sample at each pixel centre).", "",
        f"Scene: the plane [-1, 1]^2 from straight above (orthographic), {size} x {size} px, the map tiled so that "
        "one texel of the coarse level covers one pixel, metal (base colour 0.9), sun of irradiance 1 from "
        f"{LIGHT} (36 deg off the normal: the half vector 18 deg off), base roughness alpha 0.05 in the pyramid. "
        "(a) the coarse level's LEADR textures (normal from the mean slope, roughness and anisotropy from the "
        "covariance, converted to each consumer's parameters: src/microfacet/export/leadr_consumers.py); "
        "(b) the naive coarse level (the level-0 textures box-filtered, as an engine's MIP generation: "
        "averaged normals, the base roughness); (c) the reference: level 0, "
        f"Cycles {spp} samples per pixel, MaterialX {k} x {k} pixels per pixel box-downsampled. relL1 = "
        "sum |x - c| / sum c over the image. Noise: (c) against a second reference (Cycles: another seed; "
        f"MaterialX: {k // 2} x {k // 2}).", "",
        "Column alpha: the mean over the level's texels of LEADR's sqrt(alpha1 alpha2) (the naive level has the "
        "base 0.05): how much roughness the footprint adds, i.e. how much there is for LEADR to carry.", "",
        "| map | level (texels) | alpha | consumer | (a) LEADR vs (c) | (b) naive vs (c) | noise of (c) | (a) < (b) "
        "| time |", "|---|---|---|---|---|---|---|---|---|", *rows, "",
        ("(a) < (b) in every case." if not fails else
         "(a) < (b) fails for: " + "; ".join(fails) + ". Where the level adds little roughness to the base (alpha "
         "column near 0.05), the naive level is already close and LEADR's gain is below the errors both share "
         "(GGX's lobe against the footprint's actual slope distribution, bilinear filtering of the parameters "
         "over each Cycles pixel)."), "",
        f"![naive | LEADR | reference, one row per table row](figures/{png.name})", "",
        "Image rows in the table's order; columns (b), (a), (c), each scaled by the reference's 99.5th "
        "percentile.", ""]
    out.write_text("\n".join(text))
    print("\n".join(text))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one map and level, 48 px, smaller references")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "leadr_consumers.md")
    args = ap.parse_args()
    run(args.quick, args.out)


if __name__ == "__main__":
    main()
