"""``microfacet bake MAP -o OUT.exr``: LEAN/LEADR moment MIP pyramids (thesis Ch. 3, 5)."""
from __future__ import annotations

from pathlib import Path

from ..io.exr import COMPRESSIONS
from .common import add_batch_options, add_normal_map_arguments, finite_float, float_in, output_path, run_batch

def add(sub) -> None:
    p = sub.add_parser(
        "bake", help="prefilter a height or normal map into a LEAN/LEADR moment MIP pyramid (EXR + PNG preview)",
        description="Convert a height map (PNG 8/16-bit gray or RGB, or EXR) into slopes by central "
                    "differences (thesis Sec. 3.4, Listing 3.6), their five Beckmann moments E1..E5 "
                    "(Eq. 3.5-3.9) and an exactly averaged MIP pyramid, written as OUT.exr (one part "
                    "per level, mip0, mip1, ..., float32 channels E1..E5). Also writes OUT.png, the "
                    "filtered appearance at several MIP levels. Prints the pyramid's summary. With "
                    "--normal-map, MAP is a tangent-space normal map read by the library's one decoder "
                    "(the same reading as 'microfacet glints'): 8/16-bit PNG or EXR, (n + 1) / 2 or n "
                    "(--encoding), z stored or rebuilt (--z); texels facing away or beyond 89 degrees "
                    "are clamped to 89 degrees, with a warning giving their number.")
    p.add_argument("map", metavar="MAP", help="height map (or normal map with --normal-map), PNG or EXR; "
                                             "or a folder of them")
    p.add_argument("-o", "--output", metavar="OUT.exr", required=True,
                   help="output pyramid (.exr added if missing; an existing folder takes MAP's name); "
                        "the output folder when MAP is a folder")
    p.add_argument("--scale", type=finite_float, default=1.0, metavar="S",
                   help="height scale: x~ = W*S*(xi(i+1,j) - xi(i-1,j))/2; with --normal-map, "
                        "the normal map's slopes are multiplied by S (default 1)")
    p.add_argument("--normal-map", action="store_true", help="MAP is a tangent-space normal map, not heights")
    add_normal_map_arguments(p)
    p.add_argument("--border", choices=("wrap", "clamp"), default="wrap",
                   help="height map borders for the central differences (default wrap)")
    base = p.add_mutually_exclusive_group()
    base.add_argument("--roughness", type=float_in(0.0, 1e3), metavar="A",
                      help="isotropic Beckmann base roughness merged into every texel (Listing 5.1)")
    base.add_argument("--material", metavar="FIT.npz",
                      help="a fit from 'microfacet fit': its Beckmann moments are the base roughness")
    p.add_argument("--compression", choices=tuple(COMPRESSIONS), default="none",
                   help="lossless EXR compression of OUT.exr (default none: the fastest write; zip or "
                        "zstd give files 0-20%% smaller at 3-10x the write time; zstd needs OpenEXR >= 3.4)")
    add_batch_options(p)
    p.set_defaults(run=run)

def run(args) -> int:
    if Path(args.map).is_dir():
        return run_batch(args, "bake", args.map)
    from ..batch.tasks import bake_file
    out = output_path(args.output, ".exr", args.map, side=(".png",))
    r = bake_file(Path(args.map), out, scale=args.scale, normal_map=args.normal_map, border=args.border,
                  roughness=args.roughness, material=args.material, encoding=args.encoding, z=args.z,
                  compression=args.compression)
    print(f"{out}: {r['levels']} MIP levels from {r['width']} x {r['height']}; top level: alpha_x "
          f"{r['alpha_x']:.4g}, alpha_y {r['alpha_y']:.4g}, rho {r['rho']:.4g}, mean slope "
          f"({r['mean_x']:.4g}, {r['mean_y']:.4g})")
    print(out.with_suffix(".png"))
    return 0
