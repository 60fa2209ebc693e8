"""``microfacet bake MAP -o OUT.exr``: LEAN/LEADR moment MIP pyramids (thesis Ch. 3, 5)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .common import add_batch_options, finite_float, float_in, output_path, run_batch


def add(sub) -> None:
    p = sub.add_parser(
        "bake", help="prefilter a height or normal map into a LEAN/LEADR moment MIP pyramid (EXR + PNG preview)",
        description="Convert a height map (PNG 8/16-bit gray or RGB, or EXR) into slopes by central "
                    "differences (thesis Sec. 3.4, Listing 3.6), their five Beckmann moments E1..E5 "
                    "(Eq. 3.5-3.9) and an exactly averaged MIP pyramid, written as OUT.exr (one part "
                    "per level, mip0, mip1, ..., float32 channels E1..E5). Also writes OUT.png, the "
                    "filtered appearance at several MIP levels. Prints the pyramid's summary.")
    p.add_argument("map", metavar="MAP", help="height map (or normal map with --normal-map), PNG or EXR; "
                                             "or a folder of them")
    p.add_argument("-o", "--output", metavar="OUT.exr", required=True,
                   help="output pyramid (.exr added if missing; an existing folder takes MAP's name); "
                        "the output folder when MAP is a folder")
    p.add_argument("--scale", type=finite_float, default=1.0, metavar="S",
                   help="height scale: x~ = W*S*(xi(i+1,j) - xi(i-1,j))/2; with --normal-map, "
                        "the normal map's slopes are multiplied by S (default 1)")
    p.add_argument("--normal-map", action="store_true", help="MAP is a tangent-space normal map, not heights")
    p.add_argument("--border", choices=("wrap", "clamp"), default="wrap",
                   help="height map borders for the central differences (default wrap)")
    base = p.add_mutually_exclusive_group()
    base.add_argument("--roughness", type=float_in(0.0, 1e3), metavar="A",
                      help="isotropic Beckmann base roughness merged into every texel (Listing 5.1)")
    base.add_argument("--material", metavar="FIT.npz",
                      help="a fit from 'microfacet fit': its Beckmann moments are the base roughness")
    add_batch_options(p)
    p.set_defaults(run=run)


def run(args) -> int:
    if Path(args.map).is_dir():
        return run_batch(args, "bake", args.map)
    from .. import leadr
    from ..io import write_png
    from ..leadr.files import load_height_map, load_normal_map
    from ..leadr.preview import preview_image
    out = output_path(args.output, ".exr", args.map, side=(".png",))
    base = args.roughness
    if args.material is not None:
        from ..fit import load
        base = load(args.material).to_beckmann()
    with np.errstate(over="ignore", invalid="ignore"):
        if args.normal_map:
            pyramid = leadr.mip_pyramid(leadr.normal_map_to_moments(load_normal_map(args.map), base, args.scale))
        else:
            pyramid = leadr.bake(load_height_map(args.map), args.scale, base, border=args.border)
    if not all(np.isfinite(level).all() for level in pyramid):
        raise MicrofacetError(f"{args.map}: the slope moments overflow float32 (--scale {args.scale:g}"
                              f"{'' if args.roughness is None else f', --roughness {args.roughness:g}'}"
                              "); use a smaller scale or roughness")
    leadr.write_pyramid(out, pyramid)
    png = write_png(out.with_suffix(".png"), preview_image(pyramid))
    top = leadr.from_moments(pyramid[-1][0, 0])
    h, w = pyramid[0].shape[:2]
    print(f"{out}: {len(pyramid)} MIP levels from {w} x {h}; top level: alpha_x {float(top.alpha_x):.4g}, "
          f"alpha_y {float(top.alpha_y):.4g}, rho {float(top.rho):.4g}, mean slope "
          f"({float(top.xn):.4g}, {float(top.yn):.4g})")
    print(png)
    return 0
