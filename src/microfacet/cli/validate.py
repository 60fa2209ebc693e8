"""``microfacet validate``: the core models against independent quadrature."""
from __future__ import annotations

import sys

from .common import EXIT_ERROR, output_path


def add(sub) -> None:
    p = sub.add_parser(
        "validate", help="check the core models numerically and print their largest errors",
        description="Beckmann and GGX over a grid of roughness, correlation and mean slope: "
                    "normalization (Eq. 2.8, 3.1, 2.17) and G1 (Eq. 2.14) against independent "
                    "quadrature, white furnace, chi-square of sampling, weight consistency and "
                    "reciprocity. Prints a Markdown table; exits 1 if a check fails.")
    p.add_argument("--quick", action="store_true", help="a smaller grid and fewer samples (seconds)")
    p.add_argument("-o", "--output", metavar="FILE.md",
                   help="also write the table to FILE.md (a folder receives validate.md)")
    p.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from ..io import write_text
    from ..validation import core_report, format_report
    out = output_path(args.output, ".md", default_name="validate") if args.output is not None else None
    with tqdm(disable=not sys.stderr.isatty(), unit="step", desc="microfacet validate", leave=False) as bar:
        rows = core_report(quick=args.quick, progress=bar.update)
    text = format_report(rows)
    print(text, end="")
    if out is not None:
        write_text(out, text)
    return 0 if all(r["ok"] for r in rows) else EXIT_ERROR
