#!/usr/bin/env python3
"""Load time and eval / pdf / sample throughput of the measured-BRDF readers
(``mf.measured``), against Mitsuba 3's ``measured`` plugin on the RGL files.

For every MERL ``.binary(.gz)`` and RGL ``.bsdf`` file in ``--data`` (default
``../shared/data`` from the project root; UTIA ``.bin`` files too if any) and for a
synthetic UTIA file written to a temporary folder (no real one ships with the data),
this times ``mf.measured.load(path)`` and ``eval(wi, wo)``, ``pdf(wi, wo)`` and
``sample(u, wo)`` on ``--n`` fixed-seed direction pairs uniform over the upper
hemisphere (float64; eval and sample by the compiled loops of
:mod:`microfacet.measured._kernels` on Numba's threads; ``--numpy`` also times the NumPy
reference). Each figure is the best and the median of ``--repeats`` runs after one
warm-up run (``time.perf_counter``); the warm-up of the first file includes compiling
the loops (or loading them from Numba's cache), reported as ``first``.

Mitsuba (``llvm_ad_rgb``, float32, all cores, probed as in ``bench_brdf.py``) evaluates,
samples and gives the density of its ``measured`` plugin on the same RGL files and
directions (``si.wi`` = our ``wo``), timed as call + ``dr.eval`` + ``dr.sync_thread``.
Its sampling is importance sampling by the file's luminance tables, ours is cosine
sampling (see :mod:`microfacet.measured.base`).

Usage::

    python benchmarks/bench_measured.py [--data ../shared/data] [--n 1000000] [--repeats 3]
                                        [--numpy] [--mitsuba auto|llvm_ad_rgb|none] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet import kernels
from microfacet.geometry import spherical_to_cartesian
from microfacet.io import write_text

from bench_brdf import _numba_threads, pick_variant

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT / ".." / "shared" / "data"
PATTERNS = ("merl/*.binary*", "rgl/*.bsdf", "utia/*.bin")


def time_it(fn, repeats: int) -> dict:
    """Best and median wall time of ``fn()`` over ``repeats`` runs after one warm-up run
    (``first_s``), and the process CPU time (all threads) of the best run: on a loaded
    machine the CPU time is the steadier measure of the work done."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        runs.append((time.perf_counter() - t0, time.process_time() - c0))
    best = min(runs)
    return {"best_s": best[0], "median_s": statistics.median(r[0] for r in runs), "first_s": first,
            "cpu_s": best[1]}


def uniform_dirs(rng, n: int) -> np.ndarray:
    u = rng.random((n, 2))
    return spherical_to_cartesian(np.arccos(u[:, 0]), 2 * np.pi * u[:, 1])


def synthetic_utia(folder: Path) -> Path:
    """A smooth synthetic UTIA file (the data folder has no real one)."""
    rng = np.random.default_rng(0)
    path = folder / "synthetic_utia.bin"
    path.write_bytes(rng.uniform(0, 140, (3, 6, 48, 6, 48)).astype("<f8").tobytes())
    return path


def bench_ours(path: Path, wi, wo, u, repeats: int, numpy: bool) -> list[dict]:
    """Rows ``{file, format, impl, op, best_s, median_s, first_s, cpu_s}`` for load, eval,
    pdf, sample (compiled) and, with ``numpy``, eval and sample of the NumPy reference."""
    m = mf.measured.load(path)
    ops = {"load": lambda: mf.measured.load(path), "eval": lambda: m.eval(wi, wo),
           "pdf": lambda: m.pdf(wi, wo), "sample": lambda: m.sample(u, wo)}
    rows = [{"file": path.name, "format": m.format, "impl": "microfacet", "op": op,
             **time_it(fn, repeats)} for op, fn in ops.items()]
    if numpy:
        available, kernels.AVAILABLE = kernels.AVAILABLE, False     # the NumPy path
        try:
            rows += [{"file": path.name, "format": m.format, "impl": "microfacet numpy", "op": op,
                      **time_it(ops[op], repeats)} for op in ("eval", "sample")]
        finally:
            kernels.AVAILABLE = available
    return rows


