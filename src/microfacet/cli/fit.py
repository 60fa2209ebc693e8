"""``microfacet fit INPUT -o OUT``: fits of measured BRDFs (thesis Ch. 4, least squares)."""
from __future__ import annotations

import contextlib
from pathlib import Path

from .common import add_batch_options, float_in, input_name, int_at_least, output_path, run_batch

#: Choices of --gaf, --method, --diffuse and --fresnel (the same as microfacet.brdf.GAFS,
#: microfacet.fit.outputs and microfacet.fit.analytic, tested; spelled here so that --help
#: imports none of them).
GAFS = ("smith", "vgroove", "normal_map")
METHODS = ("least-squares", "moments")
DIFFUSE = ("auto", "on", "off")
FRESNELS = ("table", "schlick", "conductor")
#: microfacet.fit.analytic.ALBEDO_WEIGHT (tested).
ALBEDO_WEIGHT = 4.0


@contextlib.contextmanager
def numpy_kernels(enabled: bool = True):
    """Within the block, with ``enabled``, every evaluation runs its NumPy reference
    (``microfacet.kernels.AVAILABLE`` False, restored after), so Numba is never imported.
    A single isotropic fit evaluates batches of at most 131,072 pairs, for which importing
    Numba and loading its cached kernels costs more than it saves (``benchmarks/bench_fit_command.py``)."""
    if not enabled:
        yield
        return
    from .. import kernels
    saved = kernels.AVAILABLE
    kernels.AVAILABLE = False
    try:
        yield
    finally:
        kernels.AVAILABLE = saved


def add(sub) -> None:
    p = sub.add_parser(
        "fit", help="fit measured BRDFs (tabulated fit by power iterations, least-squares GGX and Beckmann)",
        description="Fit a measured BRDF (MERL .binary(.gz), RGL .bsdf, UTIA .bin; recognised by "
                    "content) by power iterations (thesis Ch. 4), then GGX and Beckmann BRDFs by least "
                    "squares started from its moment conversion, and analytic models fitted in a "
                    "compressed (cube-root) space with the albedo held at or below the data's: one GGX "
                    "lobe + base, a core and a halo lobe + base, a mixture of GGX lobes on a roughness ladder "
                    "+ base, and with --coat a dielectric coat over a base (microfacet.fit.perceptual); the "
                    "best fit is the one of least image error (rendered spheres) times log error "
                    "(cosine-weighted, uniform pairs). For a file: writes OUT.npz (every fit: "
                    "microfacet.fit.load(OUT.npz) is the tabulated fit, load(OUT.npz, model='best' or a "
                    "name) any other), OUT.json (every fit with its metrics under \"fits\", \"best\"; GGX and Beckmann fits "
                    "with their Fresnel term and diffuse base, every fit of both methods, fit times, and "
                    "three metrics per fit: the grid error, the uniform-pairs error and the albedo "
                    "ratios fit/data, plus the white furnace) and OUT.png (the data's, the best fit's and the "
                    "tabulated fit's spheres under two lights, with their errors; --curves: their curves "
                    "too). For a folder: the same for every file in it (--recursive: in its "
                    "subfolders too, the outputs mirroring the input tree), into the folder OUT, with "
                    "summary.csv and summary.md. Prints the summary table.")
    p.add_argument("input", metavar="INPUT", help="measured BRDF file, or a folder of them")
    p.add_argument("-o", "--output", metavar="OUT", required=True,
                   help="OUT.npz for a file (.npz added if missing; an existing folder takes "
                        "INPUT's name), output folder for a folder")
    p.add_argument("--resolution", type=int_at_least(8, 2048), default=90, metavar="N",
                   help="elevation samples of the tabulated NDF (default 90)")
    p.add_argument("--anisotropic", action="store_true", help="fit an anisotropic NDF (slower)")
    p.add_argument("--gaf", choices=GAFS, default="smith",
                   help="geometric attenuation factor of the fit (default smith)")
    p.add_argument("--method", choices=METHODS, default="least-squares",
                   help="GGX and Beckmann fits reported as 'ggx'/'beckmann' and drawn: least-squares "
                        "(default; fitted to the data, started from the moments) or moments (the "
                        "tabulated fit's moment conversion, thesis App. C; faster)")
    p.add_argument("--diffuse", choices=DIFFUSE, default="auto",
                   help="Lambertian base of the least-squares fits: auto (fit with a base, dropped where "
                        "it fits to 0; default), on, off")
    p.add_argument("--fresnel", choices=FRESNELS, default="table",
                   help="Fresnel term of the least-squares fits, each bounded to [0, 1] per channel: "
                        "table (7 nodes in theta_d; default), schlick (F0) or conductor (eta, k; slower)")
    p.add_argument("--albedo-weight", type=float_in(0.0, 1e3), default=ALBEDO_WEIGHT, metavar="W",
                   help="weight of the directional-albedo term of the least-squares fits: they minimize "
                        "grid^2 + uniform^2 + W^2 mean((albedo fit/data - 1)^2) over views 0/30/60/75 deg "
                        f"and RGB (default {ALBEDO_WEIGHT:g}; 0: fit the shape only, ~4: albedo within ~10 %%)")
    p.add_argument("--coat", action="store_true",
                   help="also fit a layered coat (a dielectric coat of its own roughness and index over a "
                        "lobe + base, microfacet.layered.LayeredBRDF) and add a coat to the least-squares "
                        "fits: a second GGX/Beckmann lobe with its own 7-node Fresnel table (clear coats, "
                        "metallic paints; slower: 1-10 s per fit)")
    p.add_argument("--curves", action="store_true",
                   help="draw OUT.png with the backscattering and in-plane curves of the data and fits under "
                        "their spheres (Matplotlib: ~0.5 s more per file)")
    p.add_argument("--no-picture", dest="picture", action="store_false",
                   help="do not draw OUT.png (single files only: a folder's up-to-date check wants the "
                        "picture)")
    add_batch_options(p)
    p.set_defaults(run=run)


def run(args) -> int:
    args.method = args.method.replace("-", "_")
    if Path(args.input).is_dir():
        if not args.picture:
            raise ValueError(f"--no-picture applies to a single file, not to the folder {args.input}")
        return run_batch(args, "fit", args.input)
    from ..batch.tasks import fit_file
    source = Path(args.input)
    target = output_path(args.output, ".npz", source, side=(".json", ".png"))
    with numpy_kernels(not (args.anisotropic or args.coat or args.fresnel == "conductor")):
        row = fit_file(source, target, resolution=args.resolution, anisotropic=args.anisotropic, gaf=args.gaf,
                       method=args.method, diffuse=args.diffuse, fresnel=args.fresnel,
                       albedo_weight=args.albedo_weight, coat=args.coat, picture=args.picture,
                       curves=args.curves)
    import json
    from ..fit.outputs import format_fits_table      # imported by fit_file, after its read started
    summary = json.loads(target.with_suffix(".json").read_text())
    print(f"{input_name(source)}: fits written to {target} (.json, .png); load one with "
          f"microfacet.fit.load(path, model=NAME)")
    print(format_fits_table(summary), end="")
    return 0
