#!/usr/bin/env python3
"""Render time of the ``microfacet.mitsuba`` plugins against Mitsuba's built-ins.

One scene: a sphere on a plane under an environment map (a procedural sky with a sun),
``--res`` x ``--res`` pixels, ``--spp`` samples per pixel, Mitsuba's ``path`` integrator
(max depth 4), ``llvm_ad_rgb`` on all cores. The sphere and the plane get the BSDF under
test; each configuration is rendered once to trace and compile its kernels (reported
as "first"), then ``--repeats`` times (configurations interleaved, so that load changes
on the machine hit all of them alike); the figures are the best wall-clock time and the
best CPU time of the process (all threads: on a loaded machine the wall clock of a
multi-threaded render also measures the other jobs, its CPU time much less), and the
ratios are against ``roughconductor`` with the same distribution and roughness, measured in the
same process (``mf_fitted`` against ``roughconductor`` GGX; ``mf_leadr`` against
``roughconductor`` Beckmann with a bitmap-textured alpha). Goals (issue 8):
``mf_microfacet`` <= 1.2x, ``mf_fitted`` <= 2x, ``mf_leadr`` <= 3x; ``mf_glints`` (exact and
merged-lobe areas, a 256 x 256 map of smooth random slopes, lobes of ``sigma_eps`` 0.01,
``footprint`` 1 texel, 4x tiled) is measured against the same textured ``roughconductor``
(no goal). The fit (GGX 0.2 copper,
90 nodes, isotropic; and 32 x 32 anisotropic) and the LEADR pyramid (256 x 256 Gaussian
heights, base alpha 0.2, ``footprint`` 1/256: Mitsuba 3's path integrator provides no
ray differentials) are made in a temporary folder first.

Usage::

    python benchmarks/bench_mitsuba.py [--res 512] [--spp 64] [--repeats 2] [--threads N]
                                       [--only SUBSTR ...] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def environment(mi) -> dict:
    """Sky gradient and a bright soft sun, 64 x 128 RGB."""
    v, u = np.meshgrid(np.linspace(0, 1, 64), np.linspace(0, 1, 128), indexing="ij")
    sky = np.stack([0.2 + 0.6 * v, 0.3 + 0.5 * v, 0.6 + 0.3 * (1 - v)], axis=-1)
    sun = 20.0 * np.exp(-((u - 0.3) ** 2 + (v - 0.3) ** 2) / 0.002)[..., None]
    return {"type": "envmap", "bitmap": mi.Bitmap((sky + sun).astype(np.float32))}


def scene(mi, bsdf: dict, res: int, spp: int) -> dict:
    T = mi.ScalarTransform4f
    return {
        "type": "scene", "integrator": {"type": "path", "max_depth": 4},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": T().look_at(origin=[0, 1.5, 5], target=[0, 0.3, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res, "height": res},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "sphere": {"type": "sphere", "center": [0, 1, 0], "radius": 1.0, "bsdf": bsdf},
        "plane": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(6), "bsdf": bsdf},
        "light": environment(mi),
    }


def make_files(folder) -> dict[str, str]:
    """A fit of a GGX copper lobe (isotropic 90 nodes; anisotropic 32 x 32), a 256 x 256
    LEADR pyramid and the alpha bitmap of the textured ``roughconductor``."""
    import microfacet as mf
    from pathlib import Path
    folder = Path(folder)
    cu = mf.fresnel.Conductor(*mf.fresnel.Conductor.METALS["Cu"])
    out = {"fit": str(mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=cu), 90).save(folder / "fit.npz")),
           "fit_aniso": str(mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.35), fresnel=cu), 32,
                                       anisotropic=True).save(folder / "fit_aniso.npz"))}
    h = mf.leadr.gaussian_heightfield((256, 256), 0.3, correlation=4.0, seed=1)
    out["pyramid"] = str(mf.leadr.write_pyramid(folder / "pyramid.exr", mf.leadr.bake(h)))
    rng = np.random.default_rng(0)
    n = 256
    k = np.fft.fftfreq(n)[:, None] ** 2 + np.fft.fftfreq(n)[None, :] ** 2
    noise = np.fft.ifft2(np.fft.fft2(rng.normal(size=(2, n, n))) * np.exp(-k / 0.002)).real
    slopes = np.moveaxis(0.3 * noise / noise.std(), 0, -1)
    out["glints"] = str(mf.glints.Microsurface.from_slopes(slopes).save(folder / "glints.npz"))
    alpha = (0.2 + 0.1 * rng.random((256, 256, 1))).astype(np.float32)
    out["alpha"] = alpha
    return out


def configurations(files=None) -> dict[str, dict]:
    cu = {"eta": {"type": "rgb", "value": [0.200, 0.924, 1.102]},
          "k": {"type": "rgb", "value": [3.912, 2.452, 2.142]}}
    out = {}
    for kind in ("ggx", "beckmann"):
        common = {"distribution": kind, "alpha_u": 0.2, "alpha_v": 0.35, **cu}
        out[f"roughconductor {kind}"] = {"type": "roughconductor", **common}
        out[f"mf_microfacet {kind}"] = {"type": "mf_microfacet", **common}
        out[f"mf_microfacet {kind} sheared"] = {"type": "mf_microfacet", **common, "rho": 0.3,
                                                "mean_slope_u": 0.1, "mean_slope_v": -0.2}
    if files is not None:
        import mitsuba as mi
        out["mf_fitted ggx tabulated"] = {"type": "mf_fitted", "filename": files["fit"]}
        out["mf_fitted ggx tabulated aniso"] = {"type": "mf_fitted", "filename": files["fit_aniso"]}
        out["mf_fitted ggx use=ggx"] = {"type": "mf_fitted", "filename": files["fit"], "use": "ggx"}
        out["roughconductor beckmann-textured"] = {
            "type": "roughconductor", "distribution": "beckmann", **cu,
            "alpha": {"type": "bitmap", "bitmap": mi.Bitmap(files["alpha"]), "raw": True,
                      "to_uv": mi.ScalarTransform4f().scale([4, 4, 1])}}
        out["mf_leadr beckmann-textured"] = {"type": "mf_leadr", "filename": files["pyramid"], "alpha": 0.2,
                                             "uv_scale": 4.0, "footprint": 1.0 / 256, **cu}
        for exact in (True, False):
            out[f"mf_glints beckmann-textured {'exact' if exact else 'approx'}"] = {
                "type": "mf_glints", "filename": files["glints"], "exact": exact, "uv_scale": 4.0,
                "footprint": 1.0, **cu}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--only", nargs="*", default=None,
                    help="render only configurations containing one of these strings (and their references)")
    ap.add_argument("--threads", type=int, default=None, help="Dr.Jit threads (default: all cores)")
    ap.add_argument("--json", help="write the results here (atomically)")
    args = ap.parse_args(argv)

    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    if args.threads:
        dr.set_thread_count(args.threads)
    import microfacet.mitsuba as mfm
    mfm.register()

    import tempfile
    tmp = tempfile.TemporaryDirectory()
    files = make_files(tmp.name)
    configs = configurations(files)
    if args.only:
        wanted = {n for n in configs if any(o in n for o in args.only)}
        configs = {n: b for n, b in configs.items() if n in wanted or n in
                   {f"roughconductor {w.split()[1]}" for w in wanted}}
    scenes = {name: mi.load_dict(scene(mi, bsdf, args.res, args.spp)) for name, bsdf in configs.items()}

    def render(s) -> tuple[float, float]:
        """Wall-clock and process CPU seconds of one render."""
        t0, c0 = time.perf_counter(), time.process_time()
        dr.eval(mi.render(s))
        dr.sync_thread()
        return time.perf_counter() - t0, time.process_time() - c0

    first = {name: render(s)[0] for name, s in scenes.items()}
    times = {name: [] for name in scenes}
    for _ in range(args.repeats):
        for name, s in scenes.items():
            times[name].append(render(s))
    best = {name: min(t[0] for t in ts) for name, ts in times.items()}
    cpu = {name: min(t[1] for t in ts) for name, ts in times.items()}
    print(f"{args.res}x{args.res}, {args.spp} spp, path tracer, llvm_ad_rgb "
          f"({dr.thread_count()} threads); best of {args.repeats} after a compile run")
    print(f"{'configuration':34s} {'first (s)':>10s} {'best (s)':>9s} {'ratio':>7s} {'cpu (s)':>8s} {'ratio':>7s}")
    result = {"res": args.res, "spp": args.spp, "repeats": args.repeats, "threads": dr.thread_count(),
              "rows": []}
    for name in scenes:
        ref = f"roughconductor {name.split()[1]}"
        ratio, cpu_ratio = best[name] / best[ref], cpu[name] / cpu[ref]
        print(f"{name:34s} {first[name]:10.2f} {best[name]:9.2f} {ratio:7.2f}x {cpu[name]:8.2f} {cpu_ratio:7.2f}x")
        result["rows"].append({"name": name, "first_s": first[name], "best_s": best[name], "ratio": ratio,
                               "cpu_s": cpu[name], "cpu_ratio": cpu_ratio})
    if args.json:
        from microfacet.io.atomic import write_text
        write_text(args.json, json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
