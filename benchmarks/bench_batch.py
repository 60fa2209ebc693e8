#!/usr/bin/env python3
"""Batch throughput: ``--n`` generated ``--size``^2 height maps baked serially, with
``--jobs`` local worker processes and through a ``--jobs``-worker Dask LocalCluster, in
the same run; and, with ``--memory``, the peak memory of one bake and one glints task
against the map size (the per-pixel figures of :mod:`microfacet.batch.tasks`).

Each mode bakes every map into its own fresh folder with :func:`microfacet.batch.run`
(EXR pyramid + PNG preview per map, written atomically, summary.csv/md); the time is the
whole call (wall clock, ``time.perf_counter``), including the local pool's start-up, but
not the LocalCluster's (printed apart). It prints files/s, the speed-up over the serial
run, the mean task wall-clock and CPU time and the peak memory from the summary rows
(the same CPU time per task in every mode: no parallel overhead inside the tasks), the I/O volume per file,
and the load average before and after (the machine may be shared: compare the ratios
of one run, not absolute figures across runs).

Usage::

    python benchmarks/bench_batch.py [--n 200] [--size 1024] [--jobs 2] [--json out.json]
    python benchmarks/bench_batch.py --memory [--sizes 512,1024,2048,4096]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.batch import tasks
from microfacet.io.png import write_png_data


def height_map(path: Path, n: int, k: int) -> Path:
    """A smooth 16-bit height map, different for each ``k``."""
    x = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    rng = np.random.default_rng(k)
    a, b = rng.integers(1, 8, 2)
    h = 0.5 + 0.25 * np.sin(a * x[None, :] + k) * np.cos(b * x[:, None]) + 0.05 * rng.random((n, n))
    return write_png_data(path, np.round(h * 65535).astype(np.uint16))


def normal_map(path: Path, n: int, k: int) -> Path:
    x = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    gx = 0.3 * np.cos((1 + k) * x[None, :]) * np.ones((n, 1))
    normal = np.stack([-gx, np.zeros_like(gx), np.ones_like(gx)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return write_png_data(path, np.round((normal + 1.0) * 127.5).astype(np.uint8))


def load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def throughput(args, work: Path) -> dict:
    maps = work / "maps"
    maps.mkdir()
    for k in range(args.n):
        height_map(maps / f"h{k:04d}.png", args.size, k)
    results = {"n": args.n, "size": args.size, "jobs": args.jobs, "cpus": mf.batch.memory.cpu_count(),
               "load_before": load()}
    modes = [("serial", dict(jobs=1)), (f"--jobs {args.jobs}", dict(jobs=args.jobs))]
    cluster = client = None
    if not args.no_dask:
        from distributed import Client, LocalCluster
        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=args.jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None)
        client = Client(cluster)
        results["cluster_start_s"] = round(time.perf_counter() - t0, 2)
        modes.append((f"LocalCluster x{args.jobs}", dict(scheduler=client)))
    try:
        for name, kw in modes:
            out = work / name.replace(" ", "_").replace("-", "")
            t0 = time.perf_counter()
            rows = mf.batch.run("bake", maps, out, progress=False, **kw)
            seconds = time.perf_counter() - t0
            assert all(r["status"] == "ok" for r in rows), [r for r in rows if r["status"] != "ok"][:3]
            results[name] = {"seconds": round(seconds, 2), "files_per_s": round(args.n / seconds, 3),
                             "task_s_mean": round(statistics.mean(r["seconds"] for r in rows), 4),
                             "task_cpu_s_mean": round(statistics.mean(r["cpu_seconds"] for r in rows), 4),
                             "peak_mb_max": max(r["peak_mb"] for r in rows)}
    finally:
        if client is not None:
            client.close()
            cluster.close()
    serial = results["serial"]["seconds"]
    for name, _ in modes:
        results[name]["speedup"] = round(serial / results[name]["seconds"], 2)
    results["input_mb_per_file"] = round(folder_bytes(maps) / args.n / 1e6, 3)
    results["output_mb_per_file"] = round(folder_bytes(work / "serial") / args.n / 1e6, 3)
    results["load_after"] = load()
    return results


def peaks(args, work: Path) -> dict:
    """Peak memory of one task (a fresh ``microfacet`` process each) against the pixel
    count, and the least-squares line."""
    out = {}
    for name, make, sizes in (("bake", height_map, args.sizes), ("glints", normal_map, args.glints_sizes)):
        pixels, peak = [], []
        for n in sizes:
            folder = work / f"{name}{n}"
            folder.mkdir()
            make(folder / "m.png", n, 1)
            subprocess.run([sys.executable, "-m", "microfacet", name, str(folder), "-o", str(work / f"{name}{n}-out"),
                            "--jobs", "1"], check=True, stdout=subprocess.DEVNULL)     # a fresh process
            with open(work / f"{name}{n}-out" / "summary.csv", newline="") as f:
                row = {k: (float(v) if k in ("peak_mb", "seconds") else v) for k, v in next(csv.DictReader(f)).items()}
            pixels.append(n * n)
            peak.append(row["peak_mb"] * 2**20)
            print(f"{name} {n}^2: peak {row['peak_mb']:.0f} MB, {row['seconds']:.2f} s", flush=True)
        slope, intercept = np.polyfit(pixels, peak, 1)
        out[name] = {"sizes": list(sizes), "peak_mb": [round(p / 2**20, 1) for p in peak],
                     "bytes_per_pixel": round(float(slope), 1), "fixed_mb": round(float(intercept) / 2**20, 1)}
    out["constants"] = {"WORKER_BYTES": tasks.WORKER_BYTES, "BAKE_BYTES_PER_PIXEL": tasks.BAKE_BYTES_PER_PIXEL,
                        "GLINTS_BYTES_PER_PIXEL": tasks.GLINTS_BYTES_PER_PIXEL}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=200, help="maps (default 200)")
    p.add_argument("--size", type=int, default=1024, help="map side in pixels (default 1024)")
    p.add_argument("--jobs", type=int, default=2, help="local workers and cluster workers (default 2)")
    p.add_argument("--no-dask", action="store_true", help="skip the LocalCluster run")
    p.add_argument("--memory", action="store_true", help="measure peak memory against map size instead")
    p.add_argument("--sizes", type=lambda s: [int(v) for v in s.split(",")], default=[512, 1024, 2048, 4096])
    p.add_argument("--glints-sizes", type=lambda s: [int(v) for v in s.split(",")], default=[256, 512, 1024])
    p.add_argument("--json", help="also write the results here")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_batch-") as tmp:
        results = peaks(args, Path(tmp)) if args.memory else throughput(args, Path(tmp))
    print(json.dumps(results, indent=2))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
