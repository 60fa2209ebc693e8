"""``microfacet fit INPUT -o OUT``: fits of measured BRDFs (thesis Ch. 4)."""
from __future__ import annotations

import sys
from pathlib import Path

from .common import EXIT_ERROR, PROG, int_at_least, output_path


def add(sub) -> None:
    from ..brdf import GAFS
    p = sub.add_parser(
        "fit", help="fit measured BRDFs by power iterations (tabulated, GGX and Beckmann fits)",
        description="Fit a measured BRDF (MERL .binary(.gz), RGL .bsdf, UTIA .bin; recognised by "
                    "content) by power iterations (thesis Ch. 4). For a file: writes OUT.npz (the "
                    "tabulated fit, loadable by microfacet.fit.load), OUT.json (GGX and Beckmann "
                    "parameters, Fresnel term, fit time, fit errors) and OUT.png (comparison "
                    "picture). For a folder: the same for every file in it, into the folder OUT, "
                    "with summary.csv and summary.md. Prints the summary table.")
    p.add_argument("input", metavar="INPUT", help="measured BRDF file, or a folder of them")
    p.add_argument("-o", "--output", metavar="OUT", required=True,
                   help="OUT.npz for a file (.npz added if missing; an existing folder takes "
                        "INPUT's name), output folder for a folder")
    p.add_argument("--resolution", type=int_at_least(8, 2048), default=90, metavar="N",
                   help="elevation samples of the tabulated NDF (default 90)")
    p.add_argument("--anisotropic", action="store_true", help="fit an anisotropic NDF (slower)")
    p.add_argument("--gaf", choices=GAFS, default="smith",
                   help="geometric attenuation factor of the fit (default smith)")
    p.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from ..fit.outputs import fit_folder, fit_material, format_summary_markdown, material_name, summary_row
    from ..measured import load
    source = Path(args.input)
    options = dict(resolution=args.resolution, anisotropic=args.anisotropic, gaf=args.gaf)
    if source.is_dir():
        def progress(files):
            return tqdm(files, disable=not sys.stderr.isatty(), unit="material", desc="microfacet fit",
                        leave=False)
        rows = fit_folder(source, args.output, progress=progress, **options)
        print(format_summary_markdown(rows), end="")
        failed = sum(r["status"] != "ok" for r in rows)
        if failed:
            print(f"{PROG}: error: {failed} of {len(rows)} files not fitted (see the warnings "
                  f"and {Path(args.output) / 'summary.md'})", file=sys.stderr)
            return EXIT_ERROR
        return 0
    target = output_path(args.output, ".npz", source, side=(".json", ".png"))
    brdf = load(source)
    name = material_name(source)
    summary = fit_material(brdf, target, title=name, **options)
    print(format_summary_markdown([summary_row(name, source, getattr(brdf, "format", ""), summary)]), end="")
    return 0
