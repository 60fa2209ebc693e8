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

Usage::

    python benchmarks/bench_glints.py [--map PATH] [--n 20000] [--repeats 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", type=Path, default=DEFAULT_MAP)
    ap.add_argument("--n", type=int, default=20_000, help="half vectors per evaluation")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--brute-max", type=float, default=2e8, help="max lobe x query pairs for brute force")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()

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
    rng = np.random.default_rng(0)
    center = np.array([0.4137, 0.5821])
    w = ms.resolution[1]
    rows = []
    t = rng.random(args.n) * np.radians(30)
    p = rng.random(args.n) * 2 * np.pi
    cone = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    for texels in TEXELS:
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
                                         "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
