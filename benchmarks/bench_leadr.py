#!/usr/bin/env python3
"""Baking a height map into the full LEAN/LEADR moment pyramid, against a memory-bandwidth bound.

Times ``microfacet.leadr.bake`` on a ``--size`` x ``--size`` float32 height map (default
4096, goal: at most 1 s), split into level 0 (the fused compiled pass: central
differences, five moments, float32 stores) and the MIP chain, as the best and median of
``--repeats`` runs after one warm-up run (``time.perf_counter``). For comparison it
measures the machine's copy bandwidth with ``np.copyto`` (read + write of the same bytes,
into a preallocated destination, and ``np.copy`` into a fresh array, which pays the page
faults that bake's fresh outputs pay too) and converts it into two bounds:

- *minimal traffic*: read the heights once, write the pyramid once
  (``4 HW + 20 HW * 4/3`` bytes);
- *as implemented*: level 0 is written, then each level is read to build the next
  (``4 HW + 20 HW + 2 * 20 HW * 4/3 - 20 HW``, roughly).

``--write DIR`` also times ``write_pyramid`` (atomic, fsync'd, OpenEXR on all cores) into
fresh files in ``DIR`` with every lossless compression, on this noise map's pyramid and on a
smooth Gaussian surface's quantized to 16 bits like a PNG height map (``gaussian_heightfield``,
alpha 0.3): best of ``--repeats``, file
size, ``read_pyramid`` time and a bit-exact round-trip check.

Usage::

    python benchmarks/bench_leadr.py [--size 4096] [--repeats 3] [--reference] [--write DIR] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numba
import numpy as np

from microfacet import leadr
from microfacet.io.exr import COMPRESSIONS
from microfacet.leadr.mip import downsample, mip_sizes

GOAL_S = 1.0


def time_it(fn, repeats: int) -> dict:
    fn()                                          # warm-up: compile/load kernels, touch pages
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"best_s": min(times), "median_s": statistics.median(times)}


def pyramid_bytes(h: int, w: int) -> tuple[int, int]:
    """(minimal, as-implemented) bytes moved for a float32 height map of ``h x w``."""
    sizes = mip_sizes(h, w)
    texels = [a * b for a, b in sizes]
    out = 20 * sum(texels)                        # every level written once (5 float32)
    minimal = 4 * h * w + out
    implemented = minimal + 20 * sum(texels[:-1])  # each level but the last is read back
    return minimal, implemented


def time_writes(pyramid, folder: str, repeats: int) -> dict:
    """Per lossless compression: best write time of ``repeats`` into a fresh file, size,
    read time and whether the round trip is bit-exact."""
    out = {}
    path = os.path.join(folder, "bench_leadr_pyramid.exr")
    for name in COMPRESSIONS:
        times = []
        for _ in range(repeats):
            if os.path.exists(path):
                os.unlink(path)                   # a fresh file each time, as `bake` writes one
            t0 = time.perf_counter()
            leadr.write_pyramid(path, pyramid, compression=name)
            times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        back = leadr.read_pyramid(path)
        read_s = time.perf_counter() - t0
        out[name] = {"write_best_s": min(times), "bytes": os.path.getsize(path), "read_s": read_s,
                     "exact": all(np.array_equal(a, b) for a, b in zip(pyramid, back, strict=True))}
        os.unlink(path)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=4096)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--reference", action="store_true", help="also time the NumPy reference (slow, ~2 GB)")
    ap.add_argument("--write", metavar="DIR", help="also time write_pyramid per compression into DIR")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    n = args.size
    height = np.random.default_rng(0).random((n, n), dtype=np.float32)

    res = {"size": n, "threads": numba.get_num_threads(), "cpus": os.cpu_count(),
           "machine": platform.processor() or platform.machine()}
    res["bake"] = time_it(lambda: leadr.bake(height), args.repeats)
    level0 = leadr.bake(height[:1, :1])           # compile
    from microfacet.leadr.maps import _height_moments
    base = np.zeros(5)

    def level_zero():                             # channels-first, as bake stores it
        out = np.empty((5, n, n), np.float32)
        _height_moments(0, n, height, (0.5 * n, 0.5 * n, True), base, out)
        return out.transpose(1, 2, 0)
    res["level0"] = time_it(level_zero, args.repeats)
    level0 = level_zero()

    def chain():
        lv = level0
        for size in mip_sizes(n, n)[1:]:
            lv = downsample(lv, size)
    res["mip_chain"] = time_it(chain, args.repeats)
    if args.reference:
        res["numpy_reference"] = time_it(lambda: leadr.bake_reference(height), 1)

    src = np.random.default_rng(1).random(n * n * 5 // 2, dtype=np.float64).view(np.float32)
    dst = np.empty_like(src)
    copy = time_it(lambda: np.copyto(dst, src), args.repeats)
    fresh = time_it(lambda: np.copy(src), args.repeats)
    moved = 2 * src.nbytes
    res["copy_GBps"] = moved / copy["best_s"] / 1e9
    res["copy_fresh_GBps"] = moved / fresh["best_s"] / 1e9
    minimal, implemented = pyramid_bytes(n, n)
    res["bytes_minimal"], res["bytes_implemented"] = minimal, implemented
    for name, bw in (("copyto", res["copy_GBps"]), ("copy_fresh", res["copy_fresh_GBps"])):
        res[f"bound_minimal_{name}_s"] = minimal / (bw * 1e9)
        res[f"bound_implemented_{name}_s"] = implemented / (bw * 1e9)

    best = res["bake"]["best_s"]
    print(f"bake {n} x {n} float32 -> {len(mip_sizes(n, n))} levels of E1..E5 (float32), "
          f"{res['threads']} Numba threads on {res['cpus']} CPUs")
    print(f"  bake:        best {best:.3f} s, median {res['bake']['median_s']:.3f} s "
          f"(goal <= {GOAL_S:.0f} s: {'met' if best <= GOAL_S else 'NOT met'})")
    print(f"  level 0:     best {res['level0']['best_s']:.3f} s;  MIP chain: best {res['mip_chain']['best_s']:.3f} s")
    if args.reference:
        print(f"  NumPy reference bake: {res['numpy_reference']['best_s']:.3f} s")
    print(f"  copy bandwidth: {res['copy_GBps']:.1f} GB/s (np.copyto, read+write), "
          f"{res['copy_fresh_GBps']:.1f} GB/s (np.copy into a fresh array)")
    print(f"  bandwidth bound, minimal traffic {minimal / 1e6:.0f} MB: "
          f"{res['bound_minimal_copyto_s']:.3f} s ({res['bound_minimal_copy_fresh_s']:.3f} s with page faults)")
    print(f"  bandwidth bound, as implemented {implemented / 1e6:.0f} MB: "
          f"{res['bound_implemented_copyto_s']:.3f} s ({res['bound_implemented_copy_fresh_s']:.3f} s with page faults)")
    if args.write:
        g = leadr.gaussian_heightfield((n, n), 0.3, seed=0)
        g16 = np.round((g - g.min()) / np.ptp(g) * 65535) / 65535    # as a 16-bit PNG reads
        maps = {"noise": height, "gaussian16": g16}
        res["write"] = {m: time_writes(leadr.bake(h), args.write, args.repeats) for m, h in maps.items()}
        for m, rows in res["write"].items():
            print(f"  write_pyramid, {m} map (best of {args.repeats}, fresh file):")
            for name, r in rows.items():
                print(f"    {name:5s} {r['write_best_s']:6.3f} s  {r['bytes'] / 2**20:6.1f} MiB  "
                      f"read {r['read_s']:.3f} s  {'exact' if r['exact'] else 'NOT EXACT'}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)


if __name__ == "__main__":
    main()