def bench_mitsuba(path: Path, wi, wo, u, repeats: int) -> list[dict]:
    """Rows for Mitsuba's ``measured`` plugin (llvm_ad_rgb) on the same directions."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    f32 = lambda a: np.ascontiguousarray(a.T, dtype=np.float32)  # noqa: E731  (k, n) SoA
    n = len(wi)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(f32(wo))
    light, s1, s2 = mi.Vector3f(f32(wi)), dr.zeros(mi.Float, n), mi.Point2f(f32(u))
    dr.eval(si, light, s1, s2)
    dr.sync_thread()
    bsdf, ctx = mi.load_dict({"type": "measured", "filename": str(path)}), mi.BSDFContext()

    def run(fn):
        def go():
            dr.eval(fn())
            dr.sync_thread()
        return go

    ops = {"eval": lambda: bsdf.eval(ctx, si, light), "pdf": lambda: bsdf.pdf(ctx, si, light),
           "sample": lambda: bsdf.sample(ctx, si, s1, s2)}
    return [{"file": path.name, "format": "rgl", "impl": "mitsuba measured", "op": op,
             **time_it(run(fn), repeats)} for op, fn in ops.items()]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with merl/, rgl/, utia/")
    ap.add_argument("--n", type=int, default=1_000_000, help="direction pairs per call")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--numpy", action="store_true", help="also time the NumPy reference (slow)")
    ap.add_argument("--mitsuba", default="auto", choices=["auto", "llvm_ad_rgb", "none"],
                    help="compare with Mitsuba's measured plugin (llvm_ad_rgb) if it works")
    ap.add_argument("--json", type=Path, help="also write the raw results here")
    args = ap.parse_args(argv)
    if args.n < 1 or args.repeats < 1:
        ap.error("--n and --repeats must be >= 1")

    variant, why = (None, "skipped (--mitsuba none)") if args.mitsuba == "none" else pick_variant(args.mitsuba)
    if variant != "llvm_ad_rgb":
        variant = None
    print(f"N = {args.n}, best of {args.repeats}; ours float64, {_numba_threads()} Numba threads; "
          f"mitsuba: {why}")
    rng = np.random.default_rng(1)
    wi, wo, u = uniform_dirs(rng, args.n), uniform_dirs(rng, args.n), rng.random((args.n, 2))
    files = sorted(p for pattern in PATTERNS for p in args.data.glob(pattern)) if args.data.exists() else []
    if not files:
        print(f"no measured files under {args.data}; benchmarking the synthetic UTIA file only")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in files + [synthetic_utia(Path(tmp))]:
            new = bench_ours(path, wi, wo, u, args.repeats, args.numpy)
            if variant and path.suffix == ".bsdf":
                new += bench_mitsuba(path, wi, wo, u, args.repeats)
            for r in new:
                print(f"{r['file']:30s} {r['format']:5s} {r['impl']:17s} {r['op']:7s} "
                      f"best {1e3 * r['best_s']:8.2f} ms  median {1e3 * r['median_s']:8.2f} ms  "
                      f"cpu {1e3 * r['cpu_s']:8.2f} ms  first {1e3 * r['first_s']:8.1f} ms", flush=True)
            rows += new
    by = {(r["file"], r["impl"], r["op"]): r for r in rows}
    ratios = [(f, op, by[f, "microfacet", op]["best_s"] / r["best_s"], by[f, "microfacet", op]["cpu_s"] / r["cpu_s"])
              for (f, impl, op), r in by.items() if impl == "mitsuba measured"]
    if ratios:
        print("\nours / Mitsuba measured (> 1: ours slower; goal <= 3 for eval and sample):")
        print(f"  {'file':30s} {'op':7s} {'wall':>6s} {'cpu':>6s}")
        for f, op, wall, cpu in ratios:
            print(f"  {f:30s} {op:7s} {wall:6.2f} {cpu:6.2f}")
    load = os.getloadavg()
    print(f"\nload average at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} CPUs)")
    if args.json:
        env = {"python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
               "cpus": os.cpu_count(), "numba_threads": _numba_threads(), "n": args.n,
               "repeats": args.repeats, "mitsuba": why, "load_average": load, "time": time.time()}
        write_text(args.json, json.dumps({"environment": env, "results": rows,
                                          "ratios": [dict(zip(("file", "op", "wall", "cpu"), r)) for r in ratios]},
                                         indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
