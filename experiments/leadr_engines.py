#!/usr/bin/env python3
"""LEADR for engines: a plane receding to the horizon in three.js (system Chromium, SwiftShader),
textured with (a) naive MIPs (the level-0 textures box-filtered, constant roughness: what
``generateMipmap`` gives), (b) the LEADR MIPs of :mod:`microfacet.export.leadr_textures` uploaded
as the textures' ``mipmaps``, (b KTX2) the ``.glb`` of ``microfacet export --to gltf`` whose textures
are those chains as KTX2 images (Basis UASTC, KHR_texture_basisu) loaded by three.js's GLTFLoader +
KTX2Loader (what an application gets from the file alone), (b') the same LEADR MIPs with an isotropic roughness ``sqrt(alpha1 alpha2)``
and no anisotropy (what stock three.js renders correctly, see below), against (c) the reference:
level 0 without MIPs rendered at 8x the resolution and box-downsampled. Relative L1 error of each
against (c), per map, view and texture filtering (three.js ``texture.anisotropy`` 1 = trilinear,
16 = anisotropic).

Renders use :class:`microfacet.export.leadr_threejs.PlaneRenderer`: three.js's multiple-scattering
compensation and ``geometryRoughness`` off, and its anisotropy frame re-orthogonalised against
the normal-mapped normal ("patched"). Stock three.js builds the anisotropic lobe in the
geometric tangent frame, so with KHR_materials_anisotropy on the normal map barely moves the
specular lobe; the "stock" column shows what (b) gives there. (a), (b') and (c) use three.js's
isotropic lobe (the extension off), where the normal map acts in full.

Usage::

    python experiments/leadr_engines.py [--quick] [--out experiments/results/leadr_engines.md]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.export.leadr_textures import (encode_level, export_leadr, gltf_parameters, ktx2_writer,
                                             leadr_textures, level_parameters, naive_textures, write_plane_glb)
from microfacet.export.leadr_threejs import PlaneRenderer, PlaneView, relative_l1
from microfacet.io.png import write_png

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "maps"
VIEWS = {
    "grazing (3 deg at 15)": PlaneView(eye=(0.0, 0.8, 20.0), target=(0.0, 0.0, 5.0), light=(0.0, 0.06, -1.0)),
    "15 deg": PlaneView(),
    "30 deg": PlaneView(eye=(0.0, 8.0, 20.0), target=(0.0, 0.0, 4.0), light=(0.0, 0.55, -1.0)),
}
OFF = {"anisotropy": 0}                       # KHR_materials_anisotropy off: three.js's isotropic lobe


def maps(quick: bool) -> dict:
    """name: (pyramid, tiles over the 40-unit plane)."""
    out = {"Gaussian bumps 64^2 (alpha 0.4 x 0.15, rho 0.6)":
           (mf.leadr.bake(mf.leadr.gaussian_heightfield((64, 64), 0.4, 0.15, 0.6, seed=1), roughness=0.05), 80.0)}
    waves = DATA / "sms_normalmap_waves.exr"
    if not quick and waves.is_file():
        E = mf.leadr.normal_map_to_moments(waves, roughness=0.05)
        out["sms_normalmap_waves 512^2"] = (mf.leadr.mip_pyramid(E), 10.0)
    elif not quick:
        print(f"{waves} absent: the waves map is left out", file=sys.stderr)
    return out


def isotropic_levels(pyramid) -> list[dict]:
    """LEADR MIPs with the isotropic roughness of the same peak, ``alpha = sqrt(alpha1 alpha2)``."""
    out = []
    for E in pyramid:
        p = level_parameters(E)
        a = np.sqrt(p["alpha1"] * p["alpha2"])
        p = dict(p, alpha1=a, alpha2=a, roughness=np.sqrt(a), strength=np.zeros_like(a))
        out.append(encode_level(p))
    return out


def scaled_levels(pyramid, k: float) -> list[dict]:
    """LEADR MIPs with GGX alphas ``k`` times the Beckmann ones (the sensitivity of the mapping)."""
    out = []
    for E in pyramid:
        p = level_parameters(E)
        a1, a2 = k * p["alpha1"], k * p["alpha2"]
        r, s, clipped = gltf_parameters(a1, a2)
        out.append(encode_level(dict(p, alpha1=a1, alpha2=a2, roughness=r, strength=s, clipped=clipped)))
    return out


SCALES = (0.7, 1.0, 1.2, 1.4, 1.7)
#: three.js texture formats (WebGL enums) KTX2Loader may transcode UASTC to
GPU_FORMATS = {37808: "ASTC 4x4", 36492: "BC7 (BPTC)", 37496: "ETC2 RGBA", 33779: "BC3 (DXT5)", 33776: "BC1",
               1023: "RGBA8"}


def run(quick: bool, out: Path) -> None:
    figures = ROOT / "experiments" / "results" / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="leadr_engines_"))
    rows, strips, revision = [], [], None
    t0 = time.time()
    cases = maps(quick)
    views = dict(list(VIEWS.items())[1:2]) if quick else VIEWS
    ss = 4 if quick else 8
    renders, sens, formats = {}, {}, set()
    has_ktx2 = ktx2_writer(required=False) is not None
    if not has_ktx2:
        print("the KTX2 writer alktx2 is absent (pip install -e '.[export]'): no KTX2 column", file=sys.stderr)
    for stock in (False, True):
        with PlaneRenderer(mapped_frame=not stock) as r:
            for mname, (pyramid, tiles) in cases.items():
                levels = leadr_textures(pyramid)
                naive, iso = naive_textures(levels[0]), isotropic_levels(pyramid)
                glb = write_plane_glb(levels[0], work / "plane.glb", tiles=tiles)
                kglb = export_leadr(pyramid, "gltf", work / "plane_ktx2.glb", tiles=tiles)["file"] if has_ktx2 else None
                for vname, view in views.items():
                    for aniso in (1, 16):
                        v = dataclasses.replace(view, tiles=tiles, anisotropy=aniso)
                        off = dataclasses.replace(v, extra=OFF)
                        key = (mname, vname, aniso)
                        if stock:
                            renders[key]["leadr_stock"] = r.render(glb, v, levels)
                            continue
                        ref = r.render(glb, off, levels, mips=False, supersample=ss)
                        if aniso == 16 and vname != next(iter(VIEWS)):
                            sens[(mname, vname)] = {k: r.render(glb, v, scaled_levels(pyramid, k)) for k in SCALES}
                        fine = r.render(glb, off, levels, mips=False, supersample=2 * ss) if aniso == 16 else None
                        renders[key] = {"reference": ref, "fine": fine, "naive": r.render(glb, off, naive),
                                        "leadr": r.render(glb, v, levels), "leadr_iso": r.render(glb, off, iso),
                                        "ref_with_extension": r.render(glb, v, levels, mips=False, supersample=2),
                                        "ref_without_extension": r.render(glb, off, levels, mips=False, supersample=2)}
                        if kglb is not None:
                            renders[key]["ktx2"] = r.render(kglb, v)
                            formats.add(tuple(sorted((t["format"], t["levels"]) for t in r.textures.values())))
                revision = r.revision
    for (mname, vname, aniso), im in renders.items():
        e = {k: relative_l1(im[k], im["reference"]) for k in ("naive", "leadr", "leadr_iso", "leadr_stock", "ktx2")
             if k in im}
        ktx2 = f"{e['ktx2']:.3f}" if "ktx2" in e else "—"
        same = relative_l1(im["ref_with_extension"], im["ref_without_extension"])
        floor = "" if im["fine"] is None else f"{relative_l1(im['reference'], im['fine']):.3f}"
        rows.append(f"| {mname} | {vname} | {aniso} | {e['naive']:.3f} | {e['leadr']:.3f} | {ktx2} | {e['leadr_iso']:.3f} "
                    f"| {e['leadr_stock']:.3f} | {same:.1e} | {floor} |")
        if aniso == 16:
            s = np.percentile(im["reference"], 99.5)
            strips.append(np.concatenate([im["naive"], im["leadr"], im["leadr_iso"], im["reference"]], axis=1) / s)
    srows = [f"| {m} | {v} | " + " | ".join(f"{relative_l1(im[k], renders[(m, v, 16)]['reference']):.3f}"
                                          for k in SCALES) + " |" for (m, v), im in sens.items()]
    png = figures / "leadr_engines.png"
    write_png(png, np.kron(np.concatenate(strips, axis=0), np.ones((2, 2, 1))))
    text = [
        "# LEADR for engines: naive MIPs vs LEADR MIPs vs a supersampled reference in three.js", "",
        f"`python experiments/leadr_engines.py{' --quick' if quick else ''}`; three.js r{revision} in the system "
        f"Chromium (SwiftShader), {time.time() - t0:.0f} s. Plane 40 x 40 units, metal (base colour 0.9, "
        "metallic 1), base roughness alpha 0.05 in the pyramid, one directional light opposite the camera "
        f"(the highlight mid-distance), {PlaneView().width} x {PlaneView().height} px; reference: level 0 without "
        f"MIPs at {ss}x the resolution, box-downsampled. Relative L1 error (sum |image - reference| / sum "
        "reference) over the whole image.", "",
        "Columns: (a) naive MIPs (box-filtered level-0 textures, constant roughness); (b) LEADR MIPs "
        "(normal from the mean slope, roughness + KHR_materials_anisotropy from the covariance), three.js with "
        "its anisotropy frame re-orthogonalised against the mapped normal; (b') LEADR MIPs, isotropic "
        "roughness sqrt(alpha1 alpha2), anisotropy off (correct in stock three.js); (b stock) (b) in stock "
        "three.js, whose anisotropic lobe keeps the geometric tangent frame so that the normal map barely "
        "moves it; (b KTX2) (b) as the exported .glb holds it: KTX2 chains (Basis UASTC LDR 4x4, linear, "
        "KHR_texture_basisu) that three.js's KTX2Loader transcodes to the GPU format "
        f"{', '.join(sorted({GPU_FORMATS.get(f, str(f)) for fs in formats for f, _ in fs})) or '(none: no writer)'} "
        f"with {', '.join(sorted({str(n) for fs in formats for _, n in fs})) or '-'} MIP levels per texture, "
        "patched frame. Last column: the reference with the anisotropy extension on (strength 0, patched frame) "
        "against off: the patched anisotropic lobe reduces to the isotropic one. "
        f"Reference noise: the reference against the same at {2 * ss}x (its own aliasing of glints, a floor under "
        "every error; measured with texture.anisotropy 16).", "",
        "| map | view | texture.anisotropy | (a) naive | (b) LEADR | (b KTX2) LEADR, KTX2 chain | (b') LEADR isotropic "
        "| (b) stock three.js | ref. ext. on vs off | reference noise |", "|---|---|---|---|---|---|---|---|---|---|",
        *rows, "",
        f"![naive | LEADR | LEADR isotropic | reference, texture.anisotropy 16, one row per map and view]"
        f"(figures/{png.name})", "",
        "Image: rows are the map x view cases with texture.anisotropy 16 (in the table's order); columns (a), "
        "(b), (b'), (c), each scaled by the reference's 99.5th percentile.", "",
        "## Sensitivity: GGX alpha = k x the Beckmann alpha", "",
        "The export writes k = 1 (equal peak D(0)); (b) with other k, texture.anisotropy 16:", "",
        "| map | view | " + " | ".join(f"k = {k}" for k in SCALES) + " |",
        "|---|---|" + "---|" * len(SCALES), *srows, ""]
    out.write_text("\n".join(text))
    print("\n".join(text))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one map, one view, 4x reference")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "leadr_engines.md")
    args = ap.parse_args()
    run(args.quick, args.out)


if __name__ == "__main__":
    main()
