"""``microfacet glints NORMAL_MAP -o OUT.npz`` (Chermain et al. 2019) and its second form
``microfacet glints render OUT.npz -o IMG.png``."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import (PROG, Parser, add_batch_options, add_normal_map_arguments, finite_float, float_in,
                     int_at_least, output_path, run_batch)

#: ``microfacet.glints.microsurface.SPACING_RANGE``, spelled here so that parsing does not import
#: the glints modules (Numba; tested equal).
SPACING_RANGE = (1.0 / 16.0, 1e4)


def add(sub) -> None:
    p = sub.add_parser(
        "glints", help="build a normal map's Beckmann lobe mixture for glints (.npz); "
                       "'glints render' renders one",
        description="Build the microsurface of a normal map (Chermain et al. 2019, Sec. 3): one "
                    "noncentred Beckmann lobe per h x h texels, with slope moments E1..E5 of the "
                    "bilinearly interpolated map under Gaussian kernels (Eq. 3-6), their MIP levels "
                    "(Sec. 4.2.2) and the acceleration hierarchy (Sec. 5), written as a versioned "
                    "OUT.npz. The map is an 8/16-bit PNG or an EXR, 2 to 4 channels, read by the "
                    "library's one decoder (the same reading as 'microfacet bake --normal-map'): "
                    "(n + 1) / 2 or n (--encoding), z stored or rebuilt (--z); texels facing away or "
                    "beyond 89 degrees are clamped to 89 degrees, with a warning giving their number. "
                    "Second form: 'microfacet glints render OUT.npz -o IMG.png'.")
    p.add_argument("map", metavar="NORMAL_MAP", help="normal map, PNG or EXR; or a folder of them")
    p.add_argument("-o", "--output", metavar="OUT.npz", required=True,
                   help="output microsurface (.npz added if missing; an existing folder takes the map's name); "
                        "the output folder when NORMAL_MAP is a folder")
    p.add_argument("--spacing", type=float_in(*SPACING_RANGE), default=1.0, metavar="H",
                   help="seed spacing h in texels, in [1/16, 10000] (default 1: one lobe per texel)")
    p.add_argument("--sigma-eps", type=float_in(0.0, 10.0, open_lo=True), default=0.01, metavar="S",
                   help="floor of the lobes' slope standard deviations, in (0, 10] (default 0.01)")
    add_normal_map_arguments(p)
    add_batch_options(p)
    p.set_defaults(run=run)

def run(args) -> int:
    if Path(args.map).is_dir():
        return run_batch(args, "glints", args.map)
    from ..batch.tasks import glints_file
    out = output_path(args.output, ".npz", args.map)
    r = glints_file(Path(args.map), out, spacing=args.spacing, sigma_eps=args.sigma_eps,
                    encoding=args.encoding, z=args.z)
    print(f"{out}: {r['lobes']} lobes from a {r['width']} x {r['height']} map, {r['levels']} MIP levels; "
          f"lobe alpha median {r['alpha_median']:.4g}, max {r['alpha_max']:.4g}")
    return 0

def add_render(sub) -> None:
    p = sub.add_parser("render", help="render a microsurface built by 'microfacet glints'")
    p.add_argument("microsurface", metavar="OUT.npz", help="microsurface from 'microfacet glints'")
    p.add_argument("-o", "--output", metavar="IMG.png", required=True, help="output image (.png)")
    p.add_argument("--light", metavar="X,Y,Z", default="0,0.35,0.9",
                   help="direction from the plane's centre to the point light, local frame with z up "
                        "(default 0,0.35,0.9)")
    p.add_argument("--distance", type=float_in(0.0, 1e6, open_lo=True), default=1.2, metavar="D",
                   help="distance of the point light from the plane's centre; the plane spans [-1, 1]^2 "
                        "(default 1.2)")
    p.add_argument("--size", type=int_at_least(1, 8192), default=256, metavar="W",
                   help="image width in pixels (default 256)")
    p.add_argument("--view", type=float_in(0.0, 90.0, open_lo=True), default=50.0, metavar="DEG",
                   help="camera elevation above the plane, degrees (default 50)")
    p.add_argument("--approx", action="store_true",
                   help="MIP-approximated patch masking (Sec. 4.2.2) instead of the exact one")
    p.set_defaults(run=run_render)

def run_render(args) -> int:
    """A plane with the microsurface under a point light, each pixel shaded by its
    footprint's P-BRDF (Chermain et al. 2019, Eq. 7)."""
    from ..glints.figures import render_cli
    try:
        light = tuple(finite_float(v) for v in args.light.split(","))
    except argparse.ArgumentTypeError:
        light = ()
    if len(light) != 3 or not any(light):
        raise ValueError(f"--light must be three finite numbers X,Y,Z, not all 0, got {args.light!r}")
    out = output_path(args.output, ".png", args.microsurface)
    png, img, seconds = render_cli(args.microsurface, out, light=light, distance=args.distance,
                                   width=args.size, view_deg=args.view, exact=not args.approx)
    print(f"{png}: {img.shape[1]} x {img.shape[0]} plane, {'approximate' if args.approx else 'exact'} "
          f"P-BRDF, {seconds:.2f} s")
    return 0

def render_parser() -> argparse.ArgumentParser:
    """Parser of the second form ``microfacet glints render ...``."""
    parser = Parser(prog=f"{PROG} glints")
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    add_render(sub)
    return parser
