"""``microfacet export FIT.npz --to gltf|mtlx|usd|blender -o OUT``: a fit as a glTF, MaterialX,
USD or Blender material (a measured file instead of FIT.npz: fitted first, as ``microfacet fit``
does, its fit files kept beside OUT); ``microfacet export PYRAMID.exr --to textures|ktx2|gltf -o OUT``: a LEADR
pyramid as engine textures; ``microfacet export GLINTS.npz --to threejs -o OUT``: a glint
microsurface as a three.js material (a folder)."""
from __future__ import annotations

import sys

from pathlib import Path

from .common import input_name, output_path

FORMAT_SUFFIX = {"gltf": ".glb", "mtlx": ".mtlx", "usd": ".usda", "blender": ".blend"}


def add(sub) -> None:
    p = sub.add_parser(
        "export", help="export a fit as a glTF (.glb), MaterialX (.mtlx), USD (.usda) or Blender (.blend) material",
        description="Map the analytic model of FIT.npz (from 'microfacet fit'; --model best: the best fit by "
                    "image error, or the best analytic one when that is the tabulated fit) to glTF 2.0 (a .glb "
                    "sphere: metallicRoughness, KHR_materials_specular/ior/anisotropy/clearcoat), MaterialX (an "
                    "exact pbrlib graph and an open_pbr_surface), USD (UsdPreviewSurface and the OpenPBR "
                    "surface bound to a sphere) or Blender (a .blend Cycles material, OUT.blender.json and the "
                    "add-on microfacet_blender.zip; needs 'make setup-blender'). Beside OUT: OUT.export.json "
                    "and OUT.export.md, what the format "
                    "could not carry and the image error of the exported material (read back from OUT) against "
                    "the library's fit and the tabulated fit, measured now. Formulas: docs/export.md.")
    p.add_argument("fit", metavar="FIT.npz|MEASURED|PYRAMID.exr|GLINTS.npz",
                   help="fit file written by 'microfacet fit', or a measured file (MERL .binary(.gz), RGL .bsdf, "
                        "UTIA .bin: fitted first as 'microfacet fit' does, OUT's name .npz/.json/.png kept "
                        "beside OUT), or a LEADR pyramid of 'microfacet bake' (--to "
                        "textures|ktx2|gltf: normal, roughness and anisotropy textures per MIP level as PNG files, "
                        "KTX2 MIP chains or a .glb plane holding them, docs/export.md), "
                        "or a glint microsurface of 'microfacet glints' (--to threejs: a folder with the glint "
                        "P-BRDF as a three.js material, docs/glints.md)")
    p.add_argument("--to", required=True, choices=sorted([*FORMAT_SUFFIX, "textures", "ktx2", "threejs"]),
                   help="output format")
    p.add_argument("--base-roughness", type=float, default=None, metavar="ALPHA",
                   help="PYRAMID.exr only: Beckmann roughness added to every level (leave out when baked with it)")
    p.add_argument("--level", type=int, default=None, metavar="L",
                   help="PYRAMID.exr --to blender|mtlx|usd only: the MIP level exported (default 0)")
    p.add_argument("--model", default="best", metavar="NAME",
                   help="fit of the file to export: best (default) or a name (microfacet.fit.fit_names)")
    p.add_argument("--mesh", choices=["plane", "sphere"], default=None,
                   help="GLINTS.npz --to threejs only: the mesh of the folder's demo page (default plane)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output file (.glb/.mtlx/.usda added if missing) or folder (FIT's name)")
    p.set_defaults(run=run)


def run(args) -> int:
    from ..export import export, is_microsurface, is_pyramid
    if is_microsurface(args.fit):
        from ..export.glints_export import run_cli as run_glints
        return run_glints(args)
    if getattr(args, "mesh", None) is not None:
        raise ValueError("--mesh applies to a glint microsurface (GLINTS.npz) exported --to threejs")
    if args.to == "threejs":
        raise ValueError(f"{args.fit}: --to threejs exports a glint microsurface (GLINTS.npz from 'microfacet "
                         "glints'); a fit file exports --to gltf (three.js loads .glb)")
    if is_pyramid(args.fit) and args.to in ("blender", "mtlx", "usd"):
        from ..export.leadr_consumers import run_cli as run_leadr_consumers
        return run_leadr_consumers(args)
    if getattr(args, "level", None) is not None:
        raise ValueError("--level applies to a LEADR pyramid exported --to blender, mtlx or usd")
    if is_pyramid(args.fit) or args.to in ("textures", "ktx2"):
        from ..export.leadr_textures import run_cli
        return run_cli(args)
    if args.base_roughness is not None:
        raise ValueError("--base-roughness applies to a LEADR pyramid (PYRAMID.exr), not to a fit file")
    suffix = FORMAT_SUFFIX[args.to]
    out = output_path(args.output, suffix, source=args.fit)
    source = args.fit if Path(args.fit).suffix.lower() == ".npz" else _fitted(Path(args.fit), out)
    report = export(source, args.to, out, model=args.model)
    e = report["image_error"]
    print(f"{report['file']}: {report['model']} as {args.to}; report {report['file']}.export.md")
    for k, v in e["exported_vs_fit"].items():
        tab = e.get("exported_vs_tabulated", {}).get(k)
        print(f"  {k}: image error {v:.4f} vs the fit" + ("" if tab is None else f", {tab:.4f} vs the tabulated fit"
                                                         f" (the fit itself {e['fit_vs_tabulated']:.4f})"))
    for line in report["lost"]:
        print(f"  not carried: {line}", file=sys.stderr)
    return 0


def _fitted(measured: Path, out: Path) -> Path:
    """``measured`` fitted as ``microfacet fit MEASURED -o OUT.npz`` does (``.json`` and
    ``.png`` beside it, ``OUT`` the export's name): the fit file to export."""
    from ..batch.tasks import fit_file
    from .fit import numpy_kernels
    target = output_path(out.with_suffix(".npz"), ".npz", measured, side=(".json", ".png"))
    with numpy_kernels():
        fit_file(measured, target)
    print(f"{input_name(measured)}: fitted, fits written to {target} (.json, .png)")
    return target
