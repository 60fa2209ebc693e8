"""``microfacet demo -o DIR``: the demo report (HTML, PNG, EXR)."""
from __future__ import annotations

import sys

from .common import int_at_least

#: microfacet.demo's DEFAULT_SIZE, DEFAULT_SPP and DEFAULT_SEED (tested), spelled here so
#: that --help does not import the demo (and with it the whole library).
DEFAULT_SIZE, DEFAULT_SPP, DEFAULT_SEED = 128, 64, 0
#: Most environment samples per pixel --spp takes: 64 times the default (the demo's render time
#: grows with it, ~30 s at the default; a typo such as 64000000 would run for days).
MAX_SPP = 4096


def add(sub) -> None:
    p = sub.add_parser(
        "demo", help="render the thesis Figs. 2.2-2.6 demo report and a fitting section (HTML, PNG, EXR)",
        description="Render spheres and polar lobe plots showing the Fresnel term, the GAF, "
                    "isotropic and anisotropic roughness and its orientation (thesis Figs. "
                    "2.2-2.6) under a directional light and an environment, fits of measured "
                    "materials (the shared corpus where $MICROFACET_DATA or ../shared/data has it, "
                    "else built-in ones) as `microfacet fit` makes them beside the data and the "
                    "published ABC fits, LEADR, glints, Mitsuba and the real-time viewer, into "
                    "DIR/index.html (docs/demo.md).")
    p.add_argument("-o", "--output", metavar="DIR", required=True, help="output folder (created if needed)")
    p.add_argument("--size", type=int_at_least(8), default=DEFAULT_SIZE, metavar="PX",
                   help=f"sphere image side in pixels (default {DEFAULT_SIZE})")
    p.add_argument("--spp", type=int_at_least(1, MAX_SPP), default=DEFAULT_SPP, metavar="N",
                   help=f"environment samples per pixel, in [1, {MAX_SPP}] (default {DEFAULT_SPP})")
    p.add_argument("--seed", type=int_at_least(0), default=DEFAULT_SEED, help=f"random seed (default {DEFAULT_SEED})")
    p.add_argument("-j", "--jobs", type=int_at_least(1), default=None, metavar="N",
                   help="worker processes (default: usable CPUs, at most 4); results do not depend on it")
    p.add_argument("--no-viewer", action="store_true",
                   help="leave out the real-time section (WebGL2 viewer renders in headless Chromium)")
    p.add_argument("--no-mitsuba", action="store_true",
                   help="leave out the Mitsuba 3 section (the microfacet.mitsuba plugins in scenes)")
    p.add_argument("--no-exports", action="store_true",
                   help="leave out the exports section (a fit rendered by Blender's Cycles and three.js)")
    p.add_argument("--timings", action="store_true",
                   help="print each section's wall time to stderr (the pool's fits with their worker's time)")
    p.set_defaults(run=run)


def run(args) -> int:
    from ..demo import default_workers, log, run_demo
    if args.timings:
        import logging
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
    index = run_demo(args.output, size=args.size, spp=args.spp, seed=args.seed,
                     workers=args.jobs or default_workers(), progress=sys.stderr.isatty(), viewer=not args.no_viewer,
                     mitsuba=not args.no_mitsuba, exports=not args.no_exports)
    print(index)
    return 0
