"""The ``microfacet`` command line.

``microfacet demo -o DIR`` renders the demo report (thesis Figs. 2.2-2.6) into ``DIR``
and prints the path of its ``index.html``; ``microfacet validate`` checks the core models
numerically and prints their largest errors; ``microfacet fit INPUT -o OUT`` fits a
measured BRDF (or every one in a folder) and writes the fits, their parameters and
comparison pictures; ``microfacet bake MAP -o OUT.exr`` prefilters a height (or normal) map
into a LEAN/LEADR moment MIP pyramid (multi-part EXR) with a PNG preview; ``microfacet
glints NORMAL_MAP -o OUT.npz`` builds a normal map's Beckmann lobe mixture (glints) and
``microfacet glints render OUT.npz -o IMG.png`` renders it. Bad input prints one line on stderr and exits
with a non-zero status, without a traceback; long work shows a progress bar when stderr
is a terminal and stays quiet otherwise (pipes, CI).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence

import numpy as np

from . import __version__
from .errors import MicrofacetError

__all__ = ["main", "build_parser"]

PROG = "microfacet"
EXIT_ERROR, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line: ``microfacet: error: ...``."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def _int_at_least(lo: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {value}")
        return value
    return parse


def _add_demo(sub) -> None:
    from .demo import DEFAULT_SEED, DEFAULT_SIZE, DEFAULT_SPP, default_workers
    p = sub.add_parser(
        "demo", help="render the thesis Figs. 2.2-2.6 demo report and a fitting section (HTML, PNG, EXR)",
        description="Render spheres and polar lobe plots showing the Fresnel term, the GAF, "
                    "isotropic and anisotropic roughness and its orientation (thesis Figs. "
                    "2.2-2.6) under a directional light and an environment, and fits of built-in "
                    "analytic materials by power iterations (Ch. 4), into DIR/index.html.")
    p.add_argument("-o", "--output", metavar="DIR", required=True, help="output folder (created if needed)")
    p.add_argument("--size", type=_int_at_least(8), default=DEFAULT_SIZE, metavar="PX",
                   help=f"sphere image side in pixels (default {DEFAULT_SIZE})")
    p.add_argument("--spp", type=_int_at_least(1), default=DEFAULT_SPP, metavar="N",
                   help=f"environment samples per pixel (default {DEFAULT_SPP})")
    p.add_argument("--seed", type=_int_at_least(0), default=DEFAULT_SEED, help=f"random seed (default {DEFAULT_SEED})")
    p.add_argument("-j", "--jobs", type=_int_at_least(1), default=default_workers(), metavar="N",
                   help="worker processes (default: usable CPUs, at most 4); results do not depend on it")
    p.set_defaults(run=_run_demo)


def _run_demo(args) -> int:
    from .demo import run_demo
    index = run_demo(args.output, size=args.size, spp=args.spp, seed=args.seed,
                     workers=args.jobs, progress=sys.stderr.isatty())
    print(index)
    return 0


def _add_validate(sub) -> None:
    p = sub.add_parser(
        "validate", help="check the core models numerically and print their largest errors",
        description="Beckmann and GGX over a grid of roughness, correlation and mean slope: "
                    "normalization (Eq. 2.8, 3.1, 2.17) and G1 (Eq. 2.14) against independent "
                    "quadrature, white furnace, chi-square of sampling, weight consistency and "
                    "reciprocity. Prints a Markdown table; exits 1 if a check fails.")
    p.add_argument("--quick", action="store_true", help="a smaller grid and fewer samples (seconds)")
    p.add_argument("-o", "--output", metavar="FILE", help="also write the table to FILE (Markdown)")
    p.set_defaults(run=_run_validate)


def _run_validate(args) -> int:
    from tqdm import tqdm

    from .io import write_text
    from .validation import core_report, format_report
    with tqdm(disable=not sys.stderr.isatty(), unit="step", desc="microfacet validate", leave=False) as bar:
        rows = core_report(quick=args.quick, progress=bar.update)
    text = format_report(rows)
    print(text, end="")
    if args.output:
        write_text(args.output, text)
    return 0 if all(r["ok"] for r in rows) else EXIT_ERROR


def _add_fit(sub) -> None:
    from .brdf import GAFS
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
    p.add_argument("--resolution", type=_int_at_least(8), default=90, metavar="N",
                   help="elevation samples of the tabulated NDF (default 90)")
    p.add_argument("--anisotropic", action="store_true", help="fit an anisotropic NDF (slower)")
    p.add_argument("--gaf", choices=GAFS, default="smith",
                   help="geometric attenuation factor of the fit (default smith)")
    p.set_defaults(run=_run_fit)


def _fit_target(input_path, output: str):
    """The ``.npz`` path of a single-file fit."""
    from pathlib import Path

    from .fit_outputs import material_name
    out = Path(output)
    if out.is_dir():
        return out / f"{material_name(input_path)}.npz"
    return out if out.suffix.lower() == ".npz" else out.with_name(out.name + ".npz")


def _run_fit(args) -> int:
    from pathlib import Path

    from tqdm import tqdm

    from .fit_outputs import (fit_folder, fit_material, format_summary_markdown, material_name,
                              summary_row)
    from .measured import load
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
    brdf = load(source)
    target = _fit_target(source, args.output)
    name = material_name(source)
    summary = fit_material(brdf, target, title=name, **options)
    print(format_summary_markdown([summary_row(name, source, getattr(brdf, "format", ""), summary)]), end="")
    return 0


def _add_bake(sub) -> None:
    p = sub.add_parser(
        "bake", help="prefilter a height or normal map into a LEAN/LEADR moment MIP pyramid (EXR + PNG preview)",
        description="Convert a height map (PNG 8/16-bit gray or RGB, or EXR) into slopes by central "
                    "differences (thesis Sec. 3.4, Listing 3.6), their five Beckmann moments E1..E5 "
                    "(Eq. 3.5-3.9) and an exactly averaged MIP pyramid, written as OUT.exr (one part "
                    "per level, mip0, mip1, ..., float32 channels E1..E5). Also writes OUT.png, the "
                    "filtered appearance at several MIP levels. Prints the pyramid's summary.")
    p.add_argument("map", metavar="MAP", help="height map (or normal map with --normal-map), PNG or EXR")
    p.add_argument("-o", "--output", metavar="OUT.exr", required=True, help="output pyramid (.exr added if missing)")
    p.add_argument("--scale", type=_finite_float, default=1.0, metavar="S",
                   help="height scale: x~ = W*S*(xi(i+1,j) - xi(i-1,j))/2; with --normal-map, "
                        "the normal map's slopes are multiplied by S (default 1)")
    p.add_argument("--normal-map", action="store_true", help="MAP is a tangent-space normal map, not heights")
    p.add_argument("--border", choices=("wrap", "clamp"), default="wrap",
                   help="height map borders for the central differences (default wrap)")
    base = p.add_mutually_exclusive_group()
    base.add_argument("--roughness", type=_finite_float, metavar="A",
                      help="isotropic Beckmann base roughness merged into every texel (Listing 5.1)")
    base.add_argument("--material", metavar="FIT.npz",
                      help="a fit from 'microfacet fit': its Beckmann moments are the base roughness")
    p.set_defaults(run=_run_bake)


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def _run_bake(args) -> int:
    from pathlib import Path

    from . import leadr
    from .io import write_png
    from .leadr.files import load_height_map, load_normal_map
    from .leadr.preview import preview_image
    out = Path(args.output)
    out = out if out.suffix.lower() == ".exr" else out.with_name(out.name + ".exr")
    source = Path(args.map)
    for target in (out, out.with_suffix(".png")):
        if source.exists() and target.exists() and target.samefile(source):
            raise MicrofacetError(f"{target}: output would overwrite the input {source}; choose another -o")
    if args.roughness is not None and args.roughness < 0:
        raise ValueError(f"--roughness must be >= 0, got {args.roughness}")
    base = args.roughness
    if args.material is not None:
        from .fit import load
        base = load(args.material).to_beckmann()
    if args.normal_map:
        pyramid = leadr.mip_pyramid(leadr.normal_map_to_moments(load_normal_map(args.map), base, args.scale))
    else:
        pyramid = leadr.bake(load_height_map(args.map), args.scale, base, border=args.border)
    out.parent.mkdir(parents=True, exist_ok=True)
    leadr.write_pyramid(out, pyramid)
    png = write_png(out.with_suffix(".png"), preview_image(pyramid))
    top = leadr.from_moments(pyramid[-1][0, 0])
    h, w = pyramid[0].shape[:2]
    print(f"{out}: {len(pyramid)} MIP levels from {w} x {h}; top level: alpha_x {float(top.alpha_x):.4g}, "
          f"alpha_y {float(top.alpha_y):.4g}, rho {float(top.rho):.4g}, mean slope "
          f"({float(top.xn):.4g}, {float(top.yn):.4g})")
    print(png)
    return 0


def _add_glints(sub) -> None:
    p = sub.add_parser(
        "glints", help="build a normal map's Beckmann lobe mixture for glints (.npz); "
                       "'glints render' renders one",
        description="Build the microsurface of a normal map (Chermain et al. 2019, Sec. 3): one "
                    "noncentred Beckmann lobe per h x h texels, with slope moments E1..E5 of the "
                    "bilinearly interpolated map under Gaussian kernels (Eq. 3-6), their MIP levels "
                    "(Sec. 4.2.2) and the acceleration hierarchy (Sec. 5), written as a versioned "
                    "OUT.npz. The map is an 8/16-bit PNG or an EXR, (n + 1) / 2 encoded (floats may "
                    "hold n itself), 2 to 4 channels; n_z is reconstructed. "
                    "Second form: 'microfacet glints render OUT.npz -o IMG.png'.")
    p.add_argument("map", metavar="NORMAL_MAP", help="normal map, PNG or EXR")
    p.add_argument("-o", "--output", metavar="OUT.npz", required=True, help="output microsurface (.npz added if missing)")
    p.add_argument("--spacing", type=_finite_float, default=1.0, metavar="H",
                   help="seed spacing h in texels (default 1: one lobe per texel)")
    p.add_argument("--sigma-eps", type=_finite_float, default=0.01, metavar="S",
                   help="floor of the lobes' slope standard deviations (default 0.01)")
    p.add_argument("--encoding", choices=("auto", "offset", "signed"), default="auto",
                   help="float (EXR) maps: (n + 1) / 2 ('offset'), n ('signed') or by content (default)")
    p.set_defaults(run=_run_glints)


def _run_glints(args) -> int:
    from pathlib import Path

    from .glints import Microsurface
    out = Path(args.output)
    out = out if out.suffix.lower() == ".npz" else out.with_name(out.name + ".npz")
    source = Path(args.map)
    if source.exists() and out.exists() and out.samefile(source):
        raise MicrofacetError(f"{out}: output would overwrite the input {source}; choose another -o")
    if args.spacing <= 0 or args.sigma_eps <= 0:
        raise ValueError("--spacing and --sigma-eps must be > 0")
    ms = Microsurface.from_normal_map(source, h=args.spacing, sigma_eps=args.sigma_eps, encoding=args.encoding)
    out.parent.mkdir(parents=True, exist_ok=True)
    ms.save(out)
    alpha = np.sqrt(2.0 * (ms.lobe_moments[:, 2:4] - ms.lobe_moments[:, :2] ** 2))
    print(f"{out}: {ms.n_lobes} lobes ({ms.grid[1]} x {ms.grid[0]}) from a {ms.resolution[1]} x "
          f"{ms.resolution[0]} map, {len(ms.mip)} MIP levels; lobe alpha median "
          f"{float(np.median(alpha)):.4g}, max {float(alpha.max()):.4g}")
    return 0


# ---- hook for 'microfacet glints render OUT.npz -o IMG.png' (owned by the P-BRDF/figures work)
def _add_glints_render(sub) -> None:
    p = sub.add_parser("render", help="render a microsurface built by 'microfacet glints'")
    p.add_argument("microsurface", metavar="OUT.npz", help="microsurface from 'microfacet glints'")
    p.add_argument("-o", "--output", metavar="IMG.png", required=True, help="output image")
    p.add_argument("--light", metavar="X,Y,Z", default="0,0.35,0.9",
                   help="direction from the plane's centre to the point light, local frame with z up "
                        "(default 0,0.35,0.9)")
    p.add_argument("--distance", type=_finite_float, default=1.2, metavar="D",
                   help="distance of the point light from the plane's centre; the plane spans [-1, 1]^2 "
                        "(default 1.2)")
    p.add_argument("--size", type=int, default=256, metavar="W", help="image width in pixels (default 256)")
    p.add_argument("--view", type=_finite_float, default=50.0, metavar="DEG",
                   help="camera elevation above the plane, degrees (default 50)")
    p.add_argument("--approx", action="store_true",
                   help="MIP-approximated patch masking (Sec. 4.2.2) instead of the exact one")
    p.set_defaults(run=_run_glints_render)


def _run_glints_render(args) -> int:
    """'microfacet glints render OUT.npz -o IMG.png': a plane with the microsurface under a
    point light, each pixel shaded by its footprint's P-BRDF (Chermain et al. 2019, Eq. 7)."""
    from pathlib import Path

    from .glints.figures import render_cli
    try:
        light = tuple(float(v) for v in args.light.split(","))
    except ValueError:
        light = ()
    if len(light) != 3:
        raise ValueError(f"--light must be three numbers X,Y,Z, got {args.light!r}")
    if args.size < 1 or args.size > 8192:
        raise ValueError(f"--size must lie in [1, 8192], got {args.size}")
    if not 0 < args.view <= 90:
        raise ValueError(f"--view must lie in (0, 90] degrees, got {args.view}")
    source, out = Path(args.microsurface), Path(args.output)
    if source.exists() and out.exists() and out.samefile(source):
        raise MicrofacetError(f"{out}: output would overwrite the input {source}; choose another -o")
    png, img, seconds = render_cli(source, out, light=light, distance=args.distance,
                                   width=args.size, view_deg=args.view, exact=not args.approx)
    print(f"{png}: {img.shape[1]} x {img.shape[0]} plane, {'approximate' if args.approx else 'exact'} "
          f"P-BRDF, {seconds:.2f} s")
    return 0


