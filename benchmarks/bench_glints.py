#!/usr/bin/env python3
"""P-NDF throughput of a glints microsurface (Chermain et al. 2019, Sec. 5.1.2).

Builds the lobe mixture of a normal map (default ``../shared/data/maps/
glitterman_scratches.png``, 1024^2, else a synthetic 512^2 Gaussian random surface) and
times ``Microsurface.pndf(h, center, cov)`` for isotropic Gaussian footprints "of N
texels", N = 1, 100 and 10^4 (std ``sqrt(N) / 2`` texels, so the +-1 std square covers N
texels), on ``--n`` half vectors drawn from the footprint's own P-NDF (the directions a
renderer asks about: ``Microsurface.sample_slopes``) and on ``--n`` half vectors uniform
in a 30-degree cone (mostly empty regions, where the hierarchy prunes). Methods: the
compiled hierarchy traversal (default in ``pndf``), its NumPy breadth-first reference,
and the brute-force sum over every lobe of the footprint (skipped above ``--brute-max``
lobe x query pairs). Reports the best of ``--repeats`` runs after one warm-up, as
evaluations per second, with the number of lobes in the footprint and the build time.

Production sizes (``--production 4096``): the map tiled to 4096^2 texels; in child
processes (so each peak resident memory, ``ru_maxrss``, is its own): decoding the PNG
(``load_slopes``, not the lobe construction), building the microsurface from the
slopes (``Microsurface.from_slopes``: moments, floor) and saving it, and loading it
and rendering the 256-pixel-wide plane of ``microfacet glints render`` (exact and
approximate P-BRDF, and the exact one without pruning, ``prune=inf``, with the largest
difference relative to the image's maximum); wall and CPU seconds (all threads) of each.
Then, in this process, milliseconds per ``PatchBRDF.eval_cos`` of
one direction pair (and per ``ms.pbrdf`` construction) for footprints of 32 texels
(std ``sqrt(32) / 2`` texels, the convention above) and of std 32 texels.

Usage::

    python benchmarks/bench_glints.py [--map PATH] [--n 20000] [--repeats 3] [--json out.json]
    python benchmarks/bench_glints.py --production 4096 [--skip-pndf]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from microfacet import leadr
from microfacet.glints import Microsurface

DEFAULT_MAP = Path(__file__).resolve().parents[2] / "shared" / "data" / "maps" / "glitterman_scratches.png"
TEXELS = (1, 100, 10_000)


def best_time(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def normals_of_slopes(s: np.ndarray) -> np.ndarray:
    h = np.concatenate([-s, np.ones(s.shape[:-1] + (1,))], -1)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Clock:
    """Wall and CPU seconds (all threads, ``time.process_time``) of a block, recorded as
    ``KEY_s`` and ``KEY_cpu_s`` in ``out``: CPU time is the figure that survives a shared,
    loaded machine."""

    def __init__(self, out: dict, key: str):
        self.out, self.key = out, key

    def __enter__(self):
        self.t, self.c = time.perf_counter(), time.process_time()

    def __exit__(self, *exc):
        self.out[f"{self.key}_s"] = time.perf_counter() - self.t
        self.out[f"{self.key}_cpu_s"] = time.process_time() - self.c


def _stage(stage: str, folder: Path) -> dict:
    """One production stage, run in a child process (its own peak memory)."""
    from microfacet.glints import load_slopes
    from microfacet.glints.figures import PlaneScene, render_pbrdf
    from microfacet.glints.pbrdf import eval_cos_footprints
    Microsurface.from_slopes(np.zeros((8, 8, 2))).pbrdf((0.5, 0.5), np.eye(2) * 1e-3)   # compile
    render_pbrdf(Microsurface.from_slopes(np.zeros((8, 8, 2))), PlaneScene(width=2))
    render_pbrdf(Microsurface.from_slopes(np.zeros((8, 8, 2))), PlaneScene(width=2), exact=False)
    base = _peak_mb()
    out = {"baseline_mb": base}
    if stage == "decode":
        with _Clock(out, "decode"):
            s = load_slopes(folder / "map.png")
        np.save(folder / "slopes.npy", s)
    elif stage == "build":
        s = np.load(folder / "slopes.npy")
        with _Clock(out, "build"):
            ms = Microsurface.from_slopes(s)
        with _Clock(out, "save"):
            ms.save(folder / "ms.npz")
        out["file_mb"] = (folder / "ms.npz").stat().st_size / 2**20
    else:
        with _Clock(out, "load"):
            ms = Microsurface.load(folder / "ms.npz")
        scene = PlaneScene(width=256, light=tuple(1.2 * np.array([0.0, 0.35, 0.9]) / np.hypot(0.35, 0.9)))
        uv, cov, p = scene.pixels()
        wi, irradiance = scene.lighting(p)
        images = {}
        for exact in (True, False):
            with _Clock(out, f"render_{'exact' if exact else 'approx'}"):
                images[exact] = render_pbrdf(ms, scene, exact)
        with _Clock(out, "render_exact_unpruned"):          # every lobe of every footprint
            full = eval_cos_footprints(ms, uv, cov, wi, scene.wo, prune=np.inf)[:, 0]
        pruned = images[True].reshape(-1, 3)[:, 0] / irradiance                   # eval_cos again
        out["pruned_max_rel_diff"] = float(np.abs(pruned - full).max() / np.abs(full).max())
    out["peak_mb"] = _peak_mb()
    return out


def production(source: Path, size: int) -> dict:
    """Decode, build + save, load + render at ``size^2`` texels (module notes)."""
    from PIL import Image
    res = {"size": size}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        a = np.asarray(Image.open(source))
        reps = (-(-size // a.shape[0]), -(-size // a.shape[1]), 1)
        Image.fromarray(np.tile(a, reps)[:size, :size]).save(folder / "map.png")
        for stage in ("decode", "build", "render"):
            run = subprocess.run([sys.executable, __file__, "--stage", stage, str(folder)],
                                 capture_output=True, text=True, check=True)
            res[stage] = json.loads(run.stdout.strip().splitlines()[-1])
            print(f"{size}^2 {stage}: " + ", ".join(f"{k} {v:.2f}" for k, v in res[stage].items()), flush=True)
    return res


def patch_brdf_ms(ms, repeats: int = 200) -> list[dict]:
    """Milliseconds per PatchBRDF.eval_cos (one direction pair) and per construction."""
    w = ms.resolution[1]
    c = np.array([0.4137, 0.5821])
    wi, wo = np.array([0.3, 0.2, 0.93]), np.array([-0.2, -0.4, 0.89])
    wi, wo = wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)
    rows = []
    for label, sd in (("32 texels (std sqrt(32)/2)", np.sqrt(32) / 2), ("std 32 texels", 32.0)):
        cov = np.eye(2) * (sd / w) ** 2
        for exact in (True, False):
            p = ms.pbrdf(c, cov, exact=exact)
            row = {"footprint": label, "exact": exact, "lobes": len(p.weights),
                   "eval_ms": 1e3 * best_time(lambda: p.eval_cos(wi, wo), repeats),
                   "construct_ms": 1e3 * best_time(lambda: ms.pbrdf(c, cov, exact=exact), repeats)}
            rows.append(row)
            print(f"P-BRDF {label}, {'exact' if exact else 'approx'} ({row['lobes']} lobes): "
                  f"eval_cos {row['eval_ms']:.3f} ms, construction {row['construct_ms']:.3f} ms", flush=True)
    return rows


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--stage":
        print(json.dumps(_stage(sys.argv[2], Path(sys.argv[3]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", type=Path, default=DEFAULT_MAP)
    ap.add_argument("--n", type=int, default=20_000, help="half vectors per evaluation")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--brute-max", type=float, default=2e8, help="max lobe x query pairs for brute force")
    ap.add_argument("--production", type=int, metavar="SIZE",
                    help="also time decode/build/save/load/render at SIZE^2 texels (the map tiled) and "
                         "the patch BRDF per evaluation")
    ap.add_argument("--skip-pndf", action="store_true", help="skip the P-NDF throughput table")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    extra = {}
    if args.production:
        if not args.map.exists():
            raise SystemExit(f"--production needs the map {args.map}")
        extra["production"] = production(args.map, args.production)

    t0 = time.perf_counter()
    if args.map.exists():
        ms = Microsurface.from_normal_map(args.map)
        name = args.map.name
    else:
        height = leadr.gaussian_heightfield((512, 512), 0.3, correlation=4.0, seed=0)
        ms = Microsurface.from_normal_map(leadr.slopes_to_normals(leadr.height_to_slopes(height)))
        name = "synthetic 512^2 Gaussian surface (alpha 0.3)"
    build = time.perf_counter() - t0
    print(f"{name}: {ms}, built in {build:.2f} s (incl. compilation on first use); "
          f"{numba.get_num_threads()} threads, {platform.processor() or platform.machine()}")
    if args.production:
        extra["patch_brdf"] = patch_brdf_ms(ms)
    rng = np.random.default_rng(0)
    center = np.array([0.4137, 0.5821])
    w = ms.resolution[1]
    rows = []
    t = rng.random(args.n) * np.radians(30)
    p = rng.random(args.n) * 2 * np.pi
    cone = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    for texels in () if args.skip_pndf else TEXELS:
        cov = np.eye(2) * (np.sqrt(texels) / 2 / w) ** 2
        idx, _ = ms.weights(center, cov)
        lit = normals_of_slopes(ms.sample_slopes(rng.random((args.n, 3)), center, cov))
        for hname, h in (("footprint P-NDF", lit), ("30-deg cone", cone)):
            row = {"texels": texels, "lobes": int(idx.size), "queries": hname}
            for method in ("hierarchy", "hierarchy-numpy", "brute"):
                if method != "hierarchy" and idx.size * args.n > args.brute_max:
                    row[method] = None
                    continue
                dt = best_time(lambda: ms.pndf(h, center, cov, method=method), args.repeats)
                row[method] = args.n / dt
            rows.append(row)
            fmt = lambda v: "       -" if v is None else f"{v:8.3g}"
            print(f"N = {texels:>6} texels ({row['lobes']:>6} lobes), {hname:<16}: evaluations/s "
                  f"hierarchy {fmt(row['hierarchy'])}, numpy BFS {fmt(row['hierarchy-numpy'])}, "
                  f"brute {fmt(row['brute'])}", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"map": name, "build_s": build, "n": args.n,
                                         "threads": numba.get_num_threads(), "cpus": os.cpu_count(),
                                         "rows": rows, **extra}, indent=2))


if __name__ == "__main__":
    main()