def _glints_render_parser() -> argparse.ArgumentParser:
    """Parser of the second form ``microfacet glints render ...``."""
    parser = _Parser(prog=f"{PROG} glints")
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    _add_glints_render(sub)
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``microfacet`` command."""
    parser = _Parser(prog=PROG, description="Multiscale microfacet rendering: BRDFs in slope space, "
                                            "fitting, LEAN/LEADR prefiltering and glints.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND", required=True)
    _add_demo(sub)
    _add_validate(sub)
    _add_fit(sub)
    _add_bake(sub)
    _add_glints(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"{PROG}: warning: {message}", file=sys.stderr)


def _one_line(e: Exception) -> str:
    """``path: reason`` for OS errors, the message otherwise, on one line."""
    if isinstance(e, OSError) and e.strerror and e.filename:
        text = f"{e.filename}: {e.strerror}"
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if argv[:2] == ["glints", "render"]:        # second form of 'glints'
            args = _glints_render_parser().parse_args(argv[1:])
        else:
            args = build_parser().parse_args(argv)
    except SystemExit as e:          # --help, --version, usage errors (already printed)
        return e.code if isinstance(e.code, int) else EXIT_USAGE
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return args.run(args)
    except (MicrofacetError, ValueError, OSError) as e:
        print(f"{PROG}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError:
        print(f"{PROG}: error: out of memory (try a smaller size or resolution)", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
